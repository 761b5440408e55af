import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from swingar_pyg.sim import STRETCH_BAR
from swingar_pyg.world.dataset import DatasetConfig, job_recipe, make_dataset, plan_jobs
from tests.extras import require

TINY = """
name: tiny
output: {output}
seconds: 0.2
fps: 30
solver: {{substeps: 8, iterations: 2, settle_frames: 1}}
body_shapes: [[0.5, 0.5, 0.5, 0.5, 0.5, 0.5]]
splits:
  train:
    garments:
      - {{length: 0.4, flare: 0.3, vertices: 120}}
      - {{length: 0.5, vertices: 150, jitter: 0.3}}
    motions: [{{kind: sway}}]
  test:
    garments: [{{length: 0.6, flare: 0.4, vertices: 130}}]
    motions: [{{kind: twist}}]
"""


def tiny_config(tmp_path: Path, text: str = TINY) -> DatasetConfig:
    path = tmp_path / 'tiny.yaml'
    path.write_text(text.format(output=tmp_path / 'data'))
    return DatasetConfig.from_yaml(path)


def test_shipped_configs_plan_disjoint_splits():
    root = Path(__file__).resolve().parents[1] / 'configs' / 'data'
    for name in ('quickstart', 'full', 'base'):
        config = DatasetConfig.from_yaml(root / f'{name}.yaml')
        jobs = plan_jobs(config)
        kinds = {split: {job.motion.kind for job in jobs if job.split == split}
                 for split in ('train', 'val', 'test')}
        assert not (kinds['train'] & kinds['test']) and not (kinds['train'] & kinds['val'])
        garments = {split: {job.garment for job in jobs if job.split == split}
                    for split in ('train', 'test')}
        assert not garments['train'] & garments['test']
        assert len({job.id for job in jobs}) == len(jobs)


def test_a_motion_family_in_two_splits_is_refused(tmp_path):
    text = TINY.replace('motions: [{{kind: twist}}]', 'motions: [{{kind: sway, speed: 2}}]')
    with pytest.raises(ValueError, match="motion sway is in both the train and the test split"):
        plan_jobs(tiny_config(tmp_path, text))


def test_config_errors_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match="needs 'body_shapes'"):
        tiny_config(tmp_path, TINY.replace('body_shapes', 'shapes'))
    with pytest.raises(ValueError, match="unknown splits"):
        tiny_config(tmp_path, TINY.replace('test:', 'holdout:'))
    with pytest.raises(ValueError, match="flare"):
        tiny_config(tmp_path, TINY.replace('flare: 0.4', 'flare: 4'))


def test_generation_resumes_and_merges(tmp_path):
    require('anny')
    config = tiny_config(tmp_path)
    first = make_dataset(config, progress=False)
    assert first['generated'] == 3 and first['splits']['train']['complete']
    output = tmp_path / 'data'
    with h5py.File(output / 'train.h5') as file:
        assert sorted(file['sequences']) == ['train-00000', 'train-00001']
        assert len(file['garments']) == 2
        reference = file['sequences/train-00001/garment_vertices'][:]
        assert np.isfinite(reference).all()
        exact = file['sequences/train-00001/penetration_exact'][:]
        assert exact.shape == (len(reference),) and ((exact >= 0) & (exact <= 1)).all()
    assert 0 <= first['simulation']['max_penetration_exact'] <= 1
    largest, substeps = [], []
    for split in ('train', 'test'):
        with h5py.File(output / f'{split}.h5') as file:
            largest += [g['max_stretch'][:].max() for g in file['sequences'].values()]
            substeps += [g['substeps_per_frame'][:].mean() for g in file['sequences'].values()]
    assert len(largest) == 3
    assert np.isclose(first['simulation']['substeps_mean'], np.mean(substeps))
    assert np.isclose(first['simulation']['max_stretch_median_sequence'], np.median(largest))
    assert np.isclose(first['simulation']['share_over_stretch_bar'],
                      np.mean(np.array(largest) > STRETCH_BAR))
    places = first['simulation']['over_stretch_bar_by_place']
    assert set(places) <= {'near_pins', 'touching', 'free'}
    assert sum(places.values()) == np.sum(np.array(largest) > STRETCH_BAR)
    families = first['simulation']['by_garment_family']
    assert list(families) == ['skirt'] and families['skirt']['sequences'] == 3
    motions = first['simulation']['by_motion']
    assert {name: row['sequences'] for name, row in motions.items()} == {'sway': 2, 'twist': 1}
    assert np.isclose(motions['twist']['max_stretch'], largest[-1])  # the test split's one
    # A killed run leaves some parts; only the missing ones are simulated again.
    (output / 'parts' / 'train' / 'train-00001.h5').unlink()
    (output / 'train.h5').unlink()
    again = make_dataset(config, progress=False)
    assert again['generated'] == 1 and again['skipped_existing'] == 2
    with h5py.File(output / 'train.h5') as file:
        assert np.array_equal(file['sequences/train-00001/garment_vertices'][:], reference)
    # A part made from another recipe (the config changed since) is simulated again: here
    # the test garment is longer, and a train part lost its recipe (as parts made before
    # recipes were recorded have none); the split files are merged from current parts.
    # A part whose recipe predates a solver or motion setting (here stall_ratio and
    # arms_out) was made as its default makes it: it is kept.
    changed = tiny_config(tmp_path, TINY.replace('length: 0.6', 'length: 0.65'))
    with h5py.File(output / 'parts' / 'train' / 'train-00000.h5', 'a') as file:
        del file.attrs['recipe']
    with h5py.File(output / 'parts' / 'train' / 'train-00001.h5', 'a') as file:
        older = json.loads(file.attrs['recipe'])
        del older['solver']['stall_ratio']
        del older['motion']['arms_out']
        file.attrs['recipe'] = json.dumps(older, sort_keys=True)
    with pytest.warns(UserWarning, match='2 part file'):
        third = make_dataset(changed, progress=False)
    assert third['generated'] == 2 and third['replaced_stale'] == 2
    assert third['skipped_existing'] == 1
    with h5py.File(output / 'test.h5') as file:
        heights = file['garments'][next(iter(file['garments']))]['rest_vertices'][:, 2]
        assert np.ptp(heights) == pytest.approx(0.65, abs=1e-6)
    with h5py.File(output / 'parts' / 'train' / 'train-00000.h5') as file:
        assert file.attrs['recipe'] == job_recipe(plan_jobs(changed)[0], changed)
    with h5py.File(output / 'parts' / 'train' / 'train-00001.h5') as file:
        assert 'stall_ratio' not in json.loads(file.attrs['recipe'])['solver']
        assert 'arms_out' not in json.loads(file.attrs['recipe'])['motion']
        assert np.array_equal(file['sequences'][next(iter(file['sequences']))]
                              ['garment_vertices'][:], reference)


