"""Weights files and `swingar ship-weights` (export and model card)."""
import json
import shutil
from pathlib import Path

import pytest
import torch
import yaml

from tests.extras import require
from tests.windows import SMALL_ESTIMATOR


def _small_estimator():
    from swingar_pyg.models import SwinGarEstimator

    estimator = SwinGarEstimator(**SMALL_ESTIMATOR)
    with torch.no_grad():  # the zero-initialised heads would hide a lost parameter
        for parameter in estimator.parameters():
            parameter.add_(0.1 * torch.randn_like(parameter))
    return estimator.eval()


def test_a_weights_file_round_trips_the_estimator(tmp_path):
    from swingar_pyg.models import SwinGarEstimator
    from swingar_pyg.models.pretrained import read_weights, write_weights

    estimator = _small_estimator()
    path = write_weights(tmp_path / 'mine.pt', SMALL_ESTIMATOR, estimator.state_dict(),
                         {'sigma': 0.1, 'seed': 3})
    loaded = SwinGarEstimator.from_pretrained(path)
    assert not loaded.training
    assert read_weights(path)['data'] == {'sigma': 0.1, 'seed': 3}
    for name, value in estimator.state_dict().items():
        assert torch.equal(loaded.state_dict()[name], value), name
    assert [p.name for p in tmp_path.iterdir()] == ['mine.pt']  # no temporary left


def test_bad_weights_are_refused_with_the_reason(tmp_path):
    from swingar_pyg.models import SwinGarEstimator
    from swingar_pyg.models.pretrained import WEIGHTS_FORMAT

    with pytest.raises(ValueError, match="no shipped weights named 'nope'"):
        SwinGarEstimator.from_pretrained('nope')
    with pytest.raises(ValueError, match='no weights file'):
        SwinGarEstimator.from_pretrained(str(tmp_path / 'missing.pt'))
    (tmp_path / 'cut.pt').write_bytes(b'PK\x03\x04 half a file')
    with pytest.raises(ValueError, match='not a readable weights file'):
        SwinGarEstimator.from_pretrained(str(tmp_path / 'cut.pt'))
    torch.save({'state_dict': {}}, tmp_path / 'bare.pt')
    with pytest.raises(ValueError, match=r"lacks \['format', 'estimator', 'data'\]"):
        SwinGarEstimator.from_pretrained(str(tmp_path / 'bare.pt'))
    torch.save({'format': WEIGHTS_FORMAT + 1, 'estimator': {}, 'state_dict': {}, 'data': {}},
               tmp_path / 'future.pt')
    with pytest.raises(ValueError, match='weights format 2'):
        SwinGarEstimator.from_pretrained(str(tmp_path / 'future.pt'))


def test_weights_files_run_no_pickled_code(tmp_path, capsys):
    from swingar_pyg.models import SwinGarEstimator

    class Payload:
        def __reduce__(self):
            return (print, ('ran',))

    torch.save({'format': 1, 'estimator': {}, 'state_dict': {}, 'data': Payload()},
               tmp_path / 'evil.pt')
    with pytest.raises(ValueError, match='not a readable weights file'):
        SwinGarEstimator.from_pretrained(str(tmp_path / 'evil.pt'))
    assert 'ran' not in capsys.readouterr().out


TINY_CHECK_SLICE = {
    'name': 'tiny-check', 'seconds': 0.3, 'fps': 30,
    'solver': {'substeps': 10, 'iterations': 2, 'settle_frames': 10},
    'body_shapes': [[0.5, 0.5, 0.5, 0.5, 0.5, 0.5]],
    'splits': {'test': {'garments': [{'length': 0.5, 'flare': 0.35, 'vertices': 110}],
                        'motions': [{'kind': 'kick'}]}},
}


