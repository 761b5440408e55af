"""The exact body signed distance: the reference for training targets and metrics.

Sign convention (the paper's): the signed distance ``s(x)`` is **positive
inside** the body and negative outside. ``n(x)`` is the outward unit normal,
so moving a point by ``s(x) · n(x)`` puts it on the surface.
"""

from __future__ import annotations

import numpy as np


def body_signed_distance(points: np.ndarray, vertices: np.ndarray,
                         faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact signed distance (positive inside) and outward normal of points
    to a closed triangle mesh.

    The distance is to the closest point on the triangles; inside/outside comes
    from ray parity over the whole mesh (trimesh's ``contains``), not from the
    closest face, whose normal can point the wrong way in armpits and the crotch
    where the closest point lies on an edge. The normal is the direction from
    the closest point to the point (turned outward), or the closest face's
    normal for points on the surface.

    Args:
        points: ``(M, 3)``; vertices: ``(V, 3)``; faces: ``(F, 3)`` of a closed,
            outward-facing mesh.

    Returns:
        ``s`` ``(M,)`` and ``n`` ``(M, 3)``.
    """
    import trimesh

    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (M, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("points must be finite")
    surface = trimesh.Trimesh(vertices, faces, process=False)
    if not surface.is_watertight:
        raise ValueError("the body mesh is not closed (watertight): inside is undefined")
    closest, distance, face = trimesh.proximity.closest_point(surface, points)
    inside = surface.contains(points)
    offset = points - closest
    scale = np.maximum(np.abs(points).max(initial=0.0), 1.0)
    on_surface = distance <= 1e-9 * scale
    direction = offset / np.where(on_surface, 1.0, distance)[:, None]
    direction = np.where(inside[:, None], -direction, direction)
    normal = np.where(on_surface[:, None], surface.face_normals[face], direction)
    return np.where(inside, distance, -distance), normal
