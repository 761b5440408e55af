import numpy as np
import pytest
import torch
from torch_geometric.data import Batch, Data

from swingar_pyg.collision import fixed_offset_push, resolve_collisions
from swingar_pyg.geometry import (
    body_signed_distance,
    inside_share,
    mesh_edge_index,
    roll_into_cylinder,
    sheet,
)
from tests.extras import require

RADIUS = 0.3


def sphere(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Analytic SDF of a sphere at the origin, positive inside, and its gradient."""
    norm = points.norm(dim=-1, keepdim=True)
    return RADIUS - norm[:, 0], -points / norm.clamp_min(1e-12)


def tube(radius: float, height: float = 0.4, rows: int = 8, cols: int = 24):
    mesh = roll_into_cylinder(sheet(rows, cols, width=2 * np.pi * radius, height=height),
                              radius=radius)
    vertices = torch.as_tensor(mesh.vertices, dtype=torch.float64)
    return vertices - vertices.mean(0), mesh_edge_index(mesh)


def test_exact_reference_sign_and_normal_on_a_sphere_mesh():
    trimesh = require('trimesh')
    ball = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
    directions = torch.nn.functional.normalize(torch.randn(200, 3, dtype=torch.float64), dim=-1)
    radii = torch.empty(200, dtype=torch.float64).uniform_(0.05, 0.6)
    points = directions * radii[:, None]
    s, n = body_signed_distance(points.numpy(), ball.vertices, ball.faces)
    # the mesh is inscribed: distances agree with the analytic sphere to its chord error
    assert np.allclose(s, RADIUS - radii.numpy(), atol=2e-3)
    clearly_inside, clearly_outside = radii < RADIUS - 3e-3, radii > RADIUS
    assert (s[clearly_inside.numpy()] > 0).all() and (s[clearly_outside.numpy()] < 0).all()
    assert (np.einsum('ij,ij->i', n, directions.numpy()) > 0.99).all()


def test_inside_share_counts_points_inside_a_moving_sphere_mesh():
    trimesh = require('trimesh')

    ball = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    generator = np.random.default_rng(0)
    frames, count = 3, 400
    shift = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, -2.0, 1.0]])
    directions = generator.normal(size=(frames, count, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    radii = generator.uniform(0.0, 2 * RADIUS, size=(frames, count, 1))
    radii[np.abs(radii - RADIUS) < 0.01] += 0.02  # keep off the faceted surface
    points = directions * radii + shift[:, None]
    share = inside_share(ball.vertices[None] + shift[:, None], ball.faces, points)
    assert np.allclose(share, (radii[..., 0] < RADIUS).mean(axis=1))
    with pytest.raises(ValueError, match='not closed'):
        inside_share(ball.vertices[None], ball.faces[1:], points[:1])


def test_exact_reference_on_the_body_in_the_armpit_and_crotch():
    require('anny')
    from swingar_pyg.geometry import vertex_normals
    from swingar_pyg.world.body import AnnyBody

    body = AnnyBody()
    rest = body.rest_vertices(body.default_shape()).double()
    faces = body.faces
    normals = vertex_normals(rest, faces)
    # where garments are: torso, hips, crotch, legs, armpits (not the fingers, nor the eyes and
    # mouth, whose inner surfaces lie inside the head)
    region = (rest[:, 2] > -0.8) & (rest[:, 2] < 0.4) & (rest[:, 0].abs() < 0.25)
    chosen = region.nonzero()[torch.randperm(int(region.sum()))[:300], 0]
    for offset, inside in ((0.004, False), (-0.004, True)):
        points = rest[chosen] + offset * normals[chosen]
        s, _ = body_signed_distance(points.numpy(), rest.numpy(), faces.numpy())
        share = np.mean((s > 0) == inside)
        assert share > 0.99, (offset, share)
    with pytest.raises(ValueError, match='finite'):
        body_signed_distance(np.array([[np.nan, 0, 0]]), rest.numpy(), faces.numpy())


def test_correction_leaves_no_vertex_inside_and_far_vertices_untouched():
    vertices, edges = tube(0.35)
    vertices = vertices + torch.tensor([0.0, 0.0, 0.15])  # the lower rows dip into the sphere
    assert (sphere(vertices)[0] > 0).any() and (sphere(vertices)[0] < 0).any()
    result = resolve_collisions(vertices, edges, sphere, iterations=3)
    assert (sphere(result.vertices)[0] <= 1e-12).all()
    far = sphere(vertices)[0] < 0
    assert torch.equal(result.vertices[far & ~result.moved], vertices[far & ~result.moved])
    assert torch.equal(result.moved, ~far)


def test_correction_is_smoother_than_the_fixed_offset_push():
    vertices, edges = tube(0.35)
    vertices = vertices + torch.tensor([0.0, 0.0, 0.15])
    ours = resolve_collisions(vertices, edges, sphere).vertices
    push = fixed_offset_push(vertices, sphere, offset=0.02).vertices
    assert (sphere(push)[0] <= 0).all()

    def roughness(x):
        src, dst = edges
        from torch_geometric.utils import scatter
        mean = scatter(x[src], dst, dim=0, dim_size=len(x), reduce='mean')
        return (mean - x).norm(dim=-1).mean()

    assert roughness(ours) < roughness(push)


def test_correction_of_a_batch_equals_each_garment_alone():
    a, ea = tube(0.35)
    b, eb = tube(0.2, rows=5, cols=15)
    a = a + torch.tensor([0.0, 0.0, 0.15])
    batch = Batch.from_data_list([Data(pos=a, edge_index=ea), Data(pos=b, edge_index=eb)])
    together = resolve_collisions(batch.pos, batch.edge_index, sphere, sigma=0.05).vertices
    alone = torch.cat([resolve_collisions(a, ea, sphere, sigma=0.05).vertices,
                       resolve_collisions(b, eb, sphere, sigma=0.05).vertices])
    assert torch.equal(together, alone)


def test_a_garment_entirely_inside_comes_out_finite():
    vertices, edges = tube(0.1, height=0.1)
    result = resolve_collisions(vertices, edges, sphere, iterations=3)
    assert torch.isfinite(result.vertices).all()
    assert (sphere(result.vertices)[0] <= 1e-12).all() and result.moved.all()
    # a vertex exactly at the centre has no direction to go: it stays, finite
    centre = torch.zeros(1, 3, dtype=torch.float64)
    stuck = resolve_collisions(centre, torch.zeros(2, 0, dtype=torch.long), sphere)
    assert torch.equal(stuck.vertices, centre)


def test_broad_phase_skips_far_garments_entirely():
    vertices, edges = tube(0.35)
    calls = []

    def counting(points):
        calls.append(len(points))
        return sphere(points)

    result = resolve_collisions(vertices + 5.0, edges, counting,
                                near=torch.zeros(len(vertices), dtype=torch.bool))
    assert calls == [0] or calls == []
    assert result.iterations == 0 and not result.moved.any()
    with pytest.raises(ValueError, match='not finite'):
        resolve_collisions(vertices * float('nan'), edges, sphere)