def test_shards_split_the_jobs_and_merge_when_all_are_done(tmp_path):
    require('anny')
    config = tiny_config(tmp_path)
    first = make_dataset(config, shard=(0, 2), progress=False)
    assert first['generated'] == 2  # jobs 0 and 2 of 3
    assert not first['splits']['train']['complete']
    assert not (tmp_path / 'data' / 'train.h5').exists()
    second = make_dataset(config, shard=(1, 2), progress=False)
    assert second['generated'] == 1 and second['splits']['train']['complete']
    assert (tmp_path / 'data' / 'train.h5').exists() and (tmp_path / 'data' / 'test.h5').exists()
    with pytest.raises(ValueError, match='shard must be i/n'):
        make_dataset(config, shard=(2, 2), progress=False)


def test_configs_take_dresses_and_shipped_garments(tmp_path):
    from swingar_pyg.world.catalogue import ShippedGarmentSpec
    from swingar_pyg.world.skirt import DressSpec, SkirtSpec

    text = TINY.replace('garments: [{{length: 0.6, flare: 0.4, vertices: 130}}]',
                        'garments: [{{kind: dress, length: 0.9, vertices: 300}}, '
                        '{{kind: shipped, name: overall_jumpsuit, subdivisions: 1}}]')
    config = tiny_config(tmp_path, text)
    assert config.garments['test'] == (DressSpec(length=0.9, vertices=300),
                                       ShippedGarmentSpec('overall_jumpsuit', 1))
    assert isinstance(config.garments['train'][0], SkirtSpec)
    assert DressSpec(length=0.9, vertices=300).name.startswith('dress-')
    assert len(plan_jobs(config)) == 4
    with pytest.raises(ValueError, match="unknown garment kind 'cape'"):
        tiny_config(tmp_path, TINY.replace('{{length: 0.6,', '{{kind: cape, length: 0.6,'))
    with pytest.raises(ValueError, match='subdivisions'):
        ShippedGarmentSpec('overall_jumpsuit', 5)
    with pytest.raises(ValueError, match='merge_edges_below'):
        ShippedGarmentSpec('shorts', merge_edges_below=1.0)


def test_a_split_of_blocks_pairs_each_block_and_keeps_earlier_jobs(tmp_path):
    one = tiny_config(tmp_path)
    blocks = TINY.replace("""  train:
    garments:
      - {{length: 0.4, flare: 0.3, vertices: 120}}
      - {{length: 0.5, vertices: 150, jitter: 0.3}}
    motions: [{{kind: sway}}]""", """  train:
    - garments:
        - {{length: 0.4, flare: 0.3, vertices: 120}}
        - {{length: 0.5, vertices: 150, jitter: 0.3}}
      motions: [{{kind: sway}}]
    - garments: [{{length: 0.4, flare: 0.3, vertices: 120}}]
      motions: [{{kind: cmu_02_01_walk_delfem2, arms_out: 20}}]""")
    two = tiny_config(tmp_path, blocks)
    before, after = plan_jobs(one), plan_jobs(two)
    train = [job for job in after if job.split == 'train']
    assert [(j.id, j.garment, j.motion) for j in before if j.split == 'train'] == \
        [(j.id, j.garment, j.motion) for j in train[:2]]
    assert len(train) == 3 and train[2].motion.arms_out == 20
    assert two.garments['train'] == one.garments['train']  # each garment once
    assert [m.kind for m in two.motions['train']] == ['sway', 'cmu_02_01_walk_delfem2']
