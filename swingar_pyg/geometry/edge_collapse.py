r"""Short edges merged away, keeping the surface's topology.

Modelling tools leave meshes with edges far shorter than the rest: sub-millimetre
edges along seams, thin slivers at a crotch or a cuff. A position-based cloth solver
corrects every edge by about the same length per sweep, so where it cannot meet all
its constraints the leftover error lands on the short edges as a large strain
:math:`l / L - 1` (a 5 mm edge 5 mm too long is 100 % stretched). :func:`merge_short_edges`
visits the edges shorter than :math:`r` times the mesh's median edge length, shortest
first, and collapses each into one vertex (Hoppe's edge collapse) unless one of these
rules refuses it; a refused edge stays as it is.

- The link condition (Dey et al.), with the border closed by a virtual vertex: the
  vertices joined to both :math:`a` and :math:`b` are exactly the corners opposite
  :math:`(a, b)`, no edge :math:`(c, d)` closes a triangle with both :math:`a` and
  :math:`b` (a tetrahedron would fold flat), an interior edge does not join two border
  vertices (it would pinch the surface), and a border edge's opposite corner is not on
  the border with both ends (a lone triangle would vanish).
- No remaining triangle turns over or collapses: its new normal :math:`\mathbf{n}'` (the
  unnormalised cross product) keeps :math:`\mathbf{n}' \cdot \mathbf{n} > 10^{-3}
  \|\mathbf{n}\|^2`, that is :math:`(A' / A) \cos\theta > 10^{-3}`, which does not depend
  on scale.

The merged vertex sits at the edge's midpoint, or on the border end when only one end is
on the border, so a border keeps its vertices' places except along a border edge merged
at its midpoint.
"""

from __future__ import annotations

import heapq

import numpy as np

from swingar_pyg.geometry.mesh import Mesh, as_mesh, boundary_edges, mesh_edges
from swingar_pyg.geometry.weld import refuse_degenerate


def merge_short_edges(mesh: Mesh, ratio: float) -> tuple[Mesh, np.ndarray]:
    """``mesh`` with its edges shorter than ``ratio`` times the median edge length
    collapsed, shortest first, where the module's rules allow it.

    Args:
        mesh: a welded triangle mesh (:func:`~swingar_pyg.geometry.weld.weld_mesh`).
        ratio: in (0, 1); 0.5 merges the edges shorter than half the median.

    Returns:
        The new mesh and ``new_index`` ``(N,)``: where each old vertex went.

    Raises:
        ValueError: if ``ratio`` is outside (0, 1), for a mesh :func:`as_mesh` refuses (no
            faces, vertices not finite, indices out of range) and for coincident vertices
            or zero-area faces (weld them first).
    """
    if not 0.0 < ratio < 1.0:
        raise ValueError(f"ratio must be in (0, 1), got {ratio}")
    mesh = as_mesh(mesh.vertices, mesh.faces)
    refuse_degenerate(mesh, "the mesh to merge short edges in")
    vertices = np.array(mesh.vertices, dtype=np.float64)
    faces = np.array(mesh.faces, dtype=np.int64)
    n = len(vertices)
    edges = mesh_edges(faces)
    lengths = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    limit = ratio * float(np.median(lengths))
    on_boundary = np.zeros(n, dtype=bool)
    on_boundary[boundary_edges(faces).reshape(-1)] = True
    vertex_faces: list[set[int]] = [set() for _ in range(n)]
    for f, corners in enumerate(faces):
        for v in corners:
            vertex_faces[v].add(f)
    merged_into = np.arange(n)
    face_alive = np.ones(len(faces), dtype=bool)

    def neighbours(v: int) -> set[int]:
        return {int(u) for f in vertex_faces[v] for u in faces[f]} - {v}

    def link_edges(v: int, other: int) -> set[tuple[int, int]]:
        """The edges opposite ``v`` in its triangles, but those touching ``other``."""
        return {tuple(sorted(int(u) for u in faces[f] if u != v)) for f in vertex_faces[v]
                if other not in faces[f]}

    def on_border(u: int, w: int) -> bool:
        return len(vertex_faces[u] & vertex_faces[w]) == 1

    def keeps_topology(a: int, b: int, shared: set[int]) -> bool:
        opposite = {int(u) for f in shared for u in faces[f]} - {a, b}
        if neighbours(a) & neighbours(b) != opposite or link_edges(a, b) & link_edges(b, a):
            return False
        if len(shared) == 2:
            return not (on_boundary[a] and on_boundary[b])
        (corner,) = opposite
        return not (on_border(a, corner) and on_border(b, corner))

    def keeps_faces(a: int, b: int, position: np.ndarray, shared: set[int]) -> bool:
        for f in (vertex_faces[a] | vertex_faces[b]) - shared:
            corners = vertices[faces[f]]
            moved = corners.copy()
            moved[(faces[f] == a) | (faces[f] == b)] = position
            before = np.cross(corners[1] - corners[0], corners[2] - corners[0])
            after = np.cross(moved[1] - moved[0], moved[2] - moved[0])
            if not after @ before > 1e-3 * (before @ before):
                return False
        return True

    def distance(u: int, w: int) -> float:
        return float(np.linalg.norm(vertices[u] - vertices[w]))

    queue = [(distance(a, b), int(a), int(b)) for a, b in edges[lengths < limit]]
    heapq.heapify(queue)
    while queue:
        length, a, b = heapq.heappop(queue)
        if merged_into[a] != a or merged_into[b] != b:
            continue
        shared = vertex_faces[a] & vertex_faces[b]
        if not shared or distance(a, b) != length:
            continue  # no longer an edge, or moved since queued (queued again then)
        if not keeps_topology(a, b, shared):
            continue
        if on_boundary[a] == on_boundary[b]:
            position = 0.5 * (vertices[a] + vertices[b])
        else:
            position = vertices[a] if on_boundary[a] else vertices[b]
        if not keeps_faces(a, b, position, shared):
            continue
        for f in shared:
            face_alive[f] = False
            for v in faces[f]:
                vertex_faces[v].discard(f)
        for f in vertex_faces[b]:
            faces[f][faces[f] == b] = a
        vertex_faces[a] |= vertex_faces[b]
        vertex_faces[b] = set()
        vertices[a] = position
        on_boundary[a] |= on_boundary[b]
        merged_into[b] = a
        for u in neighbours(a):
            if distance(a, u) < limit:
                heapq.heappush(queue, (distance(a, u), min(a, u), max(a, u)))

    root = np.arange(n)
    for v in range(n):
        while merged_into[root[v]] != root[v]:
            root[v] = merged_into[root[v]]
    kept = merged_into == np.arange(n)
    compact = np.cumsum(kept) - 1
    new_index = compact[root]
    return as_mesh(vertices[kept], compact[faces[face_alive]]), new_index
