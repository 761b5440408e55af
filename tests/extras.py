"""Optional extras the tests need, required in CI.

Outside CI a test whose extra is missing skips, as with :func:`pytest.importorskip`.
With ``CI=true`` (set by GitHub Actions, GitLab CI and most runners; export it when
running ``.ci/run`` elsewhere) it fails instead: ``.ci/setup`` installs the ``dev``,
``body`` and ``newton`` extras, so a missing one there is a broken environment, and
skipping half the suite would leave CI green.
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType

import pytest

REQUIRED_IN_CI = {
    'anny': 'body',
    'h5py': 'data (in dev)',
    'importlinter': 'dev',
    'lightning': 'train (in dev)',
    'matplotlib': 'viz (in dev)',
    'nbclient': 'dev (through nbmake)',
    'nbformat': 'dev (through nbmake)',
    'ruff': 'dev',
    'newton': 'newton',
    'pxr': 'usd (in dev)',
    'smplx': 'smpl (in dev)',
    'trimesh': 'data (in dev)',
}
"""Modules of the extras ``.ci/setup`` installs, and the extra each comes with."""


def in_ci() -> bool:
    return os.environ.get('CI', '').strip().lower() == 'true'


def require(module: str) -> ModuleType:
    """Imports ``module``, one of :data:`REQUIRED_IN_CI`; if it does not import, skips
    the test (or the test module, at module level), or fails it under ``CI=true``.
    For an extra CI does not install, use :func:`pytest.importorskip`."""
    if module not in REQUIRED_IN_CI:
        raise ValueError(f'{module!r} is not an extra .ci/setup installs '
                         f'({", ".join(sorted(REQUIRED_IN_CI))}); use pytest.importorskip')
    try:
        return importlib.import_module(module)
    except ImportError as error:
        if in_ci():
            pytest.fail(f'CI=true and {module!r} (extra {REQUIRED_IN_CI[module]}) does not '
                        f'import: {error}', pytrace=False)
        pytest.skip(f'could not import {module!r}: {error}', allow_module_level=True)
