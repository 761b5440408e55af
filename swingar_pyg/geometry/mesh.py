"""Triangle meshes: validation at the boundary, edges, and the mesh-edge graph.

A :class:`Mesh` is plain data (float64 vertices, int64 triangle faces) that
:func:`as_mesh` has validated; code that receives one trusts it.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from typing import Any

import numpy as np
import torch
from torch import Tensor


@dataclass(frozen=True)
class Mesh:
    """A validated triangle mesh.

    Attributes:
        vertices: ``(N, 3)`` float64 positions.
        faces: ``(F, 3)`` int64 vertex indices, each in ``[0, N)``.
    """

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def num_vertices(self) -> int:
        return len(self.vertices)

    @property
    def num_faces(self) -> int:
        return len(self.faces)


def as_mesh(vertices: Any, faces: Any = None) -> Mesh:
    """Validates a mesh given as arrays, a :class:`Mesh` or a ``trimesh.Trimesh``.

    Quads ``(F, 4)`` are split into two triangles along the ``0-2`` diagonal.
    Faces that repeat a vertex (zero area) are kept: they are valid input and
    every function here handles them.

    Raises:
        ValueError: naming the problem, for empty meshes, non-finite or
            non-3D vertices, non-integer faces, faces with neither 3 nor 4
            corners, and indices outside ``[0, N)``.
    """
    if isinstance(vertices, Mesh) and faces is None:
        return vertices
    if faces is None and hasattr(vertices, "vertices") and hasattr(vertices, "faces"):
        vertices, faces = vertices.vertices, vertices.faces
    if faces is None:
        raise ValueError("a mesh needs faces; got vertices only")

    verts = np.asarray(vertices, dtype=np.float64)
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"vertices must have shape (N, 3), got {verts.shape}")
    if len(verts) == 0:
        raise ValueError("the mesh has no vertices")
    bad = ~np.isfinite(verts).all(axis=1)
    if bad.any():
        raise ValueError(
            f"{int(bad.sum())} vertices are not finite (NaN or inf), "
            f"the first is vertex {int(np.flatnonzero(bad)[0])}")

    face_array = np.asarray(faces)
    if face_array.size == 0:
        raise ValueError("the mesh has no faces")
    if face_array.ndim != 2 or face_array.shape[1] not in (3, 4):
        raise ValueError(
            f"faces must have shape (F, 3) for triangles or (F, 4) for quads, "
            f"got {face_array.shape}")
    if not np.issubdtype(face_array.dtype, np.integer):
        if not np.all(np.mod(face_array, 1) == 0):
            raise ValueError(f"faces must hold integer vertex indices, got {face_array.dtype}")
    face_array = face_array.astype(np.int64)
    if face_array.min() < 0:
        raise ValueError(f"faces index vertex {int(face_array.min())}; indices must be >= 0")
    if face_array.max() >= len(verts):
        raise ValueError(
            f"faces index vertex {int(face_array.max())} but the mesh has "
            f"{len(verts)} vertices")
    if face_array.shape[1] == 4:
        face_array = np.concatenate([face_array[:, [0, 1, 2]], face_array[:, [0, 2, 3]]])
    return Mesh(verts, np.ascontiguousarray(face_array))


def load_mesh(path: str | PathLike) -> Mesh:
    """Reads an OBJ/PLY/OFF/STL/GLB file with trimesh, keeping vertex order.

    Vertices are not merged or reordered (``process=False``), so indices match
    the file. Units and axes are the file's: convert them where the source's
    convention is known.
    """
    import trimesh

    loaded = trimesh.load(path, process=False, force="mesh")
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"{path} holds no triangle mesh")
    return as_mesh(loaded.vertices, loaded.faces)


def mesh_edges(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges ``(E, 2)`` of triangle faces, ``i < j``, sorted.

    Edges of zero length (a face repeating a vertex) are dropped.
    """
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.unique(pairs, axis=0)


def boundary_edges(faces: np.ndarray) -> np.ndarray:
    """Edges ``(B, 2)`` (``i < j``) that belong to exactly one triangle: the mesh's
    open borders (a waistband, a hem, a sleeve end)."""
    pairs = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(pairs, axis=0, return_counts=True)
    return unique[counts == 1]


def mesh_edge_index(mesh: Mesh, device: torch.device | str | None = None) -> Tensor:
    """The mesh-edge graph as a PyG ``edge_index`` ``(2, 2E)``: every edge in
    both directions, sorted by source then target (coalesced)."""
    edges = torch.from_numpy(mesh_edges(mesh.faces))
    both = torch.cat([edges, edges.flip(1)]).t()
    order = torch.argsort(both[0] * mesh.num_vertices + both[1])
    return both[:, order].contiguous().to(device)
