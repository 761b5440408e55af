import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from swingar_pyg.world.bvh import read_bvh
from swingar_pyg.world.motion import ease_from_rest, mirror_motion, procedural_motion
from tests.extras import require
from tests.test_world import CMU_JOINTS

CHAIN = """HIERARCHY
ROOT Hips
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {root}
  JOINT Spine
  {{
    OFFSET 0 2 0
    CHANNELS 3 {spine}
    End Site
    {{
      OFFSET 0 1 0
    }}
  }}
  JOINT Leg
  {{
    OFFSET 1 -1 0
    CHANNELS 3 {leg}
    End Site
    {{
      OFFSET 0 -3 0
    }}
  }}
}}
MOTION
Frames: {frames}
Frame Time: 0.0083333
{rows}
"""

ORDERS = {'Z': 'Zrotation', 'X': 'Xrotation', 'Y': 'Yrotation'}


def write_chain(path, orders, angles, positions):
    channel = {name: ' '.join(ORDERS[a] for a in order) for name, order in orders.items()}
    rows = '\n'.join(' '.join(f'{v:.6f}' for v in np.concatenate([p, *a]))
                     for p, a in zip(positions, angles))
    path.write_text(CHAIN.format(frames=len(positions), rows=rows, **channel))


@pytest.mark.parametrize('orders', [{'root': 'ZYX', 'spine': 'ZXY', 'leg': 'XYZ'},
                                    {'root': 'YXZ', 'spine': 'XZY', 'leg': 'ZYX'}])
def test_any_channel_order_reads_back_the_rotations(tmp_path, orders):
    rng = np.random.default_rng(0)
    frames = 5
    angles = rng.uniform(-80, 80, size=(frames, 3, 3))
    positions = rng.normal(size=(frames, 3))
    write_chain(tmp_path / 'chain.bvh', orders, angles, positions)
    clip = read_bvh(tmp_path / 'chain.bvh')
    assert clip.joint_names == ('Hips', 'Spine', 'Leg')
    assert clip.parents.tolist() == [-1, 0, 0]
    for j, name in enumerate(('root', 'spine', 'leg')):
        expected = Rotation.from_euler(orders[name], angles[:, j], degrees=True).as_matrix()
        assert np.allclose(clip.local_rotations[:, j], expected, atol=1e-9)
    assert np.allclose(clip.root_positions, positions, atol=1e-6)
    # Forward kinematics: the leg joint sits at root + R_root @ offset.
    rotations, joints = clip.world()
    leg = positions + np.einsum('tij,j->ti', clip.local_rotations[:, 0], [1.0, -1.0, 0.0])
    assert np.allclose(joints[:, 2], leg, atol=1e-6)
    assert np.allclose(rotations[:, 2], clip.local_rotations[:, 0] @ clip.local_rotations[:, 2])


def test_resampling_keeps_the_samples_it_lands_on(tmp_path):
    rng = np.random.default_rng(1)
    write_chain(tmp_path / 'chain.bvh', {'root': 'ZYX', 'spine': 'ZYX', 'leg': 'ZYX'},
                rng.uniform(-30, 30, size=(9, 3, 3)), rng.normal(size=(9, 3)))
    clip = read_bvh(tmp_path / 'chain.bvh')
    at_30 = clip.resample(30.0)
    assert at_30.num_frames == 3  # 120 fps -> every 4th frame
    # 0.0083333 s is not exactly 1/120 s: the 30 fps grid drifts by 1e-5 of a frame.
    assert np.allclose(at_30.local_rotations, clip.local_rotations[::4], atol=1e-3)
    assert np.allclose(at_30.root_positions, clip.root_positions[::4], atol=1e-3)


@pytest.mark.parametrize('edit, message', [
    (lambda t: t.replace('HIERARCHY', 'HIERARCHI'), 'starts with HIERARCHY'),
    (lambda t: t.replace('Xrotation', 'Wrotation', 1), "unknown channel 'Wrotation'"),
    (lambda t: t.replace('Frames: 2', 'Frames: 3'), 'promises 3 frames'),
    (lambda t: t.rsplit('\n', 2)[0] + '\n1 2 3\n', 'frame 1 has 3 values, the channels need 12'),
    (lambda t: t.replace('MOTION', 'MOTIONS'), "unexpected 'MOTIONS'"),
    (lambda t: t.replace('Frames: 2', 'Frames: two'), 'malformed'),
    (lambda t: t[:t.index('MOTION')], 'no MOTION'),
    (lambda t: t.replace('0.100000', 'abc', 1), 'non-numeric'),
])
def test_malformed_files_raise_clear_errors(tmp_path, edit, message):
    write_chain(tmp_path / 'ok.bvh', {'root': 'ZYX', 'spine': 'ZYX', 'leg': 'ZYX'},
                np.full((2, 3, 3), 0.1), np.full((2, 3), 0.1))
    (tmp_path / 'bad.bvh').write_text(edit((tmp_path / 'ok.bvh').read_text()))
    with pytest.raises(ValueError, match=message):
        read_bvh(tmp_path / 'bad.bvh')


def test_the_shipped_clips_read_and_face_forward():
    from swingar_pyg.world.motion_library import shipped_clips

    names = shipped_clips()
    assert len(names) == 3
    from importlib import resources
    folder = resources.files('swingar_pyg.world') / 'data' / 'motions'
    for name in names:
        with resources.as_file(folder / f'{name}.bvh') as path:
            clip = read_bvh(path)
        assert len(clip.joint_names) == 31 and np.isclose(1 / clip.frame_time, 120, rtol=1e-3)
        _, joints = clip.world()
        travel = joints[-1, 0] - joints[0, 0]
        assert travel[2] > abs(travel[0])  # CMU actors walk and run along +Z


