"""Inside-or-outside of many points against a deforming closed mesh, by ray parity
in NVIDIA Warp: the mesh's BVH is built once and refitted per frame, where a
ray-tracing scene rebuilt per frame (trimesh's ``contains``) costs ~10x more for a
garment's thousand points on a 14k-vertex body."""

from __future__ import annotations

import numpy as np
import warp as wp

from swingar_pyg.verbosity import init_warp


@wp.kernel
def _inside(mesh: wp.uint64, points: wp.array(dtype=wp.vec3), max_distance: float,
            inside: wp.array(dtype=wp.int32)):
    i = wp.tid()
    query = wp.mesh_query_point_sign_parity(mesh, points[i], max_distance)
    inside[i] = wp.where(query.result and query.sign < 0.0, 1, 0)


def inside_share_warp(body_vertices: np.ndarray, faces: np.ndarray,
                      points: np.ndarray) -> np.ndarray:
    """Per frame, the share of ``points`` ``(T, M, 3)`` inside the closed mesh
    ``body_vertices`` ``(T, V, 3)`` with triangles ``faces`` (ray parity, float32)."""
    init_warp()
    mesh = wp.Mesh(points=wp.array(body_vertices[0], dtype=wp.vec3, device="cpu"),
                   indices=wp.array(np.asarray(faces, np.int32).reshape(-1), dtype=wp.int32,
                                    device="cpu"))
    extent = body_vertices.max(axis=(0, 1)) - body_vertices.min(axis=(0, 1))
    reach = 2.0 * float(np.linalg.norm(extent)) + float(np.abs(points).max(initial=0.0))
    inside = wp.zeros(points.shape[1], dtype=wp.int32, device="cpu")
    shares = np.empty(points.shape[0])
    for t, (body, frame) in enumerate(zip(body_vertices, points)):
        if t:
            mesh.points.assign(body.astype(np.float32))
            mesh.refit()
        wp.launch(_inside, dim=len(frame), device="cpu",
                  inputs=[mesh.id, wp.array(frame, dtype=wp.vec3, device="cpu"), reach, inside])
        shares[t] = inside.numpy().mean()
    return shares
