import math

import numpy as np
import pytest
import torch

from swingar_pyg.geometry import closest_face_signed_distance, split_quads, vertex_normals
from swingar_pyg.geometry.mesh import as_mesh
from swingar_pyg.geometry.skinning import linear_blend_skinning
from swingar_pyg.world.garment import pin_bands
from swingar_pyg.world.motion import EXTREME_MOTIONS, PROCEDURAL_MOTIONS, procedural_motion
from swingar_pyg.world.skirt import (
    DressSpec,
    SkirtSpec,
    body_envelope,
    fit_procedural_skirt,
    procedural_skirt,
)
from tests.extras import require

CMU_JOINTS = ('Hips', 'LHipJoint', 'LeftUpLeg', 'LeftLeg', 'LeftFoot', 'LowerBack', 'Spine',
              'Spine1', 'LeftArm', 'RHipJoint', 'RightUpLeg', 'RightLeg', 'RightFoot',
              'RightArm', 'LeftForeArm', 'RightForeArm')


def cylinder_body(radius=0.15, bottom=-0.9, top=0.6, rings=40, segments=48):
    """An open vertical tube (outward-facing triangles): a stand-in body for fitting."""
    theta = np.linspace(-math.pi, math.pi, segments, endpoint=False)
    z = np.linspace(bottom, top, rings)
    t, zz = np.meshgrid(theta, z)
    points = np.stack([radius * np.cos(t), radius * np.sin(t), zz], axis=-1).reshape(-1, 3)
    index = np.arange(rings * segments).reshape(rings, segments)
    corners = (index[:-1], np.roll(index[:-1], -1, axis=1), np.roll(index[1:], -1, axis=1),
               index[1:])
    faces = split_quads(*corners, np.zeros(corners[0].shape, dtype=bool))
    return points, faces, np.zeros((len(points), 1), dtype=np.int64), np.ones((len(points), 1))


@pytest.mark.parametrize('kind', PROCEDURAL_MOTIONS + EXTREME_MOTIONS)
def test_procedural_motions_start_at_rest_and_are_rotations(kind):
    motion = procedural_motion(kind, CMU_JOINTS, seconds=2.0, fps=30)
    assert motion.rotations.shape == (60, len(CMU_JOINTS), 3, 3)
    assert motion.translation.shape == (60, 3)
    assert torch.allclose(motion.rotations[0], torch.eye(3).expand(len(CMU_JOINTS), 3, 3))
    assert torch.allclose(motion.translation[0], torch.zeros(3))
    r = motion.rotations
    assert torch.allclose(r @ r.transpose(-1, -2), torch.eye(3).expand_as(r), atol=1e-5)
    assert torch.allclose(torch.linalg.det(r), torch.ones(r.shape[:2]), atol=1e-5)
    assert (r[1:] - r[:-1]).abs().max() > 0 or motion.translation.abs().max() > 0


