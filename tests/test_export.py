"""Export to DCC tools (`swingar predict --format obj|pc2|usd`): every file read back
independently of the writer and compared frame by frame; bad input refused before
anything is written; a failed write leaves nothing behind."""

import builtins
import json
import struct
import sys

import numpy as np
import pytest
import torch

from swingar_pyg.geometry import sheet
from swingar_pyg.inference import export
from swingar_pyg.inference.export import (
    check_writers,
    parse_formats,
    write_obj,
    write_pc2,
    write_usd,
)
from tests.extras import require

FPS = 24.0


@pytest.fixture
def animation():
    """A 4 x 5 sheet (12 triangles) waving over 7 frames, and a second small mesh
    standing in for the body."""
    mesh = sheet(4, 5, width=0.4, height=0.5)
    rest = mesh.vertices.astype(np.float64)
    t = np.arange(7)[:, None]
    frames = np.repeat(rest[None], 7, axis=0)
    frames[..., 2] = 0.05 * np.sin(0.7 * t + 3.0 * rest[None, :, 0])
    frames[..., 0] += 0.01 * t
    body = sheet(3, 3, width=0.3, height=0.3)
    body_frames = np.repeat(body.vertices[None], 7, axis=0) + np.array([0.0, 0.0, 1.0])
    body_frames[..., 1] -= 0.02 * t
    return frames, mesh.faces, body_frames, body.faces


def _read_pc2(path):
    """The documented PC2 layout, parsed here without the writer's code."""
    data = path.read_bytes()
    signature = data[:12]
    version, points = struct.unpack('<ii', data[12:20])
    start, rate = struct.unpack('<ff', data[20:28])
    (samples,) = struct.unpack('<i', data[28:32])
    assert len(data) == 32 + samples * points * 3 * 4
    frames = np.frombuffer(data, dtype='<f4', offset=32).reshape(samples, points, 3)
    return signature, version, start, rate, frames


def _read_obj(path):
    vertices, faces = [], []
    for line in path.read_text().splitlines():
        kind, *values = line.split()
        if kind == 'v':
            vertices.append([float(v) for v in values])
        elif kind == 'f':
            faces.append([int(v) - 1 for v in values])
    return np.array(vertices), np.array(faces)


def test_pc2_holds_every_frame_in_the_documented_layout(animation, tmp_path):
    frames, faces, _, _ = animation
    path = tmp_path / 'garment.pc2'
    write_pc2(path, frames)
    signature, version, start, rate, read = _read_pc2(path)
    assert signature == b'POINTCACHE2\0' and version == 1
    assert (start, rate) == (0.0, 1.0)
    assert read.shape == frames.shape
    for t in range(len(frames)):
        np.testing.assert_array_equal(read[t], frames[t].astype(np.float32))
    write_pc2(path, torch.as_tensor(frames[:3]), start_frame=1.0, sample_rate=0.5)
    _, _, start, rate, read = _read_pc2(path)
    assert (start, rate) == (1.0, 0.5) and len(read) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ['garment.pc2']


def test_obj_round_trips_a_frame(animation, tmp_path):
    frames, faces, _, _ = animation
    write_obj(tmp_path / 'frame.obj', frames[3], faces)
    vertices, read_faces = _read_obj(tmp_path / 'frame.obj')
    np.testing.assert_allclose(vertices, frames[3], atol=5e-7)
    np.testing.assert_array_equal(read_faces, faces)


