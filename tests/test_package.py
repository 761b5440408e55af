import subprocess
import sys

import pytest

from swingar_pyg import __version__
from swingar_pyg.cli import main
from swingar_pyg.world.garment_assets import load_shipped_garment, shipped_garments

HEAVY = ['scipy', 'h5py', 'trimesh', 'lightning', 'matplotlib', 'anny', 'swingar_pyg.geometry']


def test_nn_imports_nothing_but_torch_and_pyg():
    code = ('import sys, swingar_pyg.nn; '
            f'print(",".join(m for m in {HEAVY!r} if m in sys.modules))')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.strip() == ''


def test_version_and_help(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(['--version'])
    assert exit_info.value.code == 0
    assert __version__ in capsys.readouterr().out
    assert main([]) == 0
    assert 'demo' in capsys.readouterr().out


def test_shipped_garments_are_in_metres_z_up():
    names = shipped_garments()
    assert len(names) == 10 and 'dress_skirt_knee' in names
    skirt = load_shipped_garment('dress_skirt_knee')
    extent = skirt.vertices.max(0) - skirt.vertices.min(0)
    # A knee-length skirt on a 1.7 m body: taller (z) than deep (y), about half a metre.
    assert 0.3 < extent[2] < 0.7 and extent[2] > extent[1]
    with pytest.raises(ValueError, match="no shipped garment 'cape'"):
        load_shipped_garment('cape')


def test_demo_runs_and_batch_matches(capsys):
    assert main(['demo', '--garment', 'dress_skirt_knee', '--garment', 'sport_top',
                 '--z', '32']) == 0
    out = capsys.readouterr().out
    assert 'dress_skirt_knee' in out and 'sport_top' in out
    gap = float(out.rsplit('per-garment runs:', 1)[1])
    assert gap < 1e-5


def test_cli_reports_bad_input_as_an_error(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(['demo', '--garment', 'cape'])
    assert exit_info.value.code == 2
    assert "no shipped garment 'cape'" in capsys.readouterr().err
