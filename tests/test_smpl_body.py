"""The SMPL adapter, on a synthetic model file in SMPL's format (no SMPL data here)."""

import math
import pickle

import numpy as np
import pytest
import torch

from tests.extras import require

smplx = require('smplx')

from swingar_pyg.world.smpl_body import SMPL_JOINTS, SMPL_TO_Z_UP, SMPLBody  # noqa: E402

PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)
# A T-pose skeleton in SMPL's frame: metres, +Y up, facing +Z
REST = np.array([
    [0.0, 0.95, 0.0], [0.09, 0.86, 0.0], [-0.09, 0.86, 0.0], [0.0, 1.05, 0.0],
    [0.1, 0.5, 0.0], [-0.1, 0.5, 0.0], [0.0, 1.17, 0.0], [0.1, 0.1, 0.0], [-0.1, 0.1, 0.0],
    [0.0, 1.22, 0.02], [0.1, 0.03, 0.12], [-0.1, 0.03, 0.12], [0.0, 1.45, 0.0],
    [0.08, 1.38, 0.0], [-0.08, 1.38, 0.0], [0.0, 1.55, 0.03], [0.18, 1.4, 0.0],
    [-0.18, 1.4, 0.0], [0.45, 1.4, 0.0], [-0.45, 1.4, 0.0], [0.7, 1.4, 0.0],
    [-0.7, 1.4, 0.0], [0.78, 1.4, 0.0], [-0.78, 1.4, 0.0]])


def synthetic_smpl(path, pose_blend: float = 1e-3):
    """An SMPL-format .pkl with made-up geometry: 6890 vertices on the bones (the first
    24 at the joints, which the regressor reads), two joints per vertex, random blend
    shapes."""
    rng = np.random.default_rng(0)
    vertices = np.zeros((6890, 3))
    weights = np.zeros((6890, 24))
    vertices[:24] = REST
    weights[np.arange(24), np.arange(24)] = 1.0
    children = [k for k in range(1, 24)]
    for i in range(24, 6890):
        child = children[rng.integers(len(children))]
        parent = PARENTS[child]
        t = rng.uniform()
        direction = rng.normal(size=3)
        vertices[i] = REST[parent] + t * (REST[child] - REST[parent]) + 0.05 * direction / \
            np.linalg.norm(direction)
        weights[i, parent], weights[i, child] = 1 - 0.5 * t, 0.5 * t
    regressor = np.zeros((24, 6890))
    regressor[np.arange(24), np.arange(24)] = 1.0
    shapedirs = 0.01 * rng.normal(size=(6890, 3, 10))
    shapedirs[:, 1, 0] = 0.05 * vertices[:, 1]  # beta 0: taller
    kintree = np.array([[4294967295] + list(PARENTS[1:]), list(range(24))], dtype=np.int64)
    faces = rng.integers(0, 6890, size=(2000, 3)).astype(np.uint32)
    model = {'v_template': vertices, 'weights': weights, 'J_regressor': regressor,
             'shapedirs': shapedirs, 'posedirs': pose_blend * rng.normal(size=(6890, 3, 207)),
             'kintree_table': kintree, 'f': faces}
    with open(path, 'wb') as file:
        pickle.dump(model, file)
    return path


@pytest.fixture(scope='module')
def smpl(tmp_path_factory):
    return SMPLBody(synthetic_smpl(tmp_path_factory.mktemp('smpl') / 'SMPL_NEUTRAL.pkl'))


def test_rest_pose_is_z_up_with_the_root_at_the_origin(smpl):
    assert smpl.joint_names == SMPL_JOINTS and smpl.parents == PARENTS
    shape = torch.zeros(10)
    rest = smpl.pose(shape, torch.eye(3).expand(1, 24, 3, 3), torch.zeros(1, 3))
    assert torch.allclose(rest.joint_positions[0, 0], torch.zeros(3), atol=1e-6)
    head = rest.joint_positions[0, SMPL_JOINTS.index('head')]
    assert head[2] > 0.5 and abs(head[1]) < 0.1  # +Y up became +Z up
    assert torch.allclose(rest.joint_transforms[0], torch.eye(4).expand(24, 4, 4), atol=1e-6)
    taller = smpl.rest_vertices(torch.tensor([2.0] + [0.0] * 9))
    assert np.ptp(taller[:, 2].numpy()) > np.ptp(rest.vertices[0, :, 2].numpy())


