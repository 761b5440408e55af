"""The code is lint-free (ruff: pycodestyle, pyflakes, import order) and keeps its
layers (import-linter: the contracts in ``pyproject.toml``, docs/design.md §1)."""

import subprocess
import sys
from pathlib import Path

from tests.extras import require

ROOT = Path(__file__).resolve().parents[1]


def _run(*command: str) -> subprocess.CompletedProcess:
    return subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_ruff_finds_nothing():
    require('ruff')
    result = _run(sys.executable, '-m', 'ruff', 'check', '--no-cache', '.')
    assert result.returncode == 0, result.stdout + result.stderr


def test_imports_keep_the_layers():
    require('importlinter')
    script = Path(sys.executable).with_name('lint-imports')
    result = _run(str(script), '--no-cache')
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'broken' in result.stdout and ' 0 broken' in result.stdout, result.stdout
