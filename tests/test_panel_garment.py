import numpy as np
import pytest
import torch

from swingar_pyg.geometry.mesh import boundary_edges, mesh_edges
from swingar_pyg.world.catalogue import fit_garment, garment_spec
from swingar_pyg.world.panel_garment import (
    JumpsuitSpec,
    Pattern,
    TShirtSpec,
    sew_panels,
    triangulate_pattern,
)
from tests.extras import require


def euler_and_loops(faces: np.ndarray) -> tuple[int, int, int]:
    """Euler characteristic, boundary loops, and edges used by more than two faces."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    vertices = len(np.unique(faces))
    boundary = boundary_edges(faces)
    n = faces.max() + 1
    graph = coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), (n, n))
    _, label = connected_components(graph, directed=False)
    loops = len(np.unique(label[np.unique(boundary)])) if len(boundary) else 0
    return vertices - len(unique) + len(faces), loops, int((counts > 2).sum())


@pytest.mark.parametrize('opening, expected', [([True, False, False, False], (1, 1)),
                                               ([True, False, True, False], (0, 2))])
def test_two_sewn_panels_close_into_a_bag_or_a_tube(opening, expected):
    square = Pattern(np.array([[0.0, 0.0], [0.4, 0.0], [0.4, 0.4], [0.0, 0.4]]),
                     np.array(opening))
    for jitter in (0.0, 0.35):
        cut = triangulate_pattern(square, 600, jitter=jitter, seed=3)
        on_seam = cut.on_seam
        front, back, faces = sew_panels(cut.points, cut.triangles, on_seam)
        assert euler_and_loops(faces) == (*expected, 0)
        assert 500 < faces.max() + 1 < 700
        # seam points are one vertex on both panels, the others two
        used = front >= 0
        assert np.array_equal(front[used & on_seam], back[used & on_seam])
        assert not np.isin(back[used & ~on_seam], front).any()


@pytest.fixture(scope='module')
def anny():
    require('anny')
    from swingar_pyg.world.body import AnnyBody

    body = AnnyBody()
    return body, body.default_shape()


@pytest.mark.parametrize('spec, holes, top', [
    (TShirtSpec(vertices=600), 4, 'Neck'), (TShirtSpec(vertices=3000, jitter=0.3), 4, 'Neck'),
    (JumpsuitSpec(vertices=800, leg=0.5), 3, 'Spine1'), (JumpsuitSpec(vertices=4000), 3, 'Spine1')])
def test_sewn_garments_are_one_surface_outside_the_body_pinned_at_the_top(anny, spec, holes, top):
    from swingar_pyg.geometry.signed_distance import BodySurface

    body, shape = anny
    garment = fit_garment(garment_spec({'kind': type(spec).__name__[:-4].lower(),
                                        **spec.__dict__}), body, shape)
    mesh = garment.mesh
    assert garment.name == spec.name
    assert euler_and_loops(mesh.faces) == (2 - holes, holes, 0)
    assert 0.85 * spec.vertices < mesh.num_vertices < 1.15 * spec.vertices
    rest = body.rest_vertices(shape).numpy().astype(np.float64)
    depth, _ = BodySurface(rest, body.faces.numpy()).signed_distance(mesh.vertices)
    assert depth.max() < -0.99 * spec.clearance  # outside, at least the clearance away
    assert np.allclose(garment.fit, -depth, atol=1e-6)
    # faces point away from the body: from the nearest body vertex to the face centre
    from scipy.spatial import cKDTree

    v, f = mesh.vertices, mesh.faces
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    centres = v[f].mean(axis=1)
    nearest = rest[cKDTree(rest).query(centres)[1]]
    assert (np.einsum('ij,ij->i', normals, centres - nearest) > 0).mean() > 0.9
    # pinned: the top opening only (the neckline or the chest line), followed by the torso
    joints = body.pose(shape, torch.eye(3).expand(1, len(body.joint_names), 3, 3),
                       torch.zeros(1, 3)).joint_positions[0]
    top_z = float(joints[body.joint_names.index(top), 2])
    assert np.abs(v[garment.pinned, 2] - top_z).max() < 0.06
    pinned_x = v[garment.pinned, 0]
    assert pinned_x.min() < -0.05 and pinned_x.max() > 0.05  # across the whole opening
    assert abs(pinned_x.mean()) < 0.02  # symmetric
    assert set(garment.pinned) <= set(np.unique(boundary_edges(f)))


def test_a_sewn_tshirt_swings_on_a_walk_without_tearing(anny):
    from swingar_pyg.sim import XPBDSettings
    from swingar_pyg.world.motion_library import make_motion
    from swingar_pyg.world.sequence import simulate_sequence

    body, shape = anny
    garment = fit_garment(TShirtSpec(vertices=400), body, shape)
    motion = make_motion('walk', body, shape, seconds=0.5, fps=30)
    sequence = simulate_sequence(body, shape, garment, motion,
                                 XPBDSettings(substeps=20, iterations=2, settle_frames=5))
    result = sequence.result
    assert torch.isfinite(result.positions).all()
    assert result.max_stretch.max() < 0.15 and result.mean_stretch.mean() < 0.01
    assert np.nanmax(result.penetration) < 0.01


def test_jumpsuits_of_different_cuts_have_different_names():
    assert JumpsuitSpec(leg=1.0, vertices=800).name == 'jumpsuit-g1.00-n800-grid'
    loose = JumpsuitSpec(leg=1.0, vertices=800, clearance=0.05, crotch_drop=0.2)
    assert loose.name == 'jumpsuit-g1.00-n800-grid-e0.04-f0.05-c0.05-d0.20'
    assert loose.name != JumpsuitSpec(leg=1.0, vertices=800, clearance=0.05).name


def test_the_jumpsuits_inseams_meet_crotch_drop_below_the_hip_joints(anny):
    body, shape = anny
    joints = body.pose(shape, torch.eye(3).expand(1, len(body.joint_names), 3, 3),
                       torch.zeros(1, 3)).joint_positions[0]
    hip_z = float(joints[body.joint_names.index('LeftUpLeg'), 2])
    crotch = {}
    for drop in (0.09, 0.2):
        mesh = fit_garment(JumpsuitSpec(vertices=800, crotch_drop=drop), body, shape).mesh
        v, f = mesh.vertices, mesh.faces
        # the crotch: the lowest vertex joined to both the left and the right half
        edges = mesh_edges(f)
        edges = np.concatenate([edges, edges[:, ::-1]])
        left = np.zeros(len(v), bool)
        right = np.zeros(len(v), bool)
        np.logical_or.at(left, edges[:, 0], v[edges[:, 1], 0] > 0.005)
        np.logical_or.at(right, edges[:, 0], v[edges[:, 1], 0] < -0.005)
        crotch[drop] = v[left & right, 2].min()
        # the seam is lifted off the body but keeps its height (to the triangles' size)
        assert abs(crotch[drop] - (hip_z - drop)) < 0.025, (drop, crotch[drop], hip_z)
    assert crotch[0.09] - crotch[0.2] > 0.09
    with pytest.raises(ValueError, match='crotch_drop 0.25 m leaves no leg'):
        fit_garment(JumpsuitSpec(vertices=800, leg=0.3, crotch_drop=0.25), body, shape)


@pytest.mark.parametrize('kind, kwargs, message', [
    ('tshirt', {'length': 2.0}, 'TShirtSpec.length must be in'),
    ('tshirt', {'vertices': 50}, 'at least 200 vertices'),
    ('jumpsuit', {'leg': 0.1}, 'JumpsuitSpec.leg must be in'),
    ('jumpsuit', {'clearance': 0.0}, 'clearance must be in'),
    ('jumpsuit', {'crotch_drop': 0.5}, 'JumpsuitSpec.crotch_drop must be in'),
    ('poncho', {}, "unknown garment kind 'poncho'")])
def test_bad_sewn_garment_specs_are_refused(kind, kwargs, message):
    with pytest.raises(ValueError, match=message):
        garment_spec({'kind': kind, **kwargs})


@pytest.mark.slow
def test_the_full_configs_sewn_garments_fit_every_body_shape(anny):
    """Every t-shirt and jumpsuit of configs/data/full.yaml on its four body shapes and
    on the all-1 body: the right holes and outside the body (~2 minutes)."""
    from swingar_pyg.world.dataset import DatasetConfig

    body, _ = anny
    config = DatasetConfig.from_yaml('configs/data/full.yaml')
    specs = {g for split in config.garments.values() for g in split
             if isinstance(g, (TShirtSpec, JumpsuitSpec))}
    assert len(specs) == 6
    for shape in list(config.body_shapes) + [[1.0] * 6]:
        for spec in specs:
            garment = fit_garment(spec, body, torch.tensor(shape, dtype=torch.float32))
            holes = 4 if isinstance(spec, TShirtSpec) else 3
            assert euler_and_loops(garment.mesh.faces) == (2 - holes, holes, 0), spec.name
            assert garment.fit.min() > 0.7 * spec.clearance, (spec.name, shape)
