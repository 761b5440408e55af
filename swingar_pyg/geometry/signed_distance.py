"""Exact signed distances to closed triangle meshes: the reference for collision
handling, training targets and metrics.

One sign convention throughout the package (the paper's): the signed distance
``s(x)`` is **positive inside** the body and negative outside. ``n(x)`` is the
outward unit normal, so moving a point by ``s(x) · n(x)`` puts it on the surface.
A garment's clearance from the body (its ``fit`` attribute) is ``-s(x)``.

Needs trimesh (extra ``data``) for its closest-point and ray queries.
"""

from __future__ import annotations

from importlib.util import find_spec

import numpy as np

from swingar_pyg.geometry.mesh import Mesh, as_mesh


class BodySurface:
    """A closed, outward-facing triangle mesh prepared once for exact signed
    distance queries (its ray-intersection structure is built on first use and
    kept).

    Args:
        vertices, faces: the mesh.
        validate: check that it is closed (skip only for a re-posed mesh already checked:
            the check costs about half a ray query).

    Raises:
        ValueError: if the mesh is not closed (inside would be undefined).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, validate: bool = True):
        import trimesh

        self.surface = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64), faces,
                                       process=False)
        if validate and not self.surface.is_watertight:
            raise ValueError("the body mesh is not closed (watertight): inside is undefined")

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact signed distance (positive inside) and outward normal of points.

        The distance is to the closest point on the triangles; inside/outside
        comes from ray parity over the whole mesh (trimesh's ``contains``), not
        from the closest face, whose normal can point the wrong way in armpits
        and the crotch where the closest point lies on an edge. The normal is
        the direction from the closest point to the point (turned outward), or
        the closest face's normal for points on the surface.

        Args:
            points: ``(M, 3)``.

        Returns:
            ``s`` ``(M,)`` and ``n`` ``(M, 3)``.
        """
        import trimesh

        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (M, 3), got {points.shape}")
        if not np.isfinite(points).all():
            raise ValueError("points must be finite")
        closest, distance, face = trimesh.proximity.closest_point(self.surface, points)
        inside = self.surface.contains(points)
        offset = points - closest
        scale = np.maximum(np.abs(points).max(initial=0.0), 1.0)
        on_surface = distance <= 1e-9 * scale
        direction = offset / np.where(on_surface, 1.0, distance)[:, None]
        direction = np.where(inside[:, None], -direction, direction)
        normal = np.where(on_surface[:, None], self.surface.face_normals[face], direction)
        return np.where(inside, distance, -distance), normal


def closest_face_signed_distance(points: np.ndarray, vertices: np.ndarray,
                                 faces: np.ndarray) -> np.ndarray:
    """Exact distance from each point to the closest point of a triangle mesh,
    positive behind the face it lies on (inside a closed, outward-facing surface).

    Cheaper than :meth:`BodySurface.signed_distance` (no ray parity, no closed-mesh
    check), and exact away from creases; in armpits and the crotch, where the
    closest point lies on an edge, the side can be wrong.
    """
    import trimesh

    surface = trimesh.Trimesh(vertices, faces, process=False)
    closest, distance, face = trimesh.proximity.closest_point(surface, points)
    side = np.einsum("ij,ij->i", points - closest, surface.face_normals[face])
    return np.where(side < 0, distance, -distance)


def inside_share(body_vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per frame, the share of ``points`` ``(T, M, 3)`` inside the closed body
    ``body_vertices`` ``(T, V, 3)`` by exact ray parity: the penetration figure a
    nearest-vertex tangent-plane test (the simulator's own, cheaper one) under-reports
    in creases. Runs in NVIDIA Warp when it is installed (one BVH refitted per frame),
    else with trimesh's ``contains`` (a ray scene per frame, ~10x slower); the two
    agree point for point (``tests/test_signed_distance.py``). Returns ``(T,)`` in [0, 1]."""
    if body_vertices.shape[0] != points.shape[0]:
        raise ValueError(f"the body has {body_vertices.shape[0]} frames, the points "
                         f"{points.shape[0]}")
    if points.shape[1] == 0:
        return np.zeros(points.shape[0])
    BodySurface(body_vertices[0], faces)  # closed? (re-posing keeps the connectivity)
    if find_spec("warp") is not None:
        # optional dependency (with the body extra), imported only where it is installed
        from swingar_pyg.geometry.warp_inside import inside_share_warp

        return inside_share_warp(body_vertices, faces, points)
    return inside_share_trimesh(body_vertices, faces, points)


def inside_share_trimesh(body_vertices: np.ndarray, faces: np.ndarray,
                         points: np.ndarray) -> np.ndarray:
    """:func:`inside_share` by trimesh's ray parity, one ray scene per frame."""
    return np.array([BodySurface(body, faces, validate=False).surface.contains(frame).mean()
                     for body, frame in zip(body_vertices, points)])


def body_signed_distance(points: np.ndarray, vertices: np.ndarray,
                         faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`BodySurface.signed_distance` of ``points`` to the closed mesh
    ``vertices`` ``(V, 3)``, ``faces`` ``(F, 3)``: ``s`` ``(M,)`` (positive
    inside) and the outward normal ``(M, 3)``."""
    return BodySurface(vertices, faces).signed_distance(points)


def push_out(mesh: Mesh, body_vertices: np.ndarray, body_faces: np.ndarray,
             clearance: float, passes: int = 4) -> Mesh:
    """``mesh`` with every vertex nearer the body than ``clearance`` (or inside it)
    moved out along the body's outward normal to ``clearance``; again, up to
    ``passes`` times, where a move brought a vertex near another part (a crease)."""
    surface = BodySurface(body_vertices, body_faces)
    vertices = mesh.vertices.copy()
    for _ in range(passes):
        depth, normal = surface.signed_distance(vertices)  # positive inside
        move = np.maximum(depth + clearance, 0.0)
        if not move.any():
            break
        vertices += (move + 1e-3 * clearance * (move > 0))[:, None] * normal
    return as_mesh(vertices, mesh.faces)