def test_usd_stage_holds_both_meshes_at_every_time_code(animation, tmp_path):
    require('pxr')
    from pxr import Usd, UsdGeom

    frames, faces, body_frames, body_faces = animation
    for name in ('scene.usd', 'scene.usda'):
        path = tmp_path / name
        write_usd(path, frames, faces, FPS, body_frames, body_faces, garment_name='my skirt')
        stage = Usd.Stage.Open(str(path))
        assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
        assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
        assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
        assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, len(frames) - 1)
        assert stage.GetDefaultPrim().GetPath() == '/Scene'
        for prim_path, expected, triangles in (('/Scene/Garment', frames, faces),
                                               ('/Scene/Body', body_frames, body_faces)):
            mesh = UsdGeom.Mesh(stage.GetPrimAtPath(prim_path))
            assert mesh, prim_path
            assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(triangles)
            np.testing.assert_array_equal(np.array(mesh.GetFaceVertexIndicesAttr().Get()),
                                          triangles.reshape(-1))
            assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
            points = mesh.GetPointsAttr()
            assert points.GetTimeSamples() == [float(t) for t in range(len(expected))]
            for t in range(len(expected)):
                np.testing.assert_array_equal(np.array(points.Get(Usd.TimeCode(t))),
                                              expected[t].astype(np.float32))
                extent = np.array(mesh.GetExtentAttr().Get(Usd.TimeCode(t)))
                np.testing.assert_allclose(extent, [expected[t].min(0), expected[t].max(0)],
                                           atol=1e-6)
        garment = stage.GetPrimAtPath('/Scene/Garment')
        assert garment.GetCustomDataByKey('swingar:garment') == 'my skirt'
    assert (tmp_path / 'scene.usda').read_text().startswith('#usda')
    assert (tmp_path / 'scene.usd').read_bytes().startswith(b'PXR-USDC')
    # the body is optional; the time codes can start elsewhere
    write_usd(tmp_path / 'alone.usd', frames, faces, 30.0, start_time_code=10)
    stage = Usd.Stage.Open(str(tmp_path / 'alone.usd'))
    assert not stage.GetPrimAtPath('/Scene/Body')
    points = UsdGeom.Mesh(stage.GetPrimAtPath('/Scene/Garment')).GetPointsAttr()
    assert points.GetTimeSamples()[0] == 10.0 and stage.GetEndTimeCode() == 16.0
    np.testing.assert_array_equal(np.array(points.Get(16)), frames[6].astype(np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ['alone.usd', 'scene.usd',
                                                          'scene.usda']


def test_formats_parse_from_commas_or_repeats():
    assert parse_formats('usd,pc2') == ('usd', 'pc2')
    assert parse_formats(['obj', ' USD, obj ']) == ('obj', 'usd')
    with pytest.raises(ValueError, match="unknown export format 'fbx'.*obj, pc2, usd"):
        parse_formats('usd,fbx')
    with pytest.raises(ValueError, match='no export format given'):
        parse_formats(' , ')


def test_bad_input_is_refused_before_anything_is_written(animation, tmp_path):
    frames, faces, body_frames, body_faces = animation
    nan = frames.copy()
    nan[4, 2, 1] = np.nan
    huge = frames.copy()
    huge[1, 0, 0] = 1e39  # finite in float64, inf in float32
    cases = [
        (lambda p: write_pc2(p / 'a.pc2', nan), 'finite.*1 of 7 frames.*frame 4'),
        (lambda p: write_pc2(p / 'a.pc2', huge), 'finite \\(in float32\\)'),
        (lambda p: write_pc2(p / 'a.pc2', frames[..., :2]), 'shape \\(T, N, 3\\)'),
        (lambda p: write_pc2(p / 'a.pc2', frames[0]), 'shape \\(T, N, 3\\)'),
        (lambda p: write_pc2(p / 'a.pc2', frames[:0]), 'T, N >= 1'),
        (lambda p: write_pc2(p / 'a.pc2', frames, sample_rate=0), 'sample_rate'),
        (lambda p: write_obj(p / 'a.obj', frames, faces), 'shape \\(N, 3\\)'),
        (lambda p: write_obj(p / 'a.obj', frames[0], faces + 100), 'index vertices in'),
        (lambda p: write_obj(p / 'a.obj', frames[0], faces[:, :2]), 'shape \\(F, 3\\)'),
        (lambda p: write_obj(p / 'a.obj', frames[0], faces.astype(float)), 'integer'),
        (lambda p: write_usd(p / 'a.usd', nan, faces, FPS), 'finite'),
        (lambda p: write_usd(p / 'a.usd', frames, faces, 0.0), 'fps'),
        (lambda p: write_usd(p / 'a.usd', frames, faces, FPS, body_frames), 'both'),
        (lambda p: write_usd(p / 'a.usd', frames, faces, FPS, body_frames[:5], body_faces),
         "garment's 7 frames"),
        (lambda p: write_usd(p / 'a.fbx', frames, faces, FPS), 'a USD file ends in'),
    ]
    for write, message in cases:
        with pytest.raises(ValueError, match=message):
            write(tmp_path)
        assert list(tmp_path.iterdir()) == [], message


def test_a_failed_write_leaves_the_old_file_and_no_temporary(animation, tmp_path, monkeypatch):
    frames, faces, body_frames, body_faces = animation
    path = tmp_path / 'garment.pc2'
    write_pc2(path, frames)
    before = path.read_bytes()

    class Killed(RuntimeError):
        pass

    real_open = builtins.open

    class HalfWritten:  # a file that dies after the header, mid-write
        def __init__(self, *args, **kwargs):
            self.file = real_open(*args, **kwargs)
            self.writes = 0

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.file.close()

        def write(self, data):
            self.writes += 1
            if self.writes > 1:
                self.file.write(data[:10])
                raise Killed('disk full')
            return self.file.write(data)

    monkeypatch.setattr(export, 'open', HalfWritten, raising=False)
    with pytest.raises(Killed):
        write_pc2(path, frames[:2])
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ['garment.pc2']

    require('pxr')
    from pxr import Sdf

    def export_half(layer, name, *args, **kwargs):  # USD writes part of the file, then fails
        with real_open(name, 'w') as handle:
            handle.write('#usda 1.0\n(')
        return False

    monkeypatch.setattr(Sdf.Layer, 'Export', export_half)
    with pytest.raises(OSError, match='USD could not write'):
        write_usd(tmp_path / 'scene.usd', frames, faces, FPS, body_frames, body_faces)
    assert [p.name for p in tmp_path.iterdir()] == ['garment.pc2']


def test_usd_without_usd_core_names_the_extra(animation, tmp_path, monkeypatch):
    frames, faces, _, _ = animation
    monkeypatch.setitem(sys.modules, 'pxr', None)  # `from pxr import ...` now fails
    with pytest.raises(ImportError, match=r"pip install 'swingar-pyg\[usd\]'"):
        write_usd(tmp_path / 'scene.usd', frames, faces, FPS)
    with pytest.raises(ImportError, match='usd-core'):
        check_writers(('obj', 'usd'))
    check_writers(('obj', 'pc2'))
    assert list(tmp_path.iterdir()) == []


# --- end to end: `swingar predict --format usd,pc2` ------------------------------------------


@pytest.fixture(scope='module')
def untrained_checkpoint(tmp_path_factory):
    """An untrained tiny estimator saved as `swingar fit` saves one (its config as
    class_path + init_args, for LightningCLI to rebuild it): no training, no data."""
    require('lightning')
    import lightning as L

    from swingar_pyg.models import SwinGarEstimator
    from swingar_pyg.training import SwinGarModule
    from tests.windows import SMALL_ESTIMATOR

    module = SwinGarModule(SwinGarEstimator(**SMALL_ESTIMATOR))
    path = tmp_path_factory.mktemp('untrained') / 'untrained.ckpt'
    torch.save({'state_dict': module.state_dict(),
                'pytorch-lightning_version': L.__version__,
                'hyper_parameters': {
                    '_class_path': 'swingar_pyg.training.SwinGarModule',
                    '_instantiator': 'lightning.pytorch.cli.instantiate_module',
                    'estimator': {'class_path': 'swingar_pyg.models.SwinGarEstimator',
                                  'init_args': SMALL_ESTIMATOR},
                    **module.hparams},
                'datamodule_hyper_parameters': {'sigma': 0.1, 'seed': 0}}, path)
    return path


def test_predict_exports_usd_and_pc2(untrained_checkpoint, tmp_path, capsys):
    require('anny')
    require('pxr')
    from pxr import Usd, UsdGeom

    from swingar_pyg.cli import main
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.motion_library import make_motion
    from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt

    body = AnnyBody()
    shape = body.default_shape()
    skirt = fit_procedural_skirt(SkirtSpec(vertices=150), body, shape)
    write_obj(tmp_path / 'skirt.obj', skirt.mesh.vertices, skirt.mesh.faces)
    out = tmp_path / 'out'
    assert main(['predict', '--ckpt', str(untrained_checkpoint), '--garment',
                 str(tmp_path / 'skirt.obj'), '--motion', 'sway', '--seconds', '0.2',
                 '--format', 'usd,pc2', '--no-preview', '--no-collisions',
                 '--out', str(out)]) == 0
    assert '(pc2, usd)' in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ['garment.npz', 'garment.pc2',
                                                     'garment.usd', 'garment_rest.obj',
                                                     'summary.json']
    saved = np.load(out / 'garment.npz')
    vertices = saved['vertices']
    assert vertices.shape == (6, skirt.mesh.num_vertices, 3)
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['fps'] == 30.0 and set(summary['exported']) == {'usd', 'pc2'}

    _, _, _, _, cached = _read_pc2(out / 'garment.pc2')
    np.testing.assert_array_equal(cached, vertices.astype(np.float32))
    rest, rest_faces = _read_obj(out / 'garment_rest.obj')
    np.testing.assert_allclose(rest, skirt.mesh.vertices, atol=5e-7)
    np.testing.assert_array_equal(rest_faces, saved['faces'])

    clip = make_motion('sway', body, shape, seconds=0.2)
    posed = body.pose(shape, clip.rotations, clip.translation).vertices.numpy()
    stage = Usd.Stage.Open(str(out / 'garment.usd'))
    assert stage.GetTimeCodesPerSecond() == 30.0 and stage.GetEndTimeCode() == 5.0
    garment = UsdGeom.Mesh(stage.GetPrimAtPath('/Scene/Garment')).GetPointsAttr()
    body_points = UsdGeom.Mesh(stage.GetPrimAtPath('/Scene/Body')).GetPointsAttr()
    for t in range(6):
        np.testing.assert_array_equal(np.array(garment.Get(t)), vertices[t])
        np.testing.assert_allclose(np.array(body_points.Get(t)), posed[t], atol=1e-6)


def test_predict_refuses_an_unknown_format_before_loading_anything(tmp_path, capsys):
    require('lightning')
    from swingar_pyg.cli import main

    with pytest.raises(SystemExit):
        main(['predict', '--ckpt', str(tmp_path / 'none.ckpt'), '--garment', 'tshirt_loose',
              '--format', 'obj', '--format', 'fbx', '--out', str(tmp_path / 'out')])
    assert "unknown export format 'fbx'" in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


def test_predict_switches_the_clearance_gate_off_on_request(tmp_path, monkeypatch):
    require('lightning')
    import swingar_pyg.cli as cli

    used = []

    def recorded(estimator, *args, **kwargs):
        used.append((estimator.clearance_scale, estimator.anchor_scale))
        raise SystemExit(0)

    monkeypatch.setattr(cli, 'predict_to_folder', recorded)
    for options in ([], ['--no-clearance-gate']):
        with pytest.raises(SystemExit):
            cli.main(['predict', '--garment', 'tshirt_loose', '--out', str(tmp_path), *options])
    assert used[0] != (None, None) and used[1] == (None, None)  # the shipped weights' gate
