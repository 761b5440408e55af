r"""Constraints of a cloth mesh: distances (stretch edges, or the opposite corners of
adjacent triangles as a simple bending model), grouped into colours for parallel
Gauss–Seidel, dihedral angles across interior edges (hinges), solved together, and
tethers from free vertices to their nearest pin.

A hinge ``(x1, x2, x3, x4)`` has the shared edge :math:`\mathbf{e} = \mathbf{x}_4 -
\mathbf{x}_3` and the triangles :math:`(\mathbf{x}_1, \mathbf{x}_3, \mathbf{x}_4)`,
:math:`(\mathbf{x}_2, \mathbf{x}_4, \mathbf{x}_3)` with normals
:math:`\mathbf{n}_1 = (\mathbf{x}_1 - \mathbf{x}_3) \times (\mathbf{x}_1 - \mathbf{x}_4)`,
:math:`\mathbf{n}_2 = (\mathbf{x}_2 - \mathbf{x}_4) \times (\mathbf{x}_2 - \mathbf{x}_3)`;
its signed angle is

.. math::
    \theta = \operatorname{atan2}\big((\hat{\mathbf{n}}_1 \times \hat{\mathbf{n}}_2)
    \cdot \hat{\mathbf{e}},\; \hat{\mathbf{n}}_1 \cdot \hat{\mathbf{n}}_2\big)

(0 for a flat, consistently oriented pair), with the gradient of Bridson et al. (2003),
:math:`\mathbf{m}_k = \mathbf{n}_k / \|\mathbf{n}_k\|^2`:

.. math::
    \nabla_1\theta = -\|\mathbf{e}\|\,\mathbf{m}_1, \quad
    \nabla_2\theta = -\|\mathbf{e}\|\,\mathbf{m}_2, \quad
    \nabla_3\theta = -\tfrac{(\mathbf{x}_1 - \mathbf{x}_4)\cdot\mathbf{e}}{\|\mathbf{e}\|}
    \mathbf{m}_1 - \tfrac{(\mathbf{x}_2 - \mathbf{x}_4)\cdot\mathbf{e}}{\|\mathbf{e}\|}
    \mathbf{m}_2, \quad
    \nabla_4\theta = \tfrac{(\mathbf{x}_1 - \mathbf{x}_3)\cdot\mathbf{e}}{\|\mathbf{e}\|}
    \mathbf{m}_1 + \tfrac{(\mathbf{x}_2 - \mathbf{x}_3)\cdot\mathbf{e}}{\|\mathbf{e}\|}
    \mathbf{m}_2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy.sparse.csgraph import dijkstra
from torch import Tensor

from swingar_pyg.geometry.geodesic import edge_length_graph
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


def _corners_by_edge(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle corner as ``(a, b, opposite)`` of its edge ``a -> b`` in the
    triangle's winding, and the edge ``(min, max)``, both sorted by edge."""
    corners = np.concatenate([faces[:, [0, 1, 2]], faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]])
    edge = np.sort(corners[:, :2], axis=1)
    order = np.lexsort((edge[:, 1], edge[:, 0]))
    return corners[order], edge[order]


def bending_pairs(mesh: Mesh) -> np.ndarray:
    """For every edge shared by two triangles, their two opposite vertices."""
    corners, edge = _corners_by_edge(mesh.faces)
    opposite = corners[:, 2]
    same = np.all(edge[1:] == edge[:-1], axis=1)
    pairs = np.stack([opposite[:-1][same], opposite[1:][same]], axis=1)
    pairs = np.sort(pairs[pairs[:, 0] != pairs[:, 1]], axis=1)
    return np.unique(pairs, axis=0)


def hinges(mesh: Mesh) -> np.ndarray:
    """``(H, 4)`` hinges ``(x1, x2, x3, x4)`` of the interior edges ``x3 -> x4`` shared
    by exactly two triangles: ``x1`` opposite the edge in the triangle that runs
    ``x3 -> x4``, ``x2`` in the other (edges of three or more triangles are left out)."""
    corners, edge = _corners_by_edge(mesh.faces)
    first = np.concatenate([[True], np.any(edge[1:] != edge[:-1], axis=1)])
    group = np.cumsum(first) - 1
    size = np.bincount(group)
    start = np.flatnonzero(first)[size == 2]
    one, two = corners[start], corners[start + 1]
    hinge = np.stack([one[:, 2], two[:, 2], one[:, 0], one[:, 1]], axis=1)
    return hinge[hinge[:, 0] != hinge[:, 1]]


