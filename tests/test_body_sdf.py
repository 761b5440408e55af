import math

import numpy as np
import pytest
import torch

from swingar_pyg.collision import resolve_collisions
from swingar_pyg.geometry.bones import bone_segments, distance_to_bones
from swingar_pyg.geometry.skinning import axis_angle_to_matrix
from swingar_pyg.models import BodySDF
from tests.extras import require

# A toy rig: a chain of three joints along +x (an "arm"), and its body: capsules of
# radius R around the two bones, whose exact SDF (positive inside) is analytic.
PARENTS = (-1, 0, 1)
BONE = 0.3
R = 0.06


def chain_pose(bend: torch.Tensor, turn: torch.Tensor | None = None):
    """Joint transforms (B, 3, 4, 4) and heads (B, 3, 3) of the chain bent at its middle
    joint by ``bend`` (radians, about z), the whole chain turned by ``turn`` (axis-angle)."""
    frames = len(bend)
    rest_heads = torch.tensor([[0.0, 0, 0], [BONE, 0, 0], [2 * BONE, 0, 0]], dtype=bend.dtype)
    root = axis_angle_to_matrix(turn) if turn is not None else \
        torch.eye(3, dtype=bend.dtype).expand(frames, 3, 3)
    elbow = axis_angle_to_matrix(torch.stack([torch.zeros_like(bend), torch.zeros_like(bend),
                                              bend], -1))
    rotations = [root, root @ elbow, root @ elbow]
    heads = torch.zeros(frames, 3, 3, dtype=bend.dtype)
    heads[:, 1] = (root @ rest_heads[1])
    heads[:, 2] = heads[:, 1] + (root @ elbow @ (rest_heads[2] - rest_heads[1]))
    transforms = torch.eye(4, dtype=bend.dtype).repeat(frames, 3, 1, 1)
    for j in range(3):
        transforms[:, j, :3, :3] = rotations[j]
        transforms[:, j, :3, 3] = heads[:, j] - (rotations[j] @ rest_heads[j])
    return transforms, heads


def capsule_sdf(points: torch.Tensor, heads: torch.Tensor):
    """Exact SDF (positive inside) of the two capsules of each frame, and outward normal.
    points (B, P, 3), heads (B, 3, 3)."""
    values, normals = [], []
    for a, b in ((0, 1), (1, 2)):
        start, end = heads[:, a, None], heads[:, b, None]
        along = end - start
        t = (((points - start) * along).sum(-1) / along.square().sum(-1)).clamp(0, 1)
        offset = points - start - t[..., None] * along
        values.append(R - offset.norm(dim=-1))
        normals.append(torch.nn.functional.normalize(offset, dim=-1))
    values, normals = torch.stack(values), torch.stack(normals)
    best = values.argmax(0)
    return values.max(0).values, torch.gather(
        normals, 0, best[None, ..., None].expand(1, *best.shape, 3))[0]


def near_chain_points(heads: torch.Tensor, count: int, generator: torch.Generator):
    """Points around the chain's bones, most within a few cm of the capsule surface."""
    frames = len(heads)
    bone = torch.randint(0, 2, (frames, count), generator=generator)
    t = torch.rand(frames, count, generator=generator)
    start = torch.gather(heads, 1, bone[..., None].expand(-1, -1, 3))
    end = torch.gather(heads, 1, (bone + 1)[..., None].expand(-1, -1, 3))
    direction = torch.nn.functional.normalize(torch.randn(frames, count, 3, generator=generator,
                                                          dtype=heads.dtype), dim=-1)
    radius = R + 0.02 * torch.randn(frames, count, generator=generator, dtype=heads.dtype)
    return start + t[..., None] * (end - start) + radius[..., None] * direction


def test_bone_distances_match_a_brute_force_sweep():
    owner, tip = bone_segments((-1, 0, 1, 1, 0))
    # one segment per parent-child pair, owned by the parent, and one point per leaf
    assert sorted(zip(owner.tolist(), tip.tolist())) == [(0, 1), (0, 4), (1, 2), (1, 3), (2, 2),
                                                          (3, 3), (4, 4)]
    heads = torch.randn(5, 3, dtype=torch.float64)
    points = torch.randn(40, 3, dtype=torch.float64)
    distance = distance_to_bones(points, heads.expand(40, -1, -1), owner, tip)
    t = torch.linspace(0, 1, 20001, dtype=torch.float64)
    for j in range(5):
        samples = torch.cat([heads[a] + t[:, None] * (heads[b] - heads[a])
                             for a, b in zip(owner.tolist(), tip.tolist()) if a == j])
        brute = torch.cdist(points, samples).min(dim=1).values
        assert torch.allclose(distance[:, j], brute, atol=1e-4)
    with pytest.raises(ValueError, match='parents must come before'):
        bone_segments((-1, 2, 0))


