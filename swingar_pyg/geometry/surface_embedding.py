r"""Points embedded on a triangle surface, carried onto another surface of the same
topology (a garment fitted on one body shape, moved onto another).

A point :math:`\mathbf{p}` is stored as its closest triangle :math:`f`, the
barycentric coordinates :math:`\mathbf{b}` of its closest point there, and its
displacement from that point in the triangle's frame :math:`F_f` (first edge,
in-plane perpendicular, normal); on a surface :math:`V'` it becomes
:math:`\mathbf{p}' = \sum_k b_k \mathbf{v}'_{f_k} + F'_f\, \mathbf{c}`. Exact on
the same surface; on another it follows each triangle's position and rotation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SurfaceEmbedding:
    """``faces`` ``(N,)`` triangle ids, ``barycentric`` ``(N, 3)``, ``local`` ``(N, 3)``
    displacement in the triangle's frame (metres)."""

    faces: np.ndarray
    barycentric: np.ndarray
    local: np.ndarray


def triangle_frames(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` orthonormal frames, columns: first edge, in-plane perpendicular,
    unit normal. Degenerate triangles get an arbitrary but valid frame."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    edge = b - a
    normal = np.cross(edge, c - a)
    edge_length = np.linalg.norm(edge, axis=1, keepdims=True)
    normal_length = np.linalg.norm(normal, axis=1, keepdims=True)
    good = (edge_length[:, 0] > 1e-15) & (normal_length[:, 0] > 1e-30)
    tangent = np.where(good[:, None], edge / np.maximum(edge_length, 1e-300), [1.0, 0.0, 0.0])
    normal = np.where(good[:, None], normal / np.maximum(normal_length, 1e-300), [0.0, 0.0, 1.0])
    return np.stack([tangent, np.cross(normal, tangent), normal], axis=-1)


def embed_points(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> SurfaceEmbedding:
    """Embeds ``points`` on the surface ``(vertices, faces)`` (needs trimesh)."""
    import trimesh

    surface = trimesh.Trimesh(vertices, faces, process=False)
    closest, _, face_ids = trimesh.proximity.closest_point(surface, points)
    barycentric = trimesh.triangles.points_to_barycentric(surface.triangles[face_ids], closest)
    frames = triangle_frames(vertices, faces)[face_ids]
    local = np.einsum("nji,nj->ni", frames, points - closest)
    return SurfaceEmbedding(face_ids, barycentric, local)


def evaluate_embedding(embedding: SurfaceEmbedding, vertices: np.ndarray,
                       faces: np.ndarray) -> np.ndarray:
    """The embedded points on a surface with the same faces."""
    corners = vertices[faces[embedding.faces]]  # (N, 3, 3)
    base = (embedding.barycentric[..., None] * corners).sum(axis=1)
    frames = triangle_frames(vertices, faces)[embedding.faces]
    return base + np.einsum("nij,nj->ni", frames, embedding.local)