def test_ease_from_rest_starts_at_rest_and_joins_the_motion():
    names = CMU_JOINTS
    kick = procedural_motion('kick', names, seconds=1.0)
    shifted = kick.rotations[10:]
    motion = ease_from_rest(type(kick)('k', shifted, kick.translation[10:] + 1.0, 30.0, names))
    joints = len(names)
    assert torch.allclose(motion.rotations[0], torch.eye(3).expand(joints, 3, 3), atol=1e-6)
    assert torch.allclose(motion.translation[0], torch.zeros(3))
    assert torch.equal(motion.rotations[15:], shifted)
    step = (motion.rotations[1:16] - motion.rotations[:15]).abs().amax()
    assert step < 0.2  # smooth, no jolt into the first frame


def test_mirror_twice_is_the_identity():
    walk = procedural_motion('walk', CMU_JOINTS, seconds=1.0)
    twice = mirror_motion(mirror_motion(walk))
    assert torch.allclose(twice.rotations, walk.rotations, atol=1e-6)
    assert torch.allclose(twice.translation, walk.translation)


@pytest.fixture(scope='module')
def anny_body():
    require('anny')
    from swingar_pyg.world.body import AnnyBody

    return AnnyBody()


@pytest.mark.parametrize('clip', ['cmu_02_01_walk_delfem2', 'cmu_02_03_run_cgspeed_style'])
def test_retargeted_limbs_point_where_the_capture_points_them(anny_body, clip):
    from importlib import resources

    from swingar_pyg.world.retarget import BVH_TO_Z_UP, retarget

    folder = resources.files('swingar_pyg.world') / 'data' / 'motions'
    with resources.as_file(folder / f'{clip}.bvh') as path:
        capture = read_bvh(path)
    shape = anny_body.default_shape()
    motion = retarget(capture, anny_body, shape)
    posed = anny_body.pose(shape, motion.rotations, motion.translation)
    _, joints = capture.resample(30.0).world()
    joints = joints @ BVH_TO_Z_UP.T
    body = posed.joint_positions.numpy()
    names, clip_names = list(anny_body.joint_names), list(capture.joint_names)
    for head, tail in [('LeftUpLeg', 'LeftLeg'), ('LeftLeg', 'LeftFoot'), ('RightLeg', 'RightFoot'),
                       ('LeftArm', 'LeftForeArm'), ('RightForeArm', 'RightHand'),
                       ('LowerBack', 'Spine'), ('Neck', 'Head')]:
        ours = body[:, names.index(tail)] - body[:, names.index(head)]
        theirs = joints[:, clip_names.index(tail)] - joints[:, clip_names.index(head)]
        norms = np.linalg.norm(ours, axis=1) * np.linalg.norm(theirs, axis=1)
        cosine = (ours * theirs).sum(1) / norms
        assert cosine.min() > 0.999, (head, tail)
    # Forward along -Y at a human pace, the pelvis at the body's own height.
    seconds = motion.num_frames / motion.fps
    speed = -float(motion.translation[-1, 1]) / seconds
    assert 0.5 < speed < 5.0
    assert abs(float(motion.translation[:, 2].mean())) < 0.15


@pytest.mark.parametrize('clip', ['cmu_02_01_walk_delfem2', 'cmu_02_03_run_cgspeed_style'])
def test_retargeted_clips_keep_the_bodys_build(anny_body, clip):
    # The girdle bones (hip bones, clavicles) keep their rest directions: turned onto the
    # clip's, anny's hip joints would come 6 cm closer and tear the skin between them.
    from swingar_pyg.world.body import rest_pose
    from swingar_pyg.world.motion_library import make_motion

    shape = anny_body.default_shape()
    motion = make_motion(clip, anny_body, shape, seconds=2.0)
    joints = anny_body.pose(shape, motion.rotations, motion.translation).joint_positions
    rest = rest_pose(anny_body, shape).joint_positions
    names = list(anny_body.joint_names)
    for left, right in [('LeftUpLeg', 'RightUpLeg'), ('LeftArm', 'RightArm')]:
        width = (joints[:, names.index(left)] - joints[:, names.index(right)]).norm(dim=-1)
        rest_width = (rest[:, names.index(left)] - rest[:, names.index(right)]).norm(dim=-1)
        assert torch.allclose(width, rest_width.expand_as(width), rtol=1e-3), (left, right)


def test_make_motion_errors(anny_body):
    from swingar_pyg.world.motion_library import make_motion

    shape = anny_body.default_shape()
    with pytest.raises(ValueError, match="unknown motion 'salsa'"):
        make_motion('salsa', anny_body, shape)
    with pytest.raises(ValueError, match='no BVH file'):
        make_motion('/nowhere/clip.bvh', anny_body, shape)
    with pytest.raises(ValueError, match='amplitude applies to procedural'):
        make_motion('cmu_02_01_walk_delfem2', anny_body, shape, amplitude=0.5)
    walk = make_motion('cmu_02_01_walk_delfem2', anny_body, shape, seconds=1.0)
    assert walk.num_frames == 30
    assert torch.allclose(walk.rotations[0], torch.eye(3).expand(31, 3, 3), atol=1e-5)