def test_network_gradient_matches_finite_differences_and_gradcheck():
    torch.manual_seed(0)
    sdf = BodySDF(PARENTS, shape_size=2, channels=16, layers=2, frequencies=2).double()
    transforms, heads = chain_pose(torch.tensor([0.7], dtype=torch.float64))
    shape = torch.rand(1, 2, dtype=torch.float64)
    points = near_chain_points(heads, 30, torch.Generator().manual_seed(1))[0]

    def field(x):
        return sdf(x, transforms, heads, shape)

    assert torch.autograd.gradcheck(field, (points.clone().requires_grad_(True),))
    value, gradient = sdf.signed_distance(points, transforms, heads, shape)
    step = 1e-6
    for axis in range(3):
        shift = torch.zeros(3, dtype=torch.float64)
        shift[axis] = step
        difference = (field(points + shift) - field(points - shift)) / (2 * step)
        assert torch.allclose(gradient[:, axis], difference, atol=1e-6)
    assert torch.allclose(value, field(points))


def test_network_is_invariant_to_moving_body_and_points_together():
    sdf = BodySDF(PARENTS, shape_size=2, channels=16, layers=2).double()
    bend = torch.tensor([0.3, 1.2], dtype=torch.float64)
    turn = torch.tensor([[0.0, 0.0, 0.0], [0.4, -1.1, 2.0]], dtype=torch.float64)
    transforms, heads = chain_pose(bend, turn)
    shape = torch.rand(1, 2, dtype=torch.float64).expand(2, -1)
    local = near_chain_points(chain_pose(bend)[1], 50, torch.Generator().manual_seed(2))
    # the same points, carried by the turn of each frame
    rotation = axis_angle_to_matrix(turn)
    moved = torch.einsum('bij,bpj->bpi', rotation, local)
    index = torch.arange(2).repeat_interleave(50)
    straight, _ = chain_pose(bend)
    a, ga = sdf.signed_distance(local.reshape(-1, 3), straight, chain_pose(bend)[1], shape, index)
    b, gb = sdf.signed_distance(moved.reshape(-1, 3), transforms, heads, shape, index)
    assert torch.allclose(a, b, atol=1e-10)
    turned = torch.einsum('bij,bpj->bpi', rotation, ga.reshape(2, 50, 3)).reshape(-1, 3)
    assert torch.allclose(turned, gb, atol=1e-8)


def test_a_batch_of_bodies_equals_each_body_alone():
    sdf = BodySDF(PARENTS, shape_size=2, channels=16, layers=2)
    transforms, heads = chain_pose(torch.tensor([0.2, 0.9, -0.5]))
    shape = torch.rand(3, 2)
    points = near_chain_points(heads, 20, torch.Generator().manual_seed(3))
    together = sdf(points.reshape(-1, 3), transforms, heads, shape,
                   torch.arange(3).repeat_interleave(20))
    alone = torch.cat([sdf(points[k], transforms[k:k + 1], heads[k:k + 1], shape[k:k + 1])
                       for k in range(3)])
    assert torch.allclose(together, alone, atol=1e-6)


def test_network_on_extreme_and_bad_input():
    sdf = BodySDF(PARENTS, shape_size=2, channels=16, layers=2)
    transforms, heads = chain_pose(torch.tensor([0.5]))
    shape = torch.rand(1, 2)
    for scale in (1e-3, 1.0, 1e3):
        points = scale * torch.randn(64, 3)
        value, gradient = sdf.signed_distance(points, transforms, heads, shape)
        assert torch.isfinite(value).all() and torch.isfinite(gradient).all()
    half = sdf.signed_distance(torch.randn(8, 3).half(), transforms.half(), heads.half(),
                               shape.half())
    assert half[0].dtype == torch.float16 and torch.isfinite(half[0]).all()
    with torch.inference_mode():
        value, gradient = sdf.signed_distance(torch.randn(8, 3), transforms, heads, shape)
    assert torch.isfinite(gradient).all()
    with pytest.raises(ValueError, match='points must have shape'):
        sdf(torch.randn(8, 2), transforms, heads, shape)
    with pytest.raises(ValueError, match='joint_transforms must have shape'):
        sdf(torch.randn(8, 3), transforms[:, :2], heads, shape)
    with pytest.raises(ValueError, match='body_index'):
        sdf(torch.randn(8, 3), transforms.expand(2, -1, -1, -1), heads.expand(2, -1, -1),
            shape.expand(2, -1))
    with pytest.raises(ValueError, match='points must be finite'):
        sdf(torch.full((2, 3), float('nan')), transforms, heads, shape)