def test_extreme_motions_reach_extreme_angles():
    def largest_angle(motion, joint):
        r = motion.rotations[:, CMU_JOINTS.index(joint)]
        cosine = ((r.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1)
        return math.degrees(float(torch.arccos(cosine).max()))

    split = procedural_motion('leg_split', CMU_JOINTS, seconds=4.0)
    assert largest_angle(split, 'LeftUpLeg') > 95 and largest_angle(split, 'RightUpLeg') > 70
    cross = procedural_motion('arm_cross', CMU_JOINTS, seconds=2.0)
    assert largest_angle(cross, 'LeftArm') > 100


def test_mirroring_twice_is_the_identity_and_swaps_sides():
    kick = procedural_motion('kick', CMU_JOINTS)
    mirrored = procedural_motion('kick', CMU_JOINTS, mirror=True)
    left, right = CMU_JOINTS.index('LeftUpLeg'), CMU_JOINTS.index('RightUpLeg')
    reflect = torch.diag(torch.tensor([-1.0, 1.0, 1.0]))
    # Reflecting the left leg's rotation in x gives the mirrored right leg's.
    assert torch.allclose(reflect @ kick.rotations[:, left] @ reflect,
                          mirrored.rotations[:, right], atol=1e-6)


def test_motion_errors():
    with pytest.raises(ValueError, match="unknown motion 'moonwalk'"):
        procedural_motion('moonwalk', CMU_JOINTS)
    with pytest.raises(ValueError, match="no joint 'LeftUpLeg'"):
        procedural_motion('kick', ('Hips',))


@pytest.mark.parametrize('spec', [SkirtSpec(), SkirtSpec(length=0.9, flare=0.0, vertices=800),
                                  SkirtSpec(length=0.3, flare=0.7, vertices=400, jitter=0.3),
                                  SkirtSpec(vertices=6000)],
                         ids=['a-line', 'straight-long', 'circle-mini-irregular',
                              'finer-than-the-body'])
def test_skirt_fits_outside_the_body(spec):
    body, faces, indices, weights = cylinder_body()
    garment = procedural_skirt(spec, body, faces, ('Hips',), indices, weights)
    v = garment.mesh.vertices
    radial = np.linalg.norm(v[:, :2], axis=1)
    # The tube is a 48-gon: its flat sides lie 0.15 cos(pi / 48) from the axis.
    assert radial.min() >= 0.15 * math.cos(math.pi / 48) + spec.clearance - 1e-9
    assert abs(garment.mesh.num_vertices - spec.vertices) < 0.15 * spec.vertices
    assert np.allclose(v[garment.pinned, 2], spec.waist_height)
    assert np.isclose(v[:, 2].min(), spec.waist_height - spec.length)
    normals = vertex_normals(torch.from_numpy(v), torch.from_numpy(garment.mesh.faces)).numpy()
    assert (np.sum(normals[:, :2] * v[:, :2], axis=1) > 0).mean() > 0.99  # outward
    assert garment.skin_indices.shape == (len(v), 1)
    # The fit attribute is the signed distance to the tube: radius - 0.15 here.
    assert np.allclose(garment.fit, radial - 0.15, atol=2e-3)


def test_body_envelope_is_the_convex_hull_of_a_sparse_cross_section():
    # Six vertices of a regular hexagon (circumradius R, centred on the axis): every
    # direction meets the hull, at R cos(pi/6) / cos(theta - theta_side), theta_side the
    # direction of the nearest side's midpoint; bins between vertices are not holes.
    R = 0.1
    corner = np.arange(6) * np.pi / 3
    ring = np.stack([R * np.cos(corner), R * np.sin(corner), np.zeros(6)], axis=-1)
    angles = np.linspace(-np.pi, np.pi, 361)[:-1]
    envelope = body_envelope(ring, np.ones(6, bool), np.array([0.0, 1.0]), angles)
    side = (np.floor(angles / (np.pi / 3)) + 0.5) * np.pi / 3
    expected = R * np.cos(np.pi / 6) / np.cos(angles - side)
    np.testing.assert_allclose(envelope[0], expected, rtol=1e-9)
    assert (envelope[1] == 0).all()  # no vertex at that height
    # Two legs: the hull bridges the gap between them instead of dipping into it.
    legs = np.concatenate([ring + [0.15, 0.0, 0.0], ring - [0.15, 0.0, 0.0]])
    gap = body_envelope(legs, np.ones(12, bool), np.array([0.0]), np.array([np.pi / 2]))
    np.testing.assert_allclose(gap, [[R * np.cos(np.pi / 6)]], rtol=1e-9)
    # No hull (three vertices on a line) or a hull beside the axis: the farthest vertex.
    line = np.array([[0.0, 0.1, 2.0], [0.0, 0.2, 2.0], [0.0, 0.3, 2.0]])
    aside = 0.1 * ring + [0.5, 0.0, 3.0]
    points = np.concatenate([ring, line, aside])
    centre = points[:, :2].mean(axis=0)
    far = body_envelope(points, np.ones(len(points), bool), np.array([2.0, 3.0]), angles[:3])
    for row, section in zip(far, (line, aside)):
        np.testing.assert_allclose(row, np.linalg.norm(section[:, :2] - centre, axis=1).max())


def test_irregular_skirt_has_a_different_topology():
    body, faces, indices, weights = cylinder_body()
    grid = procedural_skirt(SkirtSpec(vertices=600), body, faces, ('Hips',), indices, weights)
    irregular = procedural_skirt(SkirtSpec(vertices=600, jitter=0.3), body, faces, ('Hips',),
                                 indices, weights)
    degree = [np.bincount(g.mesh.faces.ravel()) for g in (grid, irregular)]
    assert len(np.unique(degree[1])) > len(np.unique(degree[0]))


def test_a_slit_opens_one_column_of_cells_at_the_back_up_from_the_hem():
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    from swingar_pyg.geometry.mesh import boundary_edges, mesh_edges

    body, faces, indices, weights = cylinder_body()
    closed = procedural_skirt(SkirtSpec(length=0.6, vertices=600), body, faces, ('Hips',),
                              indices, weights)
    spec = SkirtSpec(length=0.6, vertices=600, slit=0.25)
    slit = procedural_skirt(spec, body, faces, ('Hips',), indices, weights)
    assert slit.name == closed.name + '-s0.25'
    np.testing.assert_array_equal(slit.mesh.vertices, closed.mesh.vertices)
    v = slit.mesh.vertices
    hem = spec.waist_height - spec.length
    opened = np.array(sorted(set(map(tuple, boundary_edges(slit.mesh.faces)))
                             - set(map(tuple, boundary_edges(closed.mesh.faces)))))
    # The new border: both sides of the open column (an edge per open row each) and the
    # top of its highest open cell; the hem edge under the column is gone.
    rows = (len(closed.mesh.faces) - len(slit.mesh.faces)) // 2  # two triangles a cell
    ends = v[opened]
    vertical = ends[:, 0, 2] != ends[:, 1, 2]
    assert rows > 0 and len(opened) == 2 * rows + 1 and vertical.sum() == 2 * rows
    assert (ends[..., 1] > 0.1).all()  # at the back, +y
    assert ends[..., 2].min() == pytest.approx(hem)
    ring = spec.length / (len(np.unique(v[:, 2])) - 1)
    top = ends[~vertical][0, :, 2]
    assert (top == ends[..., 2].max()).all()
    assert hem + spec.slit - ring < top[0] <= hem + spec.slit + 1e-9
    # Still one piece, and the faces it keeps are the closed skirt's.
    n = slit.mesh.num_vertices
    edges = mesh_edges(slit.mesh.faces)
    graph = coo_array((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    assert connected_components(graph, directed=False)[0] == 1
    assert set(map(tuple, slit.mesh.faces)) < set(map(tuple, closed.mesh.faces))


def test_closest_face_signed_distance_matches_a_sphere():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.2)
    points = np.random.default_rng(0).normal(size=(200, 3))
    points *= np.random.default_rng(1).uniform(0.02, 0.4, size=(200, 1)) / np.linalg.norm(
        points, axis=1, keepdims=True)
    distance = closest_face_signed_distance(points, sphere.vertices, sphere.faces)
    # Positive inside; the faceted sphere lies within 0.5 mm inside the analytic one.
    assert np.allclose(distance, 0.2 - np.linalg.norm(points, axis=1), atol=6e-4)


@pytest.mark.parametrize('kwargs, message', [({'length': 3.0}, 'length'),
                                             ({'flare': 1.0}, 'flare'),
                                             ({'vertices': 10}, 'at least 64'),
                                             ({'jitter': -0.1}, 'jitter'),
                                             ({'jitter': 0.5}, 'jitter'),
                                             ({'slit': -0.1}, 'slit'),
                                             ({'length': 0.5, 'slit': 0.5}, 'slit')])
def test_skirt_spec_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SkirtSpec(**kwargs)


@pytest.fixture(scope='module')
def anny_body():
    require('anny')
    from swingar_pyg.world.body import AnnyBody

    return AnnyBody()


def test_anny_rest_pose_frame_and_size(anny_body):
    rest = anny_body.rest_vertices(anny_body.default_shape())
    assert rest.shape == (13718, 3)
    height = rest[:, 2].max() - rest[:, 2].min()
    assert 1.5 < height < 1.8  # metres, +Z up
    assert -0.95 < rest[:, 2].min() < -0.8  # feet below the hips at the origin
    faces = anny_body.faces
    assert faces.min() >= 0 and faces.max() < len(rest)
    assert len(anny_body.joint_names) == len(anny_body.parents) == 31


def test_anny_pose_is_linear_blend_skinning_of_the_rest_pose(anny_body):
    shape = torch.tensor([0.2, 0.7, 0.5, 0.8, 0.3, 0.6])
    motion = procedural_motion('kick', anny_body.joint_names, seconds=0.5)
    posed = anny_body.pose(shape, motion.rotations, motion.translation + torch.tensor([0, 0, 0.1]))
    rest = anny_body.rest_vertices(shape)
    indices, weights = anny_body.skinning()
    skinned = linear_blend_skinning(rest, indices, weights, posed.joint_transforms)
    assert (skinned - posed.vertices).abs().max() < 1e-5
    assert torch.allclose(posed.joint_positions[:, 0, 2], torch.full((15,), 0.1))


def test_anny_rejects_bad_input(anny_body):
    with pytest.raises(ValueError, match='must lie in'):
        anny_body.rest_vertices(torch.full((6,), 1.5))
    with pytest.raises(ValueError, match='6 values'):
        anny_body.rest_vertices(torch.zeros(3))
    with pytest.raises(ValueError, match='rotations must have shape'):
        anny_body.pose(anny_body.default_shape(), torch.eye(3).expand(2, 5, 3, 3),
                       torch.zeros(2, 3))


def test_skirt_swings_on_a_walking_body_without_stretch_or_penetration(anny_body):
    from swingar_pyg.sim import XPBDSettings
    from swingar_pyg.world.sequence import simulate_sequence

    shape = anny_body.default_shape()
    garment = fit_procedural_skirt(SkirtSpec(vertices=800), anny_body, shape)
    # Walking swings the thighs into the skirt: the case that once pushed cloth
    # through a leg (contacts paired against the body's end-of-frame pose).
    motion = procedural_motion('walk', anny_body.joint_names, seconds=2.0)
    # At 100 substeps (configs/data/quickstart.yaml's) this walk's largest stretch is 3-6 %
    # whatever micrometre the garment is moved by (simulator revision 7); at 50 it is
    # chaotic, 5-20 % on this skirt.
    settings = XPBDSettings(settle_frames=5, substeps=100)
    sequence = simulate_sequence(anny_body, shape, garment, motion, settings)
    result, skinned = sequence.result, sequence.rigid
    assert torch.isfinite(result.positions).all()
    assert result.max_stretch.max() < 0.08
    assert np.nanmax(result.penetration) == 0
    # The hem lags and swings (rigid skinning would carry it along).
    assert (result.positions - skinned).norm(dim=-1).max() > 0.02


@pytest.mark.parametrize('spec', [SkirtSpec(vertices=600), SkirtSpec(vertices=4000),
                                  DressSpec(vertices=400), DressSpec(vertices=1500),
                                  DressSpec(length=1.0, flare=0.3, vertices=1200, jitter=0.3)],
                         ids=['skirt-600', 'skirt-4000', 'dress-400', 'dress-1500',
                              'dress-1200-irregular'])
def test_skirts_and_dresses_of_any_resolution_start_outside_the_body(anny_body, spec):
    # A dress of 1,000-1,500 vertices once started up to 2 cm inside the chest: the
    # envelope, binned by angle, had holes where the body's vertices are sparse.
    import trimesh

    shape = anny_body.default_shape()
    rest = anny_body.rest_vertices(shape).numpy()
    garment = fit_procedural_skirt(spec, anny_body, shape)
    body = trimesh.Trimesh(rest, anny_body.faces.numpy(), process=False)
    # Inside: behind the face nearest to the point (exact closest point on the mesh).
    closest, _, face = trimesh.proximity.closest_point(body, garment.mesh.vertices)
    side = ((garment.mesh.vertices - closest) * body.face_normals[face]).sum(axis=1)
    assert (side > 0).all()


def test_the_waistband_follows_the_pelvis_not_the_thighs(anny_body):
    garment = fit_procedural_skirt(SkirtSpec(), anny_body, anny_body.default_shape())
    names = anny_body.joint_names
    used = {names[j] for j, w in zip(garment.skin_indices[garment.pinned].ravel(),
                                     garment.skin_weights[garment.pinned].ravel()) if w > 0}
    assert used <= {'Hips', 'LowerBack', 'Spine'}
    assert np.allclose(garment.skin_weights[garment.pinned].sum(1), 1.0)
    free = np.setdiff1d(np.arange(garment.mesh.num_vertices), garment.pinned)
    legs = {names[j] for j in garment.skin_indices[free].ravel()}
    assert any('Leg' in n for n in legs)  # the rest of the skirt keeps the body's weights


def test_pin_bands_are_the_pieces_of_pinned_mesh_edges():
    # two separate quad strips, each pinned along its top row, and a triangle pinned at one
    # corner
    strip = split_quads(np.array([[0, 1]]), np.array([[1, 2]]), np.array([[4, 5]]),
                        np.array([[3, 4]]), np.zeros((1, 2), dtype=bool))
    vertices = np.array([[x, 0.0, z] for z in (1.0, 0.0) for x in (0.0, 1.0, 2.0)])
    triangle = np.array([[9.0, 0.0, 0.0], [10.0, 0.0, 0.0], [9.0, 0.0, 1.0]])
    mesh = as_mesh(np.concatenate([vertices, vertices + [5.0, 0.0, 0.0], triangle]),
                   np.concatenate([strip, strip + 6, [[12, 13, 14]]]))
    pinned = np.array([0, 1, 2, 6, 7, 8, 14])
    bands = pin_bands(mesh, pinned)
    assert sorted(pinned[b].tolist() for b in bands) == [[0, 1, 2], [6, 7, 8], [14]]
    assert pin_bands(mesh, np.zeros(0, dtype=np.int64)) == []


def test_a_dress_top_band_moves_as_one_where_the_body_skin_stretches(anny_body):
    # In a twist, anny's chest skin stretches by half under linear blend skinning; a band
    # skinned point by point with it stretched by 40 %. Each band shares one set of weights.
    from swingar_pyg.geometry.mesh import mesh_edges
    from swingar_pyg.sim import BodyCollider
    from swingar_pyg.sim.recording import signed_edge_strain
    from swingar_pyg.world.catalogue import fit_garment

    shape = anny_body.default_shape()
    dress = fit_garment(DressSpec(length=0.9, vertices=1000), anny_body, shape)
    motion = procedural_motion('twist', anny_body.joint_names, seconds=1.5)
    posed = anny_body.pose(shape, motion.rotations, motion.translation)
    band = dress.skin_weights[dress.pinned]
    assert np.allclose(band, band[0]) and np.allclose(band.sum(1), 1.0)

    def largest_strain(rest, moved, edges):
        rest, edges = torch.as_tensor(rest), torch.as_tensor(edges)
        length = (rest[edges[:, 0]] - rest[edges[:, 1]]).norm(dim=-1)
        return float(signed_edge_strain(torch.as_tensor(moved), edges, length).abs().max())

    body_rest = anny_body.rest_vertices(shape).numpy()
    chest = np.abs(body_rest[:, 2] - dress.mesh.vertices[dress.pinned, 2].mean()) < 0.03
    body_edges = mesh_edges(anny_body.faces.numpy())
    body_edges = body_edges[chest[body_edges].all(axis=1)]
    assert largest_strain(body_rest, posed.vertices, body_edges) > 0.3

    rest = torch.as_tensor(dress.mesh.vertices, dtype=torch.float32)
    moved = linear_blend_skinning(rest, torch.as_tensor(dress.skin_indices),
                                  torch.as_tensor(dress.skin_weights, dtype=torch.float32),
                                  posed.joint_transforms)
    pinned = np.isin(np.arange(dress.mesh.num_vertices), dress.pinned)
    edges = mesh_edges(dress.mesh.faces)
    band_edges = edges[pinned[edges].all(axis=1)]
    assert largest_strain(rest, moved, band_edges) < 0.01
    collider = BodyCollider(posed.vertices, anny_body.faces)
    for frame in range(motion.num_frames):
        assert (collider.signed_distance(frame, moved[frame, dress.pinned]) > 0).all()


def test_dress_hangs_from_the_chest_and_shipped_garments_pin_all_their_top_loops():
    require('anny')
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.catalogue import ShippedGarmentSpec, fit_garment
    from swingar_pyg.world.skirt import DressSpec

    body = AnnyBody()
    shape = body.default_shape()
    dress = fit_garment(DressSpec(length=0.9, vertices=400), body, shape)
    top = dress.mesh.vertices[dress.pinned, 2]
    assert np.allclose(top, DressSpec().waist_height) and dress.fit.min() > 0
    jumpsuit = fit_garment(ShippedGarmentSpec('overall_jumpsuit'), body, shape)
    finer = fit_garment(ShippedGarmentSpec('overall_jumpsuit', subdivisions=1), body, shape)
    assert finer.mesh.num_faces == 4 * jumpsuit.mesh.num_faces
    assert finer.name.endswith('-s1')
    # the bib's top edge (292 vertices) and the eight strap ends (4 x 8 + 4 x 7), not only
    # the highest loop; the legs' hems (18 each, 1.2 m lower) stay free
    assert len(jumpsuit.pinned) == 292 + 4 * 8 + 4 * 7


def test_arms_out_turns_both_upper_arms_away_symmetrically():
    require('anny')
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.motion import Motion, arms_out, mirror_motion
    from swingar_pyg.world.motion_library import make_motion

    body = AnnyBody()
    shape = body.default_shape()
    clip = make_motion('cmu_02_01_walk_delfem2', body, shape, seconds=1.0)
    names = body.joint_names
    hands = [names.index('LeftHand'), names.index('RightHand')]

    def hand_x(motion):  # the hands' sideways distance from the root, per frame and side
        posed = body.pose(shape, motion.rotations, motion.translation)
        return (posed.joint_positions[:, hands, 0] - posed.joint_positions[:, :1, 0]).abs()

    widths = [hand_x(arms_out(clip, degrees)) for degrees in (0, 10, 20)]
    assert torch.equal(widths[0], hand_x(clip))
    assert (widths[1] > widths[0] + 0.01).all() and (widths[2] > widths[1] + 0.01).all()
    # the same turn on both sides: mirroring commutes with it
    assert torch.allclose(mirror_motion(arms_out(clip, 15)).rotations,
                          arms_out(mirror_motion(clip), 15).rotations, atol=1e-6)
    eased = make_motion('cmu_02_01_walk_delfem2', body, shape, seconds=1.0, arms_out_degrees=20)
    assert torch.allclose(eased.rotations[0], torch.eye(3).expand_as(eased.rotations[0]),
                          atol=1e-6)  # still eased in from the rest pose
    with pytest.raises(ValueError, match=r'arms_out must be in \[-45, 45\]'):
        arms_out(clip, 60)
    with pytest.raises(ValueError, match='applies to captured clips'):
        make_motion('walk', body, shape, seconds=1.0, arms_out_degrees=10)
    legs_only = Motion('legs', clip.rotations[:, :3], clip.translation, clip.fps, names[:3])
    with pytest.raises(ValueError, match='upper-arm joints'):
        arms_out(legs_only, 10)