def test_ship_weights_writes_weights_and_a_card_that_re_measures(tiny_checkpoint, tiny_windows,
                                                                 tmp_path):
    require('anny')
    require('lightning')
    from swingar_pyg.eval.model_card import check_slice_figures, ship_weights
    from swingar_pyg.training import load_estimator, load_pretrained

    card_path = ship_weights(tiny_checkpoint, 'tiny', tiny_windows.hparams.config,
                             extra_tests={'again': tiny_windows.hparams.config},
                             command='swingar fit (3 steps)', out_dir=tmp_path,
                             check_slice=TINY_CHECK_SLICE, progress=False,
                             settings={'clearance_scale': 0.03, 'contact_clearance': 0.006})
    assert sorted(p.name for p in tmp_path.iterdir()) == ['tiny.json', 'tiny.md', 'tiny.pt']
    card = json.loads(card_path.read_text())
    assert card['training']['step'] == 3 and card['data']['simulator_revisions'] == [
        card['check_slice']['simulator_revision']]
    shipped, data = load_pretrained(tmp_path / 'tiny.pt')
    trained, _ = load_estimator(tiny_checkpoint)
    for name, value in trained.state_dict().items():
        assert torch.equal(shipped.state_dict()[name], value), name
    assert trained.clearance_scale is None  # the gate is set on the trained network
    assert (shipped.clearance_scale, shipped.contact_clearance) == (0.03, 0.006)
    assert card['set_at_export'] == {'clearance_scale': 0.03, 'contact_clearance': 0.006}
    test = card['figures']['test']
    assert set(test) == {'all', 'skirt'} and test['all'] == test['skirt']
    assert card['figures']['again'] == test  # the same split measured twice
    assert 0 < test['all']['rigid_mean_mm'] and 0 < test['all']['estimator_mean_mm']
    again = check_slice_figures(shipped, data, recipe=card['check_slice']['recipe'])
    assert again == card['check_slice']['figures']  # deterministic on one machine
    markdown = (tmp_path / 'tiny.md').read_text()
    assert f"{test['all']['estimator_mean_mm']:.1f}" in markdown
    assert 'Set on the trained network at export' in markdown

    # the gate set anew on the shipped weights, without the checkpoint, onto themselves
    regated_path = ship_weights(None, 'tiny', tiny_windows.hparams.config, out_dir=tmp_path,
                                check_slice=TINY_CHECK_SLICE, progress=False,
                                settings={'clearance_scale': 0.05}, weights=tmp_path / 'tiny.pt')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['tiny.json', 'tiny.md', 'tiny.pt']
    regated_card = json.loads(regated_path.read_text())
    regated, _ = load_pretrained(tmp_path / 'tiny.pt')
    for name, value in trained.state_dict().items():
        assert torch.equal(regated.state_dict()[name], value), name
    assert (regated.clearance_scale, regated.contact_clearance) == (0.05, 0.006)
    assert regated_card['set_at_export'] == {'clearance_scale': 0.05, 'contact_clearance': 0.006}
    assert regated_card['training'] == card['training']  # provenance carried over
    assert regated_card['exported_from'] == {'weights': 'tiny.pt', 'sha256': card['sha256']}
    assert regated_card['sha256'] != card['sha256'] and 'exported_from' not in card
    assert regated_card['figures']['test']['all']['rigid_mean_mm'] == test['all']['rigid_mean_mm']
    assert f"sha256 `{card['sha256'][:16]}" in (tmp_path / 'tiny.md').read_text()
    # the clearance factor left out, the anchor factor set: both carried by file and card
    anchored_path = ship_weights(None, 'tiny', tiny_windows.hparams.config, out_dir=tmp_path,
                                 check_slice=TINY_CHECK_SLICE, progress=False,
                                 settings={'clearance_scale': None, 'anchor_scale': 0.3},
                                 weights=tmp_path / 'tiny.pt')
    anchored, _ = load_pretrained(tmp_path / 'tiny.pt')
    assert (anchored.clearance_scale, anchored.contact_clearance, anchored.anchor_scale) == (
        None, 0.006, 0.3)
    assert json.loads(anchored_path.read_text())['set_at_export'] == {
        'clearance_scale': None, 'contact_clearance': 0.006, 'anchor_scale': 0.3}
    assert '"anchor_scale": 0.3' in (tmp_path / 'tiny.md').read_text()


def test_ship_weights_cli_refuses_bad_arguments_before_any_work(tmp_path, capsys):
    require('lightning')
    from swingar_pyg.cli import main

    for arguments, message in (
            (['--extra-test', 'nolabel'], '--extra-test takes LABEL=CONFIG'),
            (['--name', 'base.pt'], 'a weights name is a bare file stem'),
            (['--name', '../x'], 'a weights name is a bare file stem'),
            (['--data', str(tmp_path / 'none.yaml')], 'no dataset config at'),
            (['--clearance-scale', '0'], 'expected metres > 0'),
            (['--contact-clearance', 'nan'], 'expected finite metres >= 0'),
            (['--clearance-scale', 'wide'], "expected metres, got 'wide'")):
        with pytest.raises(SystemExit):
            main(['ship-weights', '--ckpt', 'x.ckpt', '--name', 'x', '--data', 'd.yaml',
                  *arguments, '--out-dir', str(tmp_path)])
        assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(SystemExit):  # a checkpoint or shipped weights, not both
        main(['predict', '--ckpt', 'a.ckpt', '--weights', 'base', '--garment', 'g.obj'])
    assert 'not allowed with argument' in capsys.readouterr().err


