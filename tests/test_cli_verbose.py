"""Warp's start-up banner (anny's skinning initialises Warp) is silent unless
`swingar --verbose` asks for it."""

import os
import subprocess
import sys

import pytest

from tests.extras import require

BANNER = ('initialized', 'CUDA driver', 'Kernel cache', "load on device 'cpu'")


def _simulate(tmp_path, *flags):
    """`swingar [flags] simulate` on a tiny skirt, in a fresh process (Warp
    initialises once per process); its stdout and stderr."""
    environment = {**os.environ, 'OMP_NUM_THREADS': '1'}
    environment.pop('SWINGAR_VERBOSE', None)
    run = subprocess.run([sys.executable, '-m', 'swingar_pyg.cli', *flags, 'simulate',
                          '--seconds', '0.1', '--vertices', '200', '--substeps', '5',
                          '--no-preview', '--out', str(tmp_path / 'run')],
                         capture_output=True, text=True, env=environment, timeout=300)
    assert run.returncode == 0, run.stderr
    assert 'wrote' in run.stdout
    return run.stdout, run.stderr


def test_warp_banner_only_with_verbose(tmp_path):
    require('anny')
    out, err = _simulate(tmp_path)
    for line in BANNER + ('Warp',):
        assert line not in out and line not in err, (line, out, err)
    out, err = _simulate(tmp_path, '--verbose')
    assert 'Warp ' in out and 'initialized' in out, out
    assert "load on device 'cpu'" in out, out


def test_only_the_missing_driver_line_is_dropped_from_native_stderr(capfd, monkeypatch):
    """What Warp's native init writes to stderr passes through, less the
    missing-CUDA-driver warning; an error still raises."""
    from swingar_pyg import verbosity

    def native_init():
        os.write(2, b'Warp CUDA warning: Could not find or load the NVIDIA CUDA driver. GPU '
                    b'execution will not be available.\nWarp CUDA error: something else\n')

    verbosity._without_native_driver_warning(native_init)
    err = capfd.readouterr().err
    assert err == 'Warp CUDA error: something else\n'

    def failing_init():
        os.write(2, b'native trouble\n')
        raise RuntimeError('Warp initialization failed')

    with pytest.raises(RuntimeError, match='initialization failed'):
        verbosity._without_native_driver_warning(failing_init)
    assert capfd.readouterr().err == 'native trouble\n'
    monkeypatch.setenv('SWINGAR_VERBOSE', '1')
    assert verbosity.is_verbose()
    monkeypatch.setenv('SWINGAR_VERBOSE', '0')
    assert not verbosity.is_verbose()