@pytest.fixture(scope='module')
def trained_chain():
    """A BodySDF trained with BodySDFModule's loss on the capsule chain at random bends."""
    require('lightning')
    from swingar_pyg.training import BodySDFModule

    torch.manual_seed(0)
    module = BodySDFModule(BodySDF(PARENTS, shape_size=1, channels=48, layers=3, frequencies=2,
                                   temperature=0.02), length_unit=0.01, lr=3e-3)
    optimizer = torch.optim.Adam(module.parameters(), lr=3e-3)
    generator = torch.Generator().manual_seed(4)
    # 900 steps: at 600 the unseen-pose error sat at the 3 mm bound (3.1 mm on one machine,
    # under 3 on another: their float rounding differs); at 900 it is 1.8 mm.
    for _ in range(900):
        bend = (torch.rand(8, generator=generator) - 0.5) * 2.4
        transforms, heads = chain_pose(bend)
        points = near_chain_points(heads, 128, generator)
        sdf, normal = capsule_sdf(points, heads)
        batch = {'points': points, 'sdf': sdf, 'normal': normal, 'joint_transforms': transforms,
                 'joint_positions': heads, 'body_shape': torch.zeros(8, 1)}
        optimizer.zero_grad()
        module.loss(batch)[0].backward()
        optimizer.step()
    return module.body_sdf


def test_trained_network_generalises_to_unseen_poses(trained_chain):
    # bends beyond the training range and turns of the whole chain never seen
    bend = torch.tensor([1.5, -1.4, 0.0])
    transforms, heads = chain_pose(bend, torch.tensor([[0.0, 0, 2.5], [1.0, 0.3, 0], [0, 2, 0]]))
    points = near_chain_points(heads, 400, torch.Generator().manual_seed(5))
    exact, normal = capsule_sdf(points, heads)
    index = torch.arange(3).repeat_interleave(400)
    value, gradient = trained_chain.signed_distance(points.reshape(-1, 3), transforms, heads,
                                                    torch.zeros(3, 1), index)
    near = exact.reshape(-1).abs() < 0.02
    error = (value - exact.reshape(-1)).abs()[near]
    assert error.mean() < 3e-3, error.mean()
    cosine = -(torch.nn.functional.normalize(gradient, dim=-1) * normal.reshape(-1, 3)).sum(-1)
    assert cosine[near].mean() > 0.95


def test_correction_with_the_network_leaves_no_vertex_inside(trained_chain):
    # a sheet of cloth draped through the bent chain: rows of vertices across the capsules
    from swingar_pyg.geometry import mesh_edge_index, sheet

    transforms, heads = chain_pose(torch.tensor([0.8]))
    mesh = sheet(12, 40, width=0.8, height=0.16)
    vertices = torch.as_tensor(mesh.vertices, dtype=torch.float32) + torch.tensor([-0.05, -0.08,
                                                                                   0.03])
    exact = capsule_sdf(vertices[None], heads)[0][0]
    assert (exact > 0).sum() > 50
    field = trained_chain.bind(transforms[0], heads[0], torch.zeros(1))
    result = resolve_collisions(vertices, mesh_edge_index(mesh), field, iterations=4,
                                offset=0.004)
    after = capsule_sdf(result.vertices[None], heads)[0][0]
    assert (after > 0).float().mean() < 0.005, int((after > 0).sum())
    assert torch.equal(result.vertices[~result.moved], vertices[~result.moved])


def test_anny_rig_is_the_default_and_broad_phase_holds_extreme_poses():
    require('anny')
    from swingar_pyg.collision.broad_phase import BoneCapsules
    from swingar_pyg.models.body_sdf import ANNY_CMU_MB_PARENTS
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.motion import EXTREME_MOTIONS
    from swingar_pyg.world.motion_library import make_motion

    body = AnnyBody()
    assert body.parents == ANNY_CMU_MB_PARENTS
    shape = torch.tensor([0.2, 0.7, 0.6, 0.9, 0.3, 0.4])
    capsules = BoneCapsules.from_body(body, shape)
    for kind in EXTREME_MOTIONS:
        motion = make_motion(kind, body, shape, seconds=2.0, amplitude=1.5)
        posed = body.pose(shape, motion.rotations[::4], motion.translation[::4])
        for vertices, joints in zip(posed.vertices, posed.joint_positions):
            assert capsules.clearance(vertices, joints).max() < 0.02
    far = posed.vertices[-1] + torch.tensor([0.0, 0.0, 3.0])
    assert not capsules.near(far, posed.joint_positions[-1]).any()


