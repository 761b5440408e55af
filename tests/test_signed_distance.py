import numpy as np
import trimesh

from swingar_pyg.geometry.signed_distance import inside_share, inside_share_trimesh

from .extras import require


def test_warp_and_trimesh_ray_parity_agree_on_a_deforming_body():
    require('anny')  # warp comes with the body extra
    from swingar_pyg.geometry.warp_inside import inside_share_warp

    ball = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    axes = np.array([[1.0, 0.5, 1.5], [0.7, 0.35, 1.05], [1.3, 0.65, 1.95], [0.9, 0.8, 1.0]])
    vertices = ball.vertices[None] * axes[:, None]  # an ellipsoid changing every frame
    rng = np.random.default_rng(0)
    points = []
    for scale in axes:  # 2000 points a frame, none within 2 % of the faceted surface
        candidates = rng.uniform(-1.6, 1.6, size=(6000, 3)) * scale
        radius = np.linalg.norm(candidates / scale, axis=-1)
        points.append(candidates[np.abs(radius - 1) > 0.02][:2000])
    points = np.stack(points)
    expected = (np.linalg.norm(points / axes[:, None], axis=-1) < 1).mean(axis=1)
    warp_share = inside_share_warp(vertices, ball.faces, points)
    assert np.array_equal(warp_share, inside_share_trimesh(vertices, ball.faces, points))
    assert np.array_equal(warp_share, expected)  # the analytic ellipsoid
    assert np.array_equal(inside_share(vertices, ball.faces, points), warp_share)