def test_ship_weights_cli_passes_the_gate_on(tmp_path, monkeypatch, capsys):
    require('lightning')
    import swingar_pyg.eval.model_card as model_card
    from swingar_pyg.cli import main

    received = {}

    def recorded(*args, **kwargs):
        received.update(kwargs)
        raise SystemExit(0)

    monkeypatch.setattr(model_card, 'ship_weights', recorded)
    data = tmp_path / 'd.yaml'
    data.write_text('name: d\n')
    for options, settings in (([], {}),
                              (['--clearance-scale', '0.06', '--contact-clearance', '0.006'],
                               {'clearance_scale': 0.06, 'contact_clearance': 0.006})):
        with pytest.raises(SystemExit):
            main(['ship-weights', '--ckpt', 'x.ckpt', '--name', 'x', '--data', str(data),
                  *options, '--out-dir', str(tmp_path)])
        assert received['settings'] == settings
    with pytest.raises(SystemExit):  # shipped weights exported again with another gate
        main(['ship-weights', '--weights', 'base', '--name', 'x', '--data', str(data),
              '--clearance-scale', '0.03', '--out-dir', str(tmp_path)])
    assert received['weights'] == 'base' and received['settings'] == {'clearance_scale': 0.03}
    with pytest.raises(SystemExit):  # a factor left out, another set
        main(['ship-weights', '--weights', 'base', '--name', 'x', '--data', str(data),
              '--clearance-scale', 'none', '--anchor-scale', '0.3', '--out-dir', str(tmp_path)])
    assert received['settings'] == {'clearance_scale': None, 'anchor_scale': 0.3}
    with pytest.raises(SystemExit):
        main(['ship-weights', '--ckpt', 'x.ckpt', '--weights', 'base', '--name', 'x', '--data',
              str(data), '--out-dir', str(tmp_path)])
    assert 'not allowed with argument' in capsys.readouterr().err