def colour_constraints(rows: np.ndarray, num_vertices: int) -> np.ndarray:
    """Greedy colouring: each constraint (a row of vertex indices) gets the smallest
    colour unused at all its vertices."""
    colours = np.empty(len(rows), dtype=np.int64)
    used: list[set[int]] = [set() for _ in range(num_vertices)]
    for k, row in enumerate(rows.tolist()):
        taken = set().union(*(used[i] for i in row))
        colour = 0
        while colour in taken:
            colour += 1
        colours[k] = colour
        for i in row:
            used[i].add(colour)
    return colours


def _coloured(rows: np.ndarray, num_vertices: int) -> tuple[np.ndarray, tuple]:
    """``rows`` sorted by colour, and each colour's ``(start, stop)``."""
    colours = colour_constraints(rows, num_vertices)
    order = np.argsort(colours, kind="stable")
    colours = colours[order]
    bounds = np.flatnonzero(np.diff(colours)) + 1
    starts = np.concatenate([[0], bounds])
    stops = np.concatenate([bounds, [len(rows)]])
    return order, tuple(zip(starts.tolist(), stops.tolist()))


def distance_constraints(pairs: np.ndarray, vertices: np.ndarray) -> DistanceConstraints:
    """Coloured constraints for ``pairs`` at their rest distances in ``vertices``."""
    order, slices = _coloured(pairs, len(vertices))
    pairs = pairs[order]
    lengths = np.linalg.norm(vertices[pairs[:, 0]] - vertices[pairs[:, 1]], axis=1)
    return DistanceConstraints(torch.from_numpy(pairs), torch.from_numpy(lengths), slices)


@dataclass(frozen=True)
class DihedralConstraints:
    """Hinges kept at their rest angles, solved all at once (Jacobi).

    Attributes:
        hinges: ``(H, 4)`` long ``(x1, x2, x3, x4)`` (see :func:`hinges`).
        rest_angles: ``(H,)`` :math:`\theta_0` in ``(-pi, pi]``.
        rest_lengths: ``(H,)`` rest length of each shared edge.
        share: ``(N, 1)`` one over the number of hinges at each vertex (1 where none): the
            corrections a vertex receives in one sweep are averaged.
    """

    hinges: Tensor
    rest_angles: Tensor
    rest_lengths: Tensor
    share: Tensor

    def to(self, device: torch.device | str, dtype: torch.dtype) -> "DihedralConstraints":
        return DihedralConstraints(self.hinges.to(device), self.rest_angles.to(device, dtype),
                                   self.rest_lengths.to(device, dtype),
                                   self.share.to(device, dtype))


def _dot(a: Tensor, b: Tensor) -> Tensor:
    return (a * b).sum(0)


def _cross(a: Tensor, b: Tensor) -> Tensor:
    """``a x b`` of vectors stored coordinates first, ``(3, ...)``."""
    (a1, a2, a3), (b1, b2, b3) = a, b
    return torch.stack((a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1))


