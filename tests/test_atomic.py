import pytest

from swingar_pyg.atomic import atomic_path


def test_success_replaces_the_target(tmp_path):
    target = tmp_path / 'sub' / 'out.json'
    with atomic_path(target) as tmp:
        tmp.write_text('new')
        assert not target.exists()
    assert target.read_text() == 'new'
    assert list(target.parent.iterdir()) == [target]
    plain = tmp_path / 'plain.json'
    plain.write_text('x')
    assert target.stat().st_mode == plain.stat().st_mode


def test_failure_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    target = tmp_path / 'out.json'
    target.write_text('old')
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text('half')
            raise RuntimeError('killed mid-write')
    assert target.read_text() == 'old'
    assert list(tmp_path.iterdir()) == [target]