def test_ship_weights_leaves_nothing_when_it_fails(tiny_checkpoint, tiny_windows, tmp_path):
    require('anny')
    require('lightning')
    from swingar_pyg.eval.model_card import ship_weights
    from swingar_pyg.models.pretrained import WEIGHTS_DIR, weights_sha256

    other = tmp_path / 'other.yaml'  # a valid config, but not the checkpoint's data
    other.write_text(Path(tiny_windows.hparams.config).read_text())
    out = tmp_path / 'weights'
    out.mkdir()
    (out / 'tiny.json').write_text('{"the": "old card"}')
    with pytest.raises(ValueError, match='was trained on'):
        ship_weights(tiny_checkpoint, 'tiny', other, out_dir=out, progress=False)
    with pytest.raises(ValueError, match='no dataset config at'):
        ship_weights(tiny_checkpoint, 'tiny', tiny_windows.hparams.config,
                     extra_tests={'missing': str(tmp_path / 'missing.yaml')}, out_dir=out,
                     progress=False)
    unmade = tmp_path / 'unmade.yaml'  # its data were never simulated
    unmade.write_text(other.read_text().replace(str(Path(tiny_windows.hparams.config).parent),
                                                str(tmp_path / 'nowhere')))
    with pytest.raises(ValueError, match='no test split at .*swingar make-dataset'):
        ship_weights(tiny_checkpoint, 'tiny', tiny_windows.hparams.config,
                     extra_tests={'unmade': str(unmade)}, out_dir=out, progress=False)
    val_only = yaml.safe_load(other.read_text())  # no test split to measure
    val_only['splits'] = {'val': val_only['splits']['val']}
    (tmp_path / 'val_only.yaml').write_text(yaml.safe_dump(val_only))
    with pytest.raises(ValueError, match="val_only.yaml has no 'test' split \\(it has val\\)"):
        ship_weights(tiny_checkpoint, 'tiny', tiny_windows.hparams.config,
                     extra_tests={'val only': str(tmp_path / 'val_only.yaml')}, out_dir=out,
                     progress=False)
    with pytest.raises(ValueError, match='a checkpoint or weights, exactly one of the two'):
        ship_weights(None, 'tiny', tiny_windows.hparams.config, out_dir=out, progress=False)
    with pytest.raises(ValueError, match='a checkpoint or weights, exactly one of the two'):
        ship_weights(tiny_checkpoint, 'tiny', tiny_windows.hparams.config, out_dir=out,
                     progress=False, weights='base')
    bare = tmp_path / 'bare'  # shipped weights without their card, then with a wrong card
    bare.mkdir()
    shutil.copy(WEIGHTS_DIR / 'base.pt', bare / 'base.pt')
    with pytest.raises(ValueError, match='no model card .*export its checkpoint with --ckpt'):
        ship_weights(None, 'tiny', tiny_windows.hparams.config, out_dir=out, progress=False,
                     weights=bare / 'base.pt')
    wrong = {**json.loads((WEIGHTS_DIR / 'base.json').read_text()), 'sha256': '0' * 64}
    (bare / 'base.json').write_text(json.dumps(wrong))
    with pytest.raises(ValueError, match='describes other weights than'):
        ship_weights(None, 'tiny', tiny_windows.hparams.config, out_dir=out, progress=False,
                     weights=bare / 'base.pt')
    (bare / 'base.json').write_text(json.dumps({'sha256': weights_sha256(bare / 'base.pt')}))
    with pytest.raises(ValueError, match='holds no training provenance'):
        ship_weights(None, 'tiny', tiny_windows.hparams.config, out_dir=out, progress=False,
                     weights=bare / 'base.pt')
    for settings, message in (({'channels': 8}, 'only clearance_scale, contact_clearance'),
                              ({'contact_clearance': 0.006}, 'does nothing without a'),
                              ({'anchor_scale': 0.3}, 'needs its contact_clearance'),
                              ({'clearance_scale': float('inf')}, 'finite positive metres')):
        with pytest.raises(ValueError, match=message):
            ship_weights(tiny_checkpoint, 'tiny', tiny_windows.hparams.config, out_dir=out,
                         progress=False, settings=settings)
    assert [p.name for p in out.iterdir()] == ['tiny.json']
    assert (out / 'tiny.json').read_text() == '{"the": "old card"}'


def test_measure_reads_stored_sequences_one_at_a_time_with_the_same_figures(tiny_checkpoint,
                                                                            tiny_windows,
                                                                            monkeypatch):
    require('anny')
    require('lightning')
    import swingar_pyg.eval.error_vs_time as error_vs_time
    from swingar_pyg.eval.error_vs_time import (
        StoredSequences,
        evaluate_estimator,
        evaluate_rigid,
        load_test_sequences,
    )
    from swingar_pyg.eval.model_card import made_split, measure
    from swingar_pyg.training import load_estimator
    from swingar_pyg.world.body import AnnyBody

    estimator, data = load_estimator(tiny_checkpoint)
    body = AnnyBody()
    _, path = made_split(tiny_windows.hparams.config)
    loaded = load_test_sequences(path, body)
    stored = StoredSequences(path, body)
    assert len(stored) == len(loaded) >= 1 and stored.ids == [s.id for s in loaded]
    reads = []

    def counted(*args, **kwargs):
        reads.append(kwargs['ids'])
        return load_test_sequences(*args, **kwargs)

    monkeypatch.setattr(error_vs_time, 'load_test_sequences', counted)
    for read, kept in zip(stored, loaded):
        assert read.id == kept.id and torch.equal(read.truth, kept.truth)
        assert torch.equal(read.posed.joint_transforms, kept.posed.joint_transforms)
    assert reads == [[s.id] for s in loaded]  # one sequence a read
    lazily = measure(estimator, data, stored, progress=False)
    rigid = evaluate_rigid(loaded).stats()
    streamed = evaluate_estimator('estimator', estimator, loaded, data['sigma'],
                                  data['seed']).stats()
    assert lazily['all']['sequences'] == len(loaded)
    assert lazily['all']['rigid_mean_mm'] == pytest.approx(rigid['mean_mm'], rel=1e-6)
    assert lazily['all']['estimator_p95_mm'] == pytest.approx(streamed['p95_mm'], rel=1e-6)
    assert lazily['all']['mean_ratio'] == pytest.approx(
        streamed['mean_mm'] / rigid['mean_mm'], rel=1e-6)
