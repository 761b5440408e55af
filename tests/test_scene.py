import dataclasses

import pytest
import torch

from swingar_pyg.inference.scene import GarmentFeatureCache, Scene, compile_scene
from swingar_pyg.models import SwinGarEstimator
from tests.extras import require
from tests.windows import SMALL_ESTIMATOR

require('anny')


@pytest.fixture(scope='module')
def world():
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt

    body = AnnyBody()
    shape = body.default_shape()
    skirts = [fit_procedural_skirt(SkirtSpec(length=0.45, vertices=120), body, shape),
              fit_procedural_skirt(SkirtSpec(length=0.6, flare=0.5, vertices=160, jitter=0.3),
                                   body, shape)]
    torch.manual_seed(0)
    estimator = SwinGarEstimator(**SMALL_ESTIMATOR)
    for head in (estimator.skinning_head, estimator.blend_head, estimator.correction):
        torch.nn.init.normal_(head.weight, std=0.05)
    return body, shape, skirts, estimator.eval()


def kick(body, shape, seconds=0.5):
    from swingar_pyg.world.motion_library import make_motion

    return make_motion('kick', body, shape, seconds=seconds)


def test_skinning_only_runs_no_network_and_is_rigid_skinning(world, monkeypatch):
    from swingar_pyg.geometry.skinning import linear_blend_skinning

    body, shape, skirts, estimator = world
    monkeypatch.setattr(SwinGarEstimator, 'skin', lambda *a, **k: pytest.fail('network ran'))
    motion = kick(body, shape)
    result = compile_scene(Scene(skirts[:1], body, shape, motion, skinning_only=True,
                                 collisions=False), estimator).run()
    posed = body.pose(shape, motion.rotations, motion.translation)
    expected = linear_blend_skinning(torch.as_tensor(skirts[0].mesh.vertices, dtype=torch.float32),
                                     torch.as_tensor(skirts[0].skin_indices),
                                     torch.as_tensor(skirts[0].skin_weights, dtype=torch.float32),
                                     posed.joint_transforms)
    assert torch.allclose(result.vertices[0], expected, atol=1e-6)
    ran = {s.name for s in result.stages if s.ran}
    assert ran == {'body poses', 'rigid skinning'}
    assert result.stage('detail (M_d)').note == 'left out: skinning only'


def test_a_garment_far_from_the_body_skips_the_collision_pass(world, monkeypatch):
    import swingar_pyg.collision as collision

    body, shape, skirts, estimator = world
    lifted = dataclasses.replace(skirts[0], mesh=dataclasses.replace(
        skirts[0].mesh, vertices=skirts[0].mesh.vertices + [0.0, 0.0, 3.0]))
    motion = kick(body, shape)
    calls = []
    original = collision.resolve_collisions
    monkeypatch.setattr(collision, 'resolve_collisions',
                        lambda *a, **k: calls.append(1) or original(*a, **k))
    with_pass = compile_scene(Scene([lifted], body, shape, motion), estimator).run()
    without = compile_scene(Scene([lifted], body, shape, motion, collisions=False),
                            estimator).run()
    assert not calls and not with_pass.stage('collisions: SDF + correction').ran
    assert with_pass.stage('collisions: broad phase').calls == motion.num_frames
    assert torch.equal(with_pass.vertices[0], without.vertices[0])
    # on the body, the pass runs and leaves no vertex deeper inside than before
    near = compile_scene(Scene(skirts[:1], body, shape, motion), estimator).run()
    assert near.stage('collisions: SDF + correction').ran


def test_a_static_pose_window_reuses_the_last_output(world):
    from swingar_pyg.inference.prediction import animate
    from swingar_pyg.world.motion import Motion

    body, shape, skirts, estimator = world
    moving = kick(body, shape, seconds=0.3)
    hold = 40  # longer than the pose window (8 + 1) and the three cached frames
    motion = Motion('kick-then-hold', torch.cat([moving.rotations,
                                                  moving.rotations[-1:].expand(hold, -1, -1, -1)]),
                    torch.cat([moving.translation, moving.translation[-1:].expand(hold, -1)]),
                    moving.fps, moving.joint_names)
    result = compile_scene(Scene(skirts[:1], body, shape, motion, collisions=False),
                           estimator).run()
    reused = result.stage('static frames reused')
    assert reused.ran and reused.calls == hold - (estimator.history + 2)
    assert result.stage('detail (M_d)').calls == motion.num_frames - reused.calls
    # every frame streamed: the same garment
    from swingar_pyg.inference.prediction import garment_graph

    posed = body.pose(shape, motion.rotations, motion.translation)
    graph = garment_graph(skirts[0], len(body.joint_names), estimator.descriptor_size)
    full, _ = animate(estimator, graph, shape, motion.rotations, motion.translation,
                      posed.joint_transforms, posed.joint_positions, motion.fps, progress=False)
    assert torch.allclose(result.vertices[0], full, atol=1e-6)


def test_cached_features_are_not_recomputed(world, monkeypatch, tmp_path):
    import swingar_pyg.inference.scene as scene

    body, shape, skirts, estimator = world
    computed = []
    original = scene.garment_graph_features
    monkeypatch.setattr(scene, 'garment_graph_features',
                        lambda *a, **k: computed.append(1) or original(*a, **k))
    motion = kick(body, shape, seconds=0.2)
    cache = GarmentFeatureCache(tmp_path)
    first = compile_scene(Scene(skirts, body, shape, motion, collisions=False), estimator,
                          cache).run()
    assert len(computed) == 2 and first.stage('garment features').calls == 2
    again = compile_scene(Scene(skirts, body, shape, motion, collisions=False), estimator,
                          cache).run()
    from_disk = compile_scene(Scene(skirts, body, shape, motion, collisions=False), estimator,
                              GarmentFeatureCache(tmp_path)).run()
    assert len(computed) == 2
    for result in (again, from_disk):
        assert not result.stage('garment features').ran
        assert result.stage('garment features').note == 'left out: all 2 from the cache'
        assert all(torch.equal(a, b) for a, b in zip(result.vertices, first.vertices))


def test_several_garments_run_as_one_batch_equal_to_each_alone(world):
    body, shape, skirts, estimator = world
    motion = kick(body, shape, seconds=0.3)
    together = compile_scene(Scene(skirts, body, shape, motion, collisions=False),
                             estimator).run()
    assert together.stage('batch').ran and together.names == [s.name for s in skirts]
    for skirt, vertices in zip(skirts, together.vertices):
        alone = compile_scene(Scene([skirt], body, shape, motion, collisions=False),
                              estimator).run()
        assert not alone.stage('batch').ran
        assert torch.allclose(vertices, alone.vertices[0], atol=1e-5)
    assert 'detail (M_d)' in together.table()


def test_scene_errors_name_the_problem(world):
    from swingar_pyg.world.motion import procedural_motion

    body, shape, skirts, estimator = world
    with pytest.raises(ValueError, match='at least one garment'):
        Scene([], body, shape, kick(body, shape))
    with pytest.raises(ValueError, match='another rig'):
        Scene(skirts, body, shape, procedural_motion('sway', ('Hips', 'Spine')))
    with pytest.raises(ValueError, match='needs an estimator'):
        compile_scene(Scene(skirts, body, shape, kick(body, shape)))
