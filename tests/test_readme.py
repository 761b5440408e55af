"""The README's Python examples run as written."""

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / 'README.md'
BLOCKS = re.findall(r'```python\n(.*?)```', README.read_text(), flags=re.S)


@pytest.mark.parametrize('code', BLOCKS, ids=[f'block{i}' for i in range(len(BLOCKS))])
def test_readme_example_runs(code):
    exec(compile(code, str(README), 'exec'), {})


def test_readme_has_examples():
    assert len(BLOCKS) >= 2


def test_ci_runs_the_readme_test_command():
    ci = (README.parent / '.ci' / 'run').read_text().strip().splitlines()[-1]
    assert ci in README.read_text()
