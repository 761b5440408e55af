from pathlib import Path

import numpy as np
import pytest
import trimesh

from swingar_pyg.geometry.surface_embedding import embed_points, evaluate_embedding

SHARED_HM08 = Path(__file__).resolve().parents[2] / 'shared' / 'assets' / 'body' / 'hm08_base.obj'


@pytest.fixture(scope='module')
def sphere():
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    return np.asarray(ball.vertices), np.asarray(ball.faces)


def random_shell(count, inner, outer, seed=0):
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return directions * rng.uniform(inner, outer, size=(count, 1))


def test_embedding_is_exact_on_the_same_surface(sphere):
    vertices, faces = sphere
    points = random_shell(300, 0.15, 0.3)
    embedding = embed_points(points, vertices, faces)
    assert np.allclose(evaluate_embedding(embedding, vertices, faces), points, atol=1e-10)


def test_embedding_follows_a_moved_and_scaled_surface(sphere):
    vertices, faces = sphere
    points = random_shell(300, 0.21, 0.25, seed=1)
    q, _ = np.linalg.qr(np.random.default_rng(2).normal(size=(3, 3)))
    rotation = q * np.sign(np.linalg.det(q))
    moved = vertices @ rotation.T + [1.0, -2.0, 0.5]
    embedding = embed_points(points, vertices, faces)
    assert np.allclose(evaluate_embedding(embedding, moved, faces),
                       points @ rotation.T + [1.0, -2.0, 0.5], atol=1e-10)
    # Twice the size: a point keeps its height above the surface, not its radius.
    height = np.linalg.norm(points, axis=1) - 0.2
    grown = np.linalg.norm(evaluate_embedding(embedding, 2 * vertices, faces), axis=1)
    assert np.allclose(grown, 0.4 + height, atol=2e-3)


@pytest.fixture(scope='module')
def anny_body():
    pytest.importorskip('anny')
    from swingar_pyg.world.body import AnnyBody

    return AnnyBody()


@pytest.mark.skipif(not SHARED_HM08.exists(), reason='needs ../shared/assets/body/hm08_base.obj')
def test_shipped_hm08_body_is_regenerated_from_the_asset(anny_body):
    from swingar_pyg.world.garment_assets import _hm08_body, hm08_vertices_in_anny_order

    indices = anny_body._model.base_mesh_vertex_indices.numpy()
    assert np.allclose(_hm08_body(), hm08_vertices_in_anny_order(SHARED_HM08, indices), atol=1e-6)


@pytest.mark.parametrize('name', ['dress_skirt_knee', 'overall_jumpsuit', 'shorts'])
def test_shipped_garments_fit_any_body_shape(anny_body, name):
    import torch

    from swingar_pyg.world.garment_assets import fit_shipped_garment

    names = anny_body.joint_names
    for shape in (anny_body.default_shape(), torch.tensor([0.1, 0.8, 0.3, 0.9, 0.2, 0.5])):
        garment = fit_shipped_garment(name, anny_body, shape)
        assert 0.003 < np.median(garment.fit) < 0.03  # about a centimetre off the body
        assert (garment.fit < -0.005).mean() < 0.01  # at most a few tight spots
        z = garment.mesh.vertices[:, 2]
        assert z[garment.pinned].mean() > z.min() + 0.8 * (z.max() - z.min())  # at the top
        used = {names[j] for j, w in zip(garment.skin_indices[garment.pinned].ravel(),
                                         garment.skin_weights[garment.pinned].ravel()) if w > 0}
        assert not any(word in n for n in used for word in ('Leg', 'Arm', 'HipJoint'))
