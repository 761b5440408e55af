"""The datamodule's feature cache: one file per settings beside the split file,
which is only read; stale, unreadable, interrupted and concurrent cases."""

import os
import shutil
import threading

import h5py
import pytest

from tests.extras import require

require('lightning')

from datamodules import (  # noqa: E402
    FeatureSettings,
    GarmentWindowDataset,
    ensure_feature_cache,
    feature_cache,
)
from datamodules.feature_cache import current_feature_cache, feature_cache_path  # noqa: E402


@pytest.fixture
def split(tiny_windows, tmp_path):
    """A copy of the tiny validation split, without a cache."""
    copy = tmp_path / 'val.h5'
    shutil.copyfile(tiny_windows.split_path('val'), copy)
    return copy


def _other(settings: FeatureSettings) -> FeatureSettings:
    return FeatureSettings(**{**settings.__dict__, 'descriptor_size': 8})


def test_caches_of_several_settings_stand_beside_an_untouched_split(tiny_windows, split):
    settings, other = tiny_windows.settings, _other(tiny_windows.settings)
    stamp, content = os.stat(split).st_mtime_ns, split.read_bytes()
    assert ensure_feature_cache(split, settings, progress=False)
    assert not ensure_feature_cache(split, settings, progress=False)
    assert ensure_feature_cache(split, other, progress=False)
    assert feature_cache_path(split, settings) != feature_cache_path(split, other)
    assert not ensure_feature_cache(split, settings, progress=False)
    assert os.stat(split).st_mtime_ns == stamp and split.read_bytes() == content
    assert GarmentWindowDataset(split, other, history=8)[0].descriptor.shape == (1, 8)
    assert GarmentWindowDataset(split, settings, history=8)[0].descriptor.shape == (
        1, settings.descriptor_size)


def test_a_split_made_again_makes_its_caches_stale(tiny_windows, split):
    settings = tiny_windows.settings
    ensure_feature_cache(split, settings, progress=False)
    stamp = os.stat(split).st_mtime_ns
    os.utime(split, ns=(stamp, stamp + 10**9))
    assert current_feature_cache(split, settings) is None
    with pytest.raises(ValueError, match='no current feature cache'):
        GarmentWindowDataset(split, settings)
    assert ensure_feature_cache(split, settings, progress=False)
    moved = split.with_name('moved.h5')
    shutil.copyfile(split, moved)  # a copy is another file: its own cache
    assert current_feature_cache(moved, settings) is None


def test_an_unreadable_cache_is_computed_again(tiny_windows, split):
    settings = tiny_windows.settings
    ensure_feature_cache(split, settings, progress=False)
    feature_cache_path(split, settings).write_bytes(b'not hdf5')
    assert current_feature_cache(split, settings) is None
    assert ensure_feature_cache(split, settings, progress=False)
    assert GarmentWindowDataset(split, settings, history=8)[0] is not None


def test_a_cache_group_inside_the_split_is_not_used(tiny_windows, split):
    settings = tiny_windows.settings
    with h5py.File(split, 'a') as file:  # the layout of earlier versions
        file.create_group('cache').attrs['settings'] = settings.to_json()
    content = split.read_bytes()
    assert current_feature_cache(split, settings) is None
    assert ensure_feature_cache(split, settings, progress=False)
    assert split.read_bytes() == content


def test_an_interrupted_write_leaves_the_old_cache_and_no_temporary_file(
        tiny_windows, split, monkeypatch):
    settings = tiny_windows.settings
    ensure_feature_cache(split, settings, progress=False)
    cache = feature_cache_path(split, settings)
    old = cache.read_bytes()
    stamp = os.stat(split).st_mtime_ns
    os.utime(split, ns=(stamp, stamp + 10**9))

    def interrupted(*args, **kwargs):
        raise RuntimeError('interrupted')

    monkeypatch.setattr(feature_cache, '_cache_sequences', interrupted)
    with pytest.raises(RuntimeError, match='interrupted'):
        ensure_feature_cache(split, settings, progress=False)
    assert cache.read_bytes() == old
    assert not list(split.parent.glob('*.tmp'))


def test_leftovers_of_a_killed_writer_are_removed(tiny_windows, split):
    settings = tiny_windows.settings
    cache = feature_cache_path(split, settings)
    leftover = cache.with_name(f'.{cache.name}.killed.tmp')
    leftover.write_bytes(b'half')
    assert ensure_feature_cache(split, settings, progress=False)
    assert not leftover.exists()


def test_a_second_process_waits_for_the_cache_instead_of_computing_it(
        tiny_windows, split, monkeypatch):
    settings = tiny_windows.settings
    ensure_feature_cache(split, settings, progress=False)
    cache = feature_cache_path(split, settings)
    finished = cache.with_name('finished.h5')
    cache.rename(finished)  # as if another process were still computing it

    def computed_twice(*args, **kwargs):
        raise AssertionError('computed while another process held the lock')

    monkeypatch.setattr(feature_cache, '_cache_garments', computed_twice)
    results = []
    waiting = threading.Thread(target=lambda: results.append(
        ensure_feature_cache(split, settings, progress=False)))
    with open(cache.with_name(cache.name + '.lock'), 'w') as lock:
        feature_cache.fcntl.flock(lock, feature_cache.fcntl.LOCK_EX)
        waiting.start()
        waiting.join(timeout=1.0)
        assert waiting.is_alive()  # blocked on the lock
        finished.rename(cache)  # the other process's cache lands, then it lets go
    waiting.join(timeout=60)
    assert results == [False]