def dihedral_angles(corners: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    r"""Signed angles of hinges, their gradients and whether both triangles have area.

    For a hinge :math:`(x_1, x_2, x_3, x_4)` with edge :math:`e = x_4 - x_3` and wing
    normals :math:`n_1 = (x_1 - x_3) \times (x_1 - x_4)`,
    :math:`n_2 = (x_2 - x_4) \times (x_2 - x_3)`, the angle is
    :math:`\theta = \operatorname{atan2}((n_1 \times n_2) \cdot e,\ |e|\, n_1 \cdot n_2)`
    and, with :math:`m_i = n_i / |n_i|^2` and :math:`a_{ij} = (x_i - x_j) \cdot e / |e|`,

    .. math::
        \nabla_1 \theta = -|e| m_1, \quad \nabla_2 \theta = -|e| m_2, \quad
        \nabla_3 \theta = -a_{14} m_1 - a_{24} m_2, \quad
        \nabla_4 \theta = a_{13} m_1 + a_{23} m_2.

    Args:
        corners: ``(3, 4, H)`` coordinates first (one contiguous row per axis, which
            makes these many small vector products several times faster on a CPU than
            ``(H, 4, 3)``).

    Returns:
        ``(H,)`` angles, ``(3, 4, H)`` gradients (0 where invalid) and ``(H,)`` whether
        both triangles are thicker than ``1e-6`` of the edge length squared.
    """
    x1, x2, x3, x4 = corners.unbind(1)
    e = x4 - x3
    length = _dot(e, e).sqrt()
    d13, d14, d23, d24 = x1 - x3, x1 - x4, x2 - x3, x2 - x4
    n1 = _cross(d13, d14)
    n2 = _cross(d24, d23)
    area1, area2 = _dot(n1, n1), _dot(n2, n2)
    tiny = (1e-6 * length.square()).square()
    valid = (area1 > tiny) & (area2 > tiny)
    floor = torch.finfo(corners.dtype).tiny
    m1 = torch.where(valid, n1 / area1.clamp_min(floor), 0.0)
    m2 = torch.where(valid, n2 / area2.clamp_min(floor), 0.0)
    angle = torch.atan2(_dot(_cross(n1, n2), e), length * _dot(n1, n2))
    inverse_length = 1.0 / length.clamp_min(floor)
    a13, a14, a23, a24 = (_dot(d, e) * inverse_length for d in (d13, d14, d23, d24))
    gradient = torch.stack((-length * m1, -length * m2, -a14 * m1 - a24 * m2,
                            a13 * m1 + a23 * m2), 1)
    return angle, gradient, valid


def dihedral_constraints(mesh: Mesh) -> DihedralConstraints:
    """The hinges of ``mesh`` at the angles and edge lengths of its vertices."""
    rows = hinges(mesh)
    angle, _, _ = dihedral_angles(torch.from_numpy(mesh.vertices[rows.T].transpose(2, 0, 1)))
    lengths = np.linalg.norm(mesh.vertices[rows[:, 3]] - mesh.vertices[rows[:, 2]], axis=1)
    count = np.bincount(rows.reshape(-1), minlength=mesh.num_vertices)
    share = 1.0 / np.maximum(count, 1)
    return DihedralConstraints(torch.from_numpy(rows), angle, torch.from_numpy(lengths),
                               torch.from_numpy(share)[:, None])


@dataclass(frozen=True)
class TetherConstraints:
    r"""Long-range attachments (Kim et al. 2012): each free vertex :math:`i` that
    a path of mesh edges joins to a pin is kept within its rest geodesic distance
    :math:`g_i` of its nearest pin :math:`a_i`,

    .. math::
        C_i = \|\mathbf{x}_i - \mathbf{x}_{a_i}\| - (1 + s)\, g_i \le 0,

    with slack :math:`s`. The bound is unilateral (slack cloth is free) and the
    pin does not move, so one projection satisfies it: stretch cannot accumulate
    along the cloth when there are too few sweeps to carry the pins' pull to the
    far edge.

    Attributes:
        vertices: ``(T,)`` tethered vertices (each once).
        anchors: ``(T,)`` their nearest pins.
        rest_lengths: ``(T,)`` rest geodesic distances along mesh edges.
    """

    vertices: Tensor
    anchors: Tensor
    rest_lengths: Tensor

    def to(self, device: torch.device | str, dtype: torch.dtype) -> "TetherConstraints":
        return TetherConstraints(self.vertices.to(device), self.anchors.to(device),
                                 self.rest_lengths.to(device, dtype))


def tether_constraints(mesh: Mesh, pinned: np.ndarray) -> TetherConstraints:
    """Tethers of every free vertex that shares a connected piece with a pin
    (none if nothing is pinned); geodesics cross welded seams."""
    pinned = np.unique(np.asarray(pinned, dtype=np.int64))
    free = np.setdiff1d(np.arange(mesh.num_vertices), pinned)
    if pinned.size == 0 or free.size == 0:
        empty = torch.zeros(0, dtype=torch.long)
        return TetherConstraints(empty, empty, torch.zeros(0, dtype=torch.float64))
    distance, _, nearest = dijkstra(edge_length_graph(mesh), indices=pinned, min_only=True,
                                    return_predecessors=True)
    free = free[np.isfinite(distance[free])]
    return TetherConstraints(torch.from_numpy(free), torch.from_numpy(nearest[free]),
                             torch.from_numpy(distance[free]))