def test_broad_phase_skips_the_network_for_a_garment_far_from_the_body(trained_chain):
    from swingar_pyg.collision.broad_phase import BoneCapsules
    from swingar_pyg.geometry import mesh_edge_index, sheet

    transforms, heads = chain_pose(torch.tensor([0.0]))
    rest = torch.tensor([[x, y, z] for x in np.linspace(0, BONE, 40)
                         for y, z in ((R, 0.0), (-R, 0.0), (0.0, R), (0.0, -R))])
    # all of this rest "body" rides on joint 0, R from its bone
    capsules = BoneCapsules.fit(rest, torch.zeros(len(rest), 1, dtype=torch.long),
                                torch.ones(len(rest), 1), heads[0], PARENTS)
    mesh = sheet(4, 4, width=0.2, height=0.2)
    far = torch.as_tensor(mesh.vertices, dtype=torch.float32) + torch.tensor([0.0, 0.0, 1.0])
    calls = []

    def counting(points):
        calls.append(len(points))
        return trained_chain.bind(transforms[0], heads[0], torch.zeros(1))(points)

    near = capsules.near(far, heads[0])
    result = resolve_collisions(far, mesh_edge_index(mesh), counting, near=near)
    assert not near.any() and sum(calls) == 0 and not result.moved.any()
    assert math.isclose(float(capsules.radius[0]), R, rel_tol=1e-5)


@pytest.mark.filterwarnings('ignore:The .*dataloader.* does not have many workers')
def test_cli_trains_the_body_sdf_from_its_config(tiny_windows, tiny_body_sdf, tmp_path):
    import csv
    import os
    import shutil

    import h5py
    import yaml

    from datamodules import BodySDFDataModule
    from datamodules.body_sdf_data import read_split
    from swingar_pyg.geometry import body_signed_distance
    from swingar_pyg.training import BodySDFModule
    from swingar_pyg.world.body import AnnyBody

    root = tiny_body_sdf.parents[1]
    config = root / 'tiny_sdf.yaml'
    metrics = (root / 'logs' / 'version_0' / 'metrics.csv').read_text().splitlines()
    rows = list(csv.DictReader(metrics))
    errors = [float(r['val/near_mean_mm']) for r in rows if r.get('val/near_mean_mm')]
    assert len(errors) == 2 and all(np.isfinite(errors))
    module = BodySDFModule.load_from_checkpoint(tiny_body_sdf)
    assert module.body_sdf.frequencies == 1

    # 2 shapes x 1 motion x 1 frame, and 2 garment frames of each training sequence
    train = read_split(root / 'data' / 'train.h5')
    sequences = len(tiny_windows.datasets['train'].sequences)
    assert train['points'].shape == (2 + 2 * sequences, 128, 3)
    assert sum('@train' in m for m in train['motion']) == 2 * sequences
    # the targets are the exact signed distance of the posed body, skinned from its transforms
    from swingar_pyg.geometry.skinning import linear_blend_skinning

    body = AnnyBody()
    indices, weights = body.skinning()
    for frame in (0, len(train['points']) - 1):
        shape = torch.as_tensor(train['body_shape'][frame])
        posed = linear_blend_skinning(body.rest_vertices(shape), indices, weights,
                                      torch.as_tensor(train['joint_transforms'][frame])[None])[0]
        sdf, _ = body_signed_distance(train['points'][frame], posed.double().numpy(),
                                      body.faces.numpy())
        assert np.allclose(sdf, train['sdf'][frame], atol=1e-4)
    with h5py.File(root / 'data' / 'val.h5', 'r') as file:
        assert file.attrs['split'] == 'val' and file['points'].shape[0] == 1
    # a split made with the same settings is reused, another setting remakes it
    samples = yaml.safe_load(config.read_text())['data']['init_args']['samples']
    shutil.copytree(root / 'data', tmp_path / 'data')
    train_file = tmp_path / 'data' / 'train.h5'
    stamp = os.stat(train_file).st_mtime_ns
    BodySDFDataModule(root=str(tmp_path / 'data'), samples=samples, workers=1).prepare_data()
    assert os.stat(train_file).st_mtime_ns == stamp
    BodySDFDataModule(root=str(tmp_path / 'data'), samples={**samples, 'points_per_frame': 64},
                      workers=1).prepare_data()
    assert read_split(train_file)['points'].shape[1] == 64
    with pytest.raises(ValueError, match='unknown SDF sample settings'):
        BodySDFDataModule(samples={'points': 3})
