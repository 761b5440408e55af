r"""Short edges merged away, keeping the surface's topology.

Modelling tools leave meshes with edges far shorter than the rest: sub-millimetre
edges along seams, thin slivers at a crotch or a cuff. A position-based cloth solver
corrects every edge by about the same length per sweep, so where it cannot meet all
its constraints the leftover error lands on the short edges as a large strain
:math:`l / L - 1` (a 5 mm edge 5 mm too long is 100 % stretched). :func:`merge_short_edges`
collapses every edge shorter than :math:`r` times the mesh's median edge length,
shortest first, each into one vertex (Hoppe's edge collapse). An edge
:math:`(a, b)` is collapsed only when that keeps the surface a manifold of the same
topology and orientation:

- the link condition, :math:`\mathrm{N}(a) \cap \mathrm{N}(b) = \{\text{the corners
  opposite } (a, b)\}` (no fold or pinch is made);
- an interior edge whose two ends both lie on the boundary is kept (it would join two
  boundary stretches into one vertex);
- no remaining triangle turns over (its normal keeps a positive dot product with the
  old one) or loses its area.

The merged vertex sits at the edge's midpoint, or on the boundary end when only one
end is on the boundary, so a hem, a cuff or a waistband keeps its shape.
"""

from __future__ import annotations

import heapq

import numpy as np

from swingar_pyg.geometry.mesh import Mesh, as_mesh, boundary_edges, mesh_edges


def merge_short_edges(mesh: Mesh, ratio: float) -> tuple[Mesh, np.ndarray]:
    """``mesh`` with its edges shorter than ``ratio`` times the median edge length
    collapsed (see the module's text for which collapses are allowed).

    Args:
        mesh: a triangle mesh, welded (:func:`~swingar_pyg.geometry.weld.weld_mesh`): an
            edge next to a face of zero area is left as it is.
        ratio: in (0, 1); 0.5 merges the edges shorter than half the median.

    Returns:
        The new mesh and ``new_index`` ``(N,)``: where each old vertex went.

    Raises:
        ValueError: if ``ratio`` is outside (0, 1), or for a mesh :func:`as_mesh` refuses
            (no faces, vertices not finite, indices out of range).
    """
    if not 0.0 < ratio < 1.0:
        raise ValueError(f"ratio must be in (0, 1), got {ratio}")
    mesh = as_mesh(mesh.vertices, mesh.faces)
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

    queue = [(float(length), int(a), int(b)) for (a, b), length in zip(edges, lengths)
             if length < limit]
    heapq.heapify(queue)
    while queue:
        length, a, b = heapq.heappop(queue)
        if merged_into[a] != a or merged_into[b] != b:
            continue
        shared = vertex_faces[a] & vertex_faces[b]
        current = float(np.linalg.norm(vertices[a] - vertices[b]))
        if not shared or current >= limit:
            continue
        if current != length:
            heapq.heappush(queue, (current, a, b))
            continue
        opposite = {int(u) for f in shared for u in faces[f]} - {a, b}
        if neighbours(a) & neighbours(b) != opposite:
            continue
        if on_boundary[a] and on_boundary[b] and len(shared) == 2:
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
            gap = float(np.linalg.norm(vertices[a] - vertices[u]))
            if gap < limit:
                heapq.heappush(queue, (gap, min(a, u), max(a, u)))

    root = np.arange(n)
    for v in range(n):
        while merged_into[root[v]] != root[v]:
            root[v] = merged_into[root[v]]
    kept = merged_into == np.arange(n)
    compact = np.cumsum(kept) - 1
    new_index = compact[root]
    return as_mesh(vertices[kept], compact[faces[face_alive]]), new_index
