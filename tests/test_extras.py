"""Missing extras: tests skip on a developer's machine, but fail in CI (``CI=true``),
where ``.ci/setup`` installs them and a skip would hide a broken environment."""

import re
import sys
from pathlib import Path

import pytest

from tests.extras import REQUIRED_IN_CI, in_ci, require

TESTS = Path(__file__).resolve().parent


def test_require_fails_under_ci_and_skips_elsewhere(monkeypatch):
    """A required extra that does not import fails the test under CI=true and skips it
    otherwise; one that imports is returned; an extra CI does not install is refused."""
    monkeypatch.setitem(sys.modules, 'anny', None)  # `import anny` now raises ImportError
    monkeypatch.setenv('CI', 'true')
    assert in_ci()
    with pytest.raises(pytest.fail.Exception, match="CI=true and 'anny' \\(extra body\\)"):
        require('anny')
    for value in ('false', ''):
        monkeypatch.setenv('CI', value)
        with pytest.raises(pytest.skip.Exception, match="could not import 'anny'"):
            require('anny')
    monkeypatch.delenv('CI')
    with pytest.raises(pytest.skip.Exception):
        require('anny')
    assert require('trimesh').__name__ == 'trimesh'
    with pytest.raises(ValueError, match='use pytest.importorskip'):
        require('torch_scatter')


def test_no_test_skips_on_an_extra_that_ci_installs():
    """Every test needing a required extra goes through require(), not a plain
    importorskip or skipif that CI would count as a pass."""
    names = '|'.join(map(re.escape, REQUIRED_IN_CI))
    skipping = re.compile(rf"""importorskip\(\s*['"]({names})['"]|skipif\(.*\b({names})\b""")
    offenders = [f'{path.name}:{number}: {line.strip()}'
                 for path in sorted(TESTS.glob('*.py')) if path.name != 'extras.py'
                 for number, line in enumerate(path.read_text().splitlines(), 1)
                 if skipping.search(line) and path != Path(__file__).resolve()]
    assert not offenders, '\n'.join(offenders)


def test_nothing_in_the_tests_points_outside_the_repository():
    """A user's clone has no ../shared: the tests must not read from it."""
    offenders = [f'{path.name}:{number}' for path in sorted(TESTS.glob('*.py'))
                 if path != Path(__file__).resolve()
                 for number, line in enumerate(path.read_text().splitlines(), 1)
                 if "'shared'" in line or '../shared' in line or 'parents[2]' in line]
    assert not offenders, offenders
