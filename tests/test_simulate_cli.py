import h5py
import numpy as np
import pytest

from swingar_pyg.cli import main
from tests.extras import require


def test_simulate_writes_a_sequence_file_and_a_preview(tmp_path, capsys):
    require('anny')
    out = tmp_path / 'run'
    assert main(['simulate', '--motion', 'twist', '--seconds', '0.4', '--vertices', '200',
                 '--substeps', '10', '--out', str(out)]) == 0
    assert 'max stretch' in capsys.readouterr().out
    with h5py.File(out / 'sequence.h5') as file:
        sequence = file['sequences/000000']
        garment = file['garments'][sequence.attrs['garment']]
        frames = len(sequence['rotations'])
        assert frames == 12
        assert sequence['garment_vertices'].shape == (frames, len(garment['rest_vertices']), 3)
        assert garment['fit'].shape == (len(garment['rest_vertices']),)
        assert (garment['fit'][:] > 0).all()  # fitted outside the body
        assert np.isfinite(sequence['garment_vertices'][:]).all()
        assert sequence.attrs['fps'] == 30.0
    assert (out / 'preview.gif').stat().st_size > 0
    assert sorted(p.name for p in out.iterdir()) == ['preview.gif', 'sequence.h5']


def test_simulate_with_the_vbd_solver_stores_its_settings(tmp_path, capsys):
    require('anny')
    require('newton')
    import json

    out = tmp_path / 'run'
    assert main(['simulate', '--solver', 'vbd', '--motion', 'sway', '--seconds', '0.2',
                 '--vertices', '150', '--substeps', '4', '--no-preview', '--out', str(out)]) == 0
    with h5py.File(out / 'sequence.h5') as file:
        sequence = file['sequences/000000']
        settings = json.loads(sequence.attrs['settings'])
        assert settings['substeps'] == 4 and settings['iterations'] == 10  # VBD's default
        assert 'material_damping' in settings
        assert np.isfinite(sequence['garment_vertices'][:]).all()


def test_simulate_with_dihedral_bending_stores_the_model(tmp_path, capsys):
    require('anny')
    import json

    out = tmp_path / 'run'
    assert main(['simulate', '--bending', 'dihedral', '--motion', 'sway', '--seconds', '0.2',
                 '--vertices', '150', '--substeps', '5', '--no-preview', '--out', str(out)]) == 0
    with h5py.File(out / 'sequence.h5') as file:
        sequence = file['sequences/000000']
        settings = json.loads(sequence.attrs['settings'])
        assert settings['bending'] == 'dihedral' and settings['bend_stiffness'] == 1e-3
        assert np.isfinite(sequence['garment_vertices'][:]).all()
    with pytest.raises(SystemExit):
        main(['simulate', '--solver', 'vbd', '--bending', 'distance', '--out', str(out)])
    assert '--bending chooses the XPBD bending model' in capsys.readouterr().err


def test_simulate_with_error_controlled_substeps_records_them(tmp_path, capsys):
    require('anny')
    import json

    out = tmp_path / 'run'
    # 2 substeps a frame stretch a kicked skirt far beyond the bar: frames are re-run
    assert main(['simulate', '--motion', 'kick', '--seconds', '0.3', '--vertices', '150',
                 '--substeps', '2', '--max-substeps', '16', '--no-preview',
                 '--out', str(out)]) == 0
    with h5py.File(out / 'sequence.h5') as file:
        sequence = file['sequences/000000']
        assert json.loads(sequence.attrs['settings'])['max_substeps'] == 16
        used = sequence['substeps_per_frame'][:]
        stretch = sequence['max_stretch'][:]
    assert set(used.tolist()) <= {2, 4, 8, 16} and used.max() > 2
    assert (stretch[used < 16] <= 0.06).all()
    # A stall ratio no re-run can meet (a largest strain below 1e-3 of the last) stops
    # every frame's doubling at its first re-run.
    assert main(['simulate', '--motion', 'kick', '--seconds', '0.3', '--vertices', '150',
                 '--substeps', '2', '--max-substeps', '16', '--stall-ratio', '0.001',
                 '--no-preview', '--out', str(out / 'stall')]) == 0
    with h5py.File(out / 'stall' / 'sequence.h5') as file:
        sequence = file['sequences/000000']
        assert json.loads(sequence.attrs['settings'])['stall_ratio'] == 0.001
        kept = set(sequence['substeps_per_frame'][:].tolist())
    assert kept <= {2, 4} and 4 in kept
    with pytest.raises(SystemExit):
        main(['simulate', '--stall-ratio', '0.9', '--out', str(out)])
    assert '--stall-ratio stops' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['simulate', '--solver', 'vbd', '--max-substeps', '20', '--out', str(out)])
    assert '--max-substeps is XPBD' in capsys.readouterr().err


def test_simulate_a_sewn_jumpsuit(tmp_path, capsys):
    require('anny')
    out = tmp_path / 'run'
    assert main(['simulate', '--kind', 'jumpsuit', '--motion', 'walk', '--seconds', '0.2',
                 '--vertices', '300', '--substeps', '5', '--no-preview', '--out', str(out)]) == 0
    assert 'jumpsuit-g0.90-n300-grid' in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(['simulate', '--kind', 'jumpsuit', '--length', '0.5', '--out', str(out)])
    assert "--length is not a jumpsuit's" in capsys.readouterr().err


def test_simulate_a_skirt_with_a_slit(tmp_path, capsys):
    require('anny')
    out = tmp_path / 'run'
    assert main(['simulate', '--length', '0.7', '--slit', '0.3', '--motion', 'walk',
                 '--seconds', '0.2', '--vertices', '300', '--substeps', '5', '--no-preview',
                 '--out', str(out)]) == 0
    assert 'skirt-l0.70-f0.35-n300-grid-s0.30' in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(['simulate', '--kind', 'tshirt', '--slit', '0.2', '--out', str(out)])
    assert "--slit is a skirt's or a dress's, not a tshirt's" in capsys.readouterr().err


def test_simulate_rejects_an_unknown_motion(tmp_path, capsys):
    require('anny')
    with pytest.raises(SystemExit):
        main(['simulate', '--motion', 'moonwalk', '--out', str(tmp_path)])
    assert "unknown motion 'moonwalk'" in capsys.readouterr().err


def test_preview_renders_a_stored_sequence(tmp_path, capsys):
    require('anny')
    out = tmp_path / 'run'
    assert main(['simulate', '--motion', 'sway', '--seconds', '0.2', '--vertices', '150',
                 '--substeps', '5', '--out', str(out), '--no-preview']) == 0
    assert main(['preview', str(out / 'sequence.h5'), '000000', '--out',
                 str(tmp_path / 'p.png')]) == 0
    assert (tmp_path / 'p.png').stat().st_size > 0
    with pytest.raises(SystemExit):
        main(['preview', str(out / 'sequence.h5'), 'nope', '--out', str(tmp_path / 'q.png')])
    assert "has no sequence 'nope'" in capsys.readouterr().err