def test_pose_matches_smplx_forward_in_the_converted_frame(smpl):
    from smplx.lbs import batch_rodrigues

    torch.manual_seed(0)
    axis_angle = 0.6 * torch.randn(3, 24, 3)
    betas = torch.randn(10)
    translation = torch.randn(3, 3)
    # ours: rotations in the Z-up frame; smplx: the same rotations in its own frame
    smpl_rotations = batch_rodrigues(axis_angle.reshape(-1, 3)).reshape(3, 24, 3, 3)
    ours = SMPL_TO_Z_UP @ smpl_rotations @ SMPL_TO_Z_UP.T
    posed = smpl.pose(betas, ours, translation)
    model = smpl._model
    reference = model(betas=betas[None].expand(3, -1), global_orient=axis_angle[:, 0],
                      body_pose=axis_angle[:, 1:].reshape(3, -1))
    rest_root = model(betas=betas[None]).joints[0, 0]
    expected = (reference.vertices - rest_root) @ SMPL_TO_Z_UP.T + translation[:, None]
    assert torch.allclose(posed.vertices, expected, atol=1e-5)
    assert torch.allclose(posed.joint_positions[:, 0], translation, atol=1e-5)


def test_skinning_transforms_move_the_rest_mesh_up_to_pose_blend_shapes(tmp_path):
    from swingar_pyg.geometry.skinning import linear_blend_skinning

    rigid = SMPLBody(synthetic_smpl(tmp_path / 'SMPL_NEUTRAL.pkl', pose_blend=0.0))
    torch.manual_seed(1)
    from swingar_pyg.geometry.skinning import axis_angle_to_matrix

    rotations = axis_angle_to_matrix(0.5 * torch.randn(2, 24, 3))
    shape = torch.randn(10)
    posed = rigid.pose(shape, rotations, torch.tensor([[0.0, 0.0, 0.0], [1.0, -2.0, 0.5]]))
    indices, weights = rigid.skinning()
    skinned = linear_blend_skinning(rigid.rest_vertices(shape), indices, weights,
                                    posed.joint_transforms)
    assert torch.allclose(skinned, posed.vertices, atol=1e-5)


def test_a_cmu_clip_retargets_onto_smpl(smpl):
    from swingar_pyg.world.motion_library import make_motion
    from swingar_pyg.world.smpl_body import CMU_TO_SMPL

    motion = make_motion('cmu_02_01_walk_delfem2', smpl, torch.zeros(10), seconds=2.0,
                         joint_map=CMU_TO_SMPL)
    posed = smpl.pose(torch.zeros(10), motion.rotations, motion.translation)
    assert torch.isfinite(posed.vertices).all()
    knee = motion.rotations[:, SMPL_JOINTS.index('left_knee')]
    angle = torch.arccos(((knee.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1))
    assert math.degrees(float(angle.max() - angle.min())) > 20  # the knee bends in the walk
    # the collars (CMU's LeftShoulder, a clavicle) keep SMPL's build: the shoulders stay as
    # far apart as at rest
    rest = smpl.pose(torch.zeros(10), torch.eye(3).expand(1, 24, 3, 3), torch.zeros(1, 3))
    left, right = SMPL_JOINTS.index('left_shoulder'), SMPL_JOINTS.index('right_shoulder')
    width = (posed.joint_positions[:, left] - posed.joint_positions[:, right]).norm(dim=-1)
    rest_width = (rest.joint_positions[0, left] - rest.joint_positions[0, right]).norm()
    assert torch.allclose(width, rest_width.expand_as(width), rtol=1e-3)


def test_bad_input_is_refused(smpl, tmp_path):
    with pytest.raises(ValueError, match='no SMPL model at'):
        SMPLBody(tmp_path / 'none.pkl')
    with pytest.raises(ValueError, match='10 finite SMPL betas'):
        smpl.rest_vertices(torch.zeros(3))
    with pytest.raises(ValueError, match='rotations must have shape'):
        smpl.pose(torch.zeros(10), torch.eye(3).expand(1, 23, 3, 3), torch.zeros(1, 3))
