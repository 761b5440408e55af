"""Distance constraints of a cloth mesh, grouped into colours for parallel Gauss–Seidel."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from swingar_pyg.geometry.mesh import Mesh, mesh_edges


@dataclass(frozen=True)
class DistanceConstraints:
    """Pairs ``(i, j)`` kept at rest length, in colours: no two constraints of one
    colour share a vertex, so a colour is solved in parallel without conflicts.

    Attributes:
        pairs: ``(C, 2)`` long vertex pairs, sorted by colour.
        rest_lengths: ``(C,)`` rest distances.
        colour_slices: ``[(start, stop), ...]`` of each colour in ``pairs``.
    """

    pairs: Tensor
    rest_lengths: Tensor
    colour_slices: tuple[tuple[int, int], ...]

    def to(self, device: torch.device | str, dtype: torch.dtype) -> "DistanceConstraints":
        return DistanceConstraints(self.pairs.to(device), self.rest_lengths.to(device, dtype),
                                   self.colour_slices)


def stretch_pairs(mesh: Mesh) -> np.ndarray:
    """The mesh edges."""
    return mesh_edges(mesh.faces)


def bending_pairs(mesh: Mesh) -> np.ndarray:
    """For every edge shared by two triangles, their two opposite vertices."""
    faces = mesh.faces
    corners = np.concatenate([faces[:, [0, 1, 2]], faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]])
    edge = np.sort(corners[:, :2], axis=1)
    opposite = corners[:, 2]
    order = np.lexsort((edge[:, 1], edge[:, 0]))
    edge, opposite = edge[order], opposite[order]
    same = np.all(edge[1:] == edge[:-1], axis=1)
    pairs = np.stack([opposite[:-1][same], opposite[1:][same]], axis=1)
    pairs = np.sort(pairs[pairs[:, 0] != pairs[:, 1]], axis=1)
    return np.unique(pairs, axis=0)


def colour_constraints(pairs: np.ndarray, num_vertices: int) -> np.ndarray:
    """Greedy colouring: each pair gets the smallest colour unused at both ends."""
    colours = np.empty(len(pairs), dtype=np.int64)
    used: list[set[int]] = [set() for _ in range(num_vertices)]
    for k, (i, j) in enumerate(pairs):
        taken = used[i] | used[j]
        colour = 0
        while colour in taken:
            colour += 1
        colours[k] = colour
        used[i].add(colour)
        used[j].add(colour)
    return colours


def distance_constraints(pairs: np.ndarray, vertices: np.ndarray) -> DistanceConstraints:
    """Coloured constraints for ``pairs`` at their rest distances in ``vertices``."""
    colours = colour_constraints(pairs, len(vertices))
    order = np.argsort(colours, kind="stable")
    pairs, colours = pairs[order], colours[order]
    bounds = np.flatnonzero(np.diff(colours)) + 1
    starts = np.concatenate([[0], bounds])
    stops = np.concatenate([bounds, [len(pairs)]])
    lengths = np.linalg.norm(vertices[pairs[:, 0]] - vertices[pairs[:, 1]], axis=1)
    return DistanceConstraints(torch.from_numpy(pairs), torch.from_numpy(lengths),
                               tuple(zip(starts.tolist(), stops.tolist())))
