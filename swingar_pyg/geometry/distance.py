"""Exact distances to triangle meshes (the reference for collision handling)."""

from __future__ import annotations

import numpy as np


def signed_distance_to_surface(points: np.ndarray, vertices: np.ndarray,
                               faces: np.ndarray) -> np.ndarray:
    """Exact distance from each point to the closest point of a triangle mesh,
    negative behind the face it lies on (inside a closed, outward-facing surface).

    Needs trimesh (extra ``data``): its closest-point query on the triangles.
    """
    import trimesh

    surface = trimesh.Trimesh(vertices, faces, process=False)
    closest, distance, face = trimesh.proximity.closest_point(surface, points)
    side = np.einsum("ij,ij->i", points - closest, surface.face_normals[face])
    return np.where(side < 0, -distance, distance)
