"""The neighbour term delta_i of the collision correction (paper §3.4): a colliding
vertex moves out by its own depth plus the Gaussian-weighted mean distance of its
free (non-colliding) neighbours, so it lands as far out as they hover, not on the
surface."""

import numpy as np
import pytest
import torch

from swingar_pyg.collision import resolve_collisions
from swingar_pyg.geometry import mesh_edge_index, sheet

# How far the free cloth hovers outside the body and how deep the dent goes (metres):
# garment-like numbers, and far apart from each other and from any offset used
# below, so landing on the surface, at the offset or at the dent's depth cannot
# pass for landing at the neighbours' height.
HOVER = 0.02
DEPTH = 0.015
# Every quantity is float64 and the step is one addition along an exact normal:
# the landing height is exact up to a few float64 roundoffs of a 1 m scene.
EXACT = 1e-12


def floor(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """A body filling z < 0: S = -z (positive inside), grad S = (0, 0, -1)."""
    gradient = torch.zeros_like(points)
    gradient[:, 2] = -1.0
    return -points[:, 2], gradient


RADIUS = 0.3


def ball(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """A sphere of radius RADIUS at the origin, positive inside, and its gradient."""
    norm = points.norm(dim=-1, keepdim=True)
    return RADIUS - norm[:, 0], -points / norm.clamp_min(1e-12)


def hovering_sheet(rows: int = 9, cols: int = 9, size: float = 0.2):
    """A flat sheet at z = HOVER over the floor, and its index grid."""
    mesh = sheet(rows, cols, width=size, height=size)
    vertices = torch.as_tensor(mesh.vertices, dtype=torch.float64).clone()
    vertices[:, 2] = HOVER
    return vertices, mesh_edge_index(mesh), np.arange(rows * cols).reshape(rows, cols)


@pytest.mark.parametrize('offset', [0.0, 0.004])
def test_a_dented_vertex_lands_as_far_out_as_its_free_neighbours(offset):
    """One vertex pushed DEPTH into the floor, its neighbours HOVER above: it comes
    back to HOVER (with or without a safety offset), not to the surface or the offset."""
    vertices, edges, grid = hovering_sheet()
    dent = int(grid[4, 4])
    vertices[dent, 2] = -DEPTH
    result = resolve_collisions(vertices, edges, floor, offset=offset)
    assert result.moved.nonzero().squeeze(-1).tolist() == [dent]
    assert result.iterations == 1  # one step puts it out of reach: nothing left to do
    landed = result.vertices[dent]
    assert abs(float(landed[2]) - HOVER) < EXACT, float(landed[2])
    assert torch.equal(landed[:2], vertices[dent, :2])  # straight out along the normal
    others = torch.arange(len(vertices)) != dent
    assert torch.equal(result.vertices[others], vertices[others])


def test_a_dented_patch_follows_only_its_free_neighbours():
    """A 3 x 3 patch inside the floor: each border vertex averages its free
    neighbours only (the colliding ones' depths would drag it short), so the
    border comes back to HOVER. The centre has no free neighbour (delta = 0): it
    only has to end up out of the body."""
    vertices, edges, grid = hovering_sheet()
    patch = torch.as_tensor(grid[3:6, 3:6].ravel())
    vertices[patch, 2] = -DEPTH
    result = resolve_collisions(vertices, edges, floor, iterations=3)
    assert torch.equal(result.moved.nonzero().squeeze(-1), patch.sort().values)
    centre = int(grid[4, 4])
    border = patch[patch != centre]
    heights = result.vertices[border, 2]
    assert (heights - HOVER).abs().max() < EXACT, heights.tolist()
    assert float(result.vertices[centre, 2]) >= -EXACT


def test_on_a_sphere_the_dent_lands_on_the_shell_of_its_neighbours():
    """A spherical cap HOVER outside a ball with one vertex pushed DEPTH inside: the
    vertex lands back on the cap's shell, at radius RADIUS + HOVER, along its own ray."""
    mesh = sheet(9, 9, width=0.6, height=0.6)  # (theta, phi) around the +z pole
    theta, phi = mesh.vertices[:, 0] - 0.3, mesh.vertices[:, 1] - 0.3
    directions = np.stack([np.sin(theta), np.sin(phi), np.cos(theta) * np.cos(phi)], axis=1)
    directions = torch.as_tensor(directions / np.linalg.norm(directions, axis=1, keepdims=True))
    vertices = (RADIUS + HOVER) * directions
    dent = 40  # the middle of the 9 x 9 grid
    vertices[dent] = (RADIUS - DEPTH) * directions[dent]
    result = resolve_collisions(vertices, mesh_edge_index(mesh), ball)
    assert result.moved.nonzero().squeeze(-1).tolist() == [dent]
    landed = result.vertices[dent]
    assert abs(float(landed.norm()) - (RADIUS + HOVER)) < EXACT, float(landed.norm())
    assert torch.allclose(landed / landed.norm(), directions[dent], atol=EXACT)
