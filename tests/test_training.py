import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from torch_geometric.data import Batch

from swingar_pyg.models import SwinGarEstimator
from tests.extras import require
from tests.windows import SMALL_ESTIMATOR, SMALL_FEATURES

L = require('lightning')


def test_overfits_one_short_sequence(tiny_windows):
    from swingar_pyg.training import SwinGarModule

    dataset = tiny_windows.datasets['train']
    batch = Batch.from_data_list([dataset[k] for k, (s, _) in enumerate(dataset.windows)
                                  if s == 0])
    module = SwinGarModule(SwinGarEstimator(**{**SMALL_ESTIMATOR, 'channels': 32}),
                           collision_weight=0.0)
    optimizer = torch.optim.Adam(module.parameters(), lr=1e-2)
    losses = []
    for _ in range(500):
        optimizer.zero_grad()
        terms = module._losses(batch, module(batch))
        loss = sum(module.weights[name] * value for name, value in terms.items())
        loss.backward()
        optimizer.step()
        losses.append(loss.detach().item())
    # revision-4 data (hinge bending, tethers) leaves more swing to fit: 6.9x in 500 steps
    assert min(losses[-10:]) < losses[0] / 5, (losses[0], losses[-10:])


def test_offset_losses_are_the_mean_squared_blend_shapes_and_correction(tiny_windows):
    from swingar_pyg.training import SwinGarModule

    dataset = tiny_windows.datasets['train']
    batch = Batch.from_data_list([dataset[0], dataset[len(dataset) - 1]])
    estimator = SwinGarEstimator(**SMALL_ESTIMATOR)
    blend, correction = torch.tensor([0.01, -0.02, 0.03]), torch.tensor([0.05, 0.0, -0.01])
    with torch.no_grad():  # constant offsets: the correction turns with the body, same length
        estimator.blend_head.bias.copy_(blend)
        estimator.correction.bias.copy_(correction)
    module = SwinGarModule(estimator, blend_weight=0.5, correction_weight=0.5,
                           collision_weight=0.0)
    terms = module._losses(batch, module(batch))
    torch.testing.assert_close(terms['blend'], blend.square().sum())
    torch.testing.assert_close(terms['correction'], correction.square().sum())
    plain = SwinGarModule(estimator, collision_weight=0.0)
    assert not {'blend', 'correction'} & set(plain._losses(batch, plain(batch)))
    with pytest.raises(ValueError, match='correction_weight needs the detail network'):
        SwinGarModule(SwinGarEstimator(**{**SMALL_ESTIMATOR, 'detail': False}),
                      correction_weight=0.1)


def _small_fit_args(tiny_windows, root) -> list[str]:
    return ['-c', 'configs/quickstart.yaml', '--data.config', tiny_windows.hparams.config,
            '--data.generation_workers', '1', '--data.batch_size', '2',
            *[f'--data.{k}={v}' for k, v in SMALL_FEATURES.items()],
            *[f'--model.estimator.init_args.{k}={v}' for k, v in SMALL_ESTIMATOR.items()],
            '--trainer.max_steps', '4', '--trainer.val_check_interval', '2',
            '--trainer.log_every_n_steps', '1',
            '--trainer.limit_val_batches', '2', '--trainer.enable_progress_bar', 'false',
            '--trainer.enable_model_summary', 'false',
            '--trainer.default_root_dir', str(root),
            '--trainer.logger', json.dumps({
                'class_path': 'lightning.pytorch.loggers.CSVLogger',
                'init_args': {'save_dir': str(root), 'name': 'logs'}})]


@pytest.mark.filterwarnings('ignore:Checkpoint directory .* exists and is not empty')
def test_cli_fits_from_the_quickstart_config_and_resumes(tiny_windows, tmp_path):
    import csv

    from swingar_pyg.cli import main
    from swingar_pyg.training import SwinGarModule

    assert main(['fit', *_small_fit_args(tiny_windows, tmp_path)]) == 0
    last = tmp_path / 'checkpoints' / 'last.ckpt'
    metrics = (tmp_path / 'logs' / 'version_0' / 'metrics.csv').read_text().splitlines()
    rows = list(csv.DictReader(metrics))
    errors = [(float(r['val/estimator_mean_mm']), float(r['val/rigid_mean_mm']))
              for r in rows if r.get('val/estimator_mean_mm')]
    # The untrained estimator is exactly rigid skinning, and two or four Adam steps move it
    # little: within twice rigid skinning's error on the same windows (measured 21.9 and
    # 23.1 mm against 17.8 mm, 1.2-1.3x). It was 0 < e < 1 m, which a diverged model passed.
    assert len(errors) == 2 and all(0 < e < 2 * rigid for e, rigid in errors), errors
    # the checkpoint is self-contained: the estimator comes back from its config
    module = SwinGarModule.load_from_checkpoint(last)
    assert module.estimator.history == SMALL_FEATURES['history']
    # resuming continues from step 4 with the saved optimizer state
    saved = torch.load(last, weights_only=False)
    args = _small_fit_args(tiny_windows, tmp_path)
    args[args.index('--trainer.max_steps') + 1] = '6'
    main(['fit', *args, '--ckpt_path', str(last)])
    resumed = torch.load(last, weights_only=False)
    assert saved['global_step'] == 4 and resumed['global_step'] == 6
    moment = 'exp_avg'
    assert not torch.equal(saved['optimizer_states'][0]['state'][0][moment],
                           resumed['optimizer_states'][0]['state'][0][moment])



def _fit_in_processes(tiny_windows, root: Path, devices: int, steps: int, *extra: str) -> Path:
    """`swingar fit` in a subprocess (DDP starts one more per device), recording
    the windows each process trains on; returns the last checkpoint."""
    args = _small_fit_args(tiny_windows, root)
    args[args.index('--trainer.max_steps') + 1] = str(steps)
    probe = {'class_path': 'tests.ddp_probe.RecordWindows', 'init_args': {'folder': str(root)}}
    command = [sys.executable, '-m', 'swingar_pyg.cli', 'fit', *args,
               '--trainer.accelerator', 'cpu', '--trainer.devices', str(devices),
               '--trainer.strategy', 'ddp' if devices > 1 else 'auto',
               f'--trainer.callbacks+={json.dumps(probe)}', *extra]
    subprocess.run(command, check=True, cwd=Path(__file__).resolve().parents[1], timeout=900,
                   env={**os.environ, 'OMP_NUM_THREADS': '1'})
    return root / 'checkpoints' / 'last.ckpt'


def _windows_by_step(root: Path, rank: int) -> dict[int, list[str]]:
    lines = (root / f'rank{rank}.jsonl').read_text().splitlines()
    return {record['step']: record['windows'] for record in map(json.loads, lines)}


@pytest.mark.filterwarnings('ignore:Checkpoint directory .* exists and is not empty')
def test_ddp_on_two_processes_shards_the_data_checkpoints_and_resumes(tiny_windows, tmp_path):
    from datamodules.resumable_loader import EpochPermutation

    single = _fit_in_processes(tiny_windows, tmp_path / 'single', 1, 4)
    parallel = _fit_in_processes(tiny_windows, tmp_path / 'ddp', 2, 4)
    # Each process trains on its own half: no window twice within the epoch's first steps.
    seen = [_windows_by_step(tmp_path / 'ddp', rank) for rank in (0, 1)]
    assert sorted(seen[0]) == sorted(seen[1]) == [0, 1, 2, 3]
    halves = [{w for windows in by_step.values() for w in windows} for by_step in seen]
    assert len(halves[0]) == len(halves[1]) == 4 * 2 and not halves[0] & halves[1]
    # ... and exactly the shard of the seeded order that its rank owns.
    dataset = tiny_windows.datasets['train']
    names = [f'{dataset.sequences[s].id}:{t}' for s, t in dataset.windows]
    for rank in (0, 1):
        shard = [names[i] for i in EpochPermutation(dataset, seed=0, num_replicas=2, rank=rank)]
        assert [w for step in range(4) for w in seen[rank][step]] == shard[:8]
    # The checkpoint has the single-process run's structure.
    one, two = (torch.load(path, weights_only=False) for path in (single, parallel))
    assert one['global_step'] == two['global_step'] == 4
    assert {k: v.shape for k, v in one['state_dict'].items()} == \
        {k: v.shape for k, v in two['state_dict'].items()}
    assert one['hyper_parameters'] == two['hyper_parameters']
    # Resuming on two processes continues each shard where it stopped.
    resumed = _fit_in_processes(tiny_windows, tmp_path / 'ddp', 2, 6, '--ckpt_path', str(parallel))
    assert torch.load(resumed, weights_only=False)['global_step'] == 6
    for rank in (0, 1):
        shard = [names[i] for i in EpochPermutation(dataset, seed=0, num_replicas=2, rank=rank)]
        after = _windows_by_step(tmp_path / 'ddp', rank)
        assert [w for step in (4, 5) for w in after[step]] == shard[8:12]

def test_checkpoint_round_trip_gives_identical_predictions(tiny_windows, tmp_path):
    from swingar_pyg.training import SwinGarModule

    module = SwinGarModule(SwinGarEstimator(**SMALL_ESTIMATOR))
    trainer = L.Trainer(max_steps=3, limit_val_batches=1, logger=False,
                        enable_checkpointing=False, enable_progress_bar=False,
                        enable_model_summary=False, default_root_dir=tmp_path)
    trainer.fit(module, datamodule=tiny_windows)
    path = tmp_path / 'model.ckpt'
    trainer.save_checkpoint(path)
    loaded = SwinGarModule.load_from_checkpoint(path, estimator=SwinGarEstimator(
        **SMALL_ESTIMATOR))
    batch = next(iter(tiny_windows.test_dataloader()))
    module.eval()
    loaded.eval()
    with torch.no_grad():
        assert torch.equal(module(batch).vertices, loaded(batch).vertices)
        assert not torch.equal(module(batch).vertices, module(batch).skinned)


class _RecordBatches(L.Callback):
    def __init__(self):
        self.seen = []

    def on_train_batch_start(self, trainer, module, batch, batch_index):
        self.seen.append(list(zip(batch.sequence, batch.frame.tolist())))


def _trainer(root, steps, record, *callbacks):
    return L.Trainer(max_steps=steps, limit_val_batches=0, logger=False,
                     enable_progress_bar=False, enable_model_summary=False,
                     default_root_dir=root, callbacks=[record, *callbacks])


class _LastCheckpointStep(L.Callback):
    """Before each training step: the step ``last.ckpt`` holds."""

    def __init__(self, path):
        self.path, self.steps = path, []

    def on_train_batch_start(self, trainer, module, batch, batch_index):
        if self.path.exists():
            saved = torch.load(self.path, weights_only=False)['global_step']
            self.steps.append((trainer.global_step, saved))


def test_last_checkpoint_follows_every_validation_and_the_final_step(tiny_windows, tmp_path):
    from swingar_pyg.training import SwinGarModule
    from swingar_pyg.training.cli import LastStepCheckpoint

    checkpoint = LastStepCheckpoint(tmp_path, 'best', monitor='val/estimator_mean_mm',
                                    save_last=True)
    record = _LastCheckpointStep(tmp_path / 'last.ckpt')
    trainer = L.Trainer(max_steps=5, val_check_interval=2, limit_val_batches=1,
                        num_sanity_val_steps=0, logger=False, enable_progress_bar=False,
                        enable_model_summary=False, default_root_dir=tmp_path,
                        callbacks=[record, checkpoint])
    # lr 0: the validation error never falls again, so only step 2 is a new best
    trainer.fit(SwinGarModule(SwinGarEstimator(**SMALL_ESTIMATOR), lr=0.0),
                datamodule=tiny_windows)
    assert [p.name for p in tmp_path.glob('best*.ckpt')] == ['best.ckpt']
    assert record.steps == [(2, 2), (3, 2), (4, 4)]
    assert torch.load(tmp_path / 'last.ckpt', weights_only=False)['global_step'] == 5


@pytest.mark.filterwarnings('ignore:.*limit_val_batches=0.*')
@pytest.mark.filterwarnings('ignore:Be aware that when using .ckpt_path.')
def test_resuming_mid_epoch_continues_with_the_next_batch(tiny_windows, tmp_path):
    from swingar_pyg.training import SwinGarModule

    whole = _RecordBatches()
    _trainer(tmp_path / 'a', 15, whole).fit(SwinGarModule(SwinGarEstimator(**SMALL_ESTIMATOR)),
                                     datamodule=tiny_windows)
    first, second = _RecordBatches(), _RecordBatches()
    every_ten = L.pytorch.callbacks.ModelCheckpoint(tmp_path / 'ckpt', 'mid',
                                                    every_n_train_steps=10)
    _trainer(tmp_path / 'b', 10, first, every_ten).fit(
        SwinGarModule(SwinGarEstimator(**SMALL_ESTIMATOR)), datamodule=tiny_windows)
    _trainer(tmp_path / 'c', 15, second).fit(
        SwinGarModule(SwinGarEstimator(**SMALL_ESTIMATOR)), datamodule=tiny_windows,
        ckpt_path=tmp_path / 'ckpt' / 'mid.ckpt')
    assert len(tiny_windows.train_dataloader()) == 12  # so step 13 starts epoch 2
    assert first.seen == whole.seen[:10]
    assert second.seen == whole.seen[10:]
    assert whole.seen[12] != whole.seen[0]  # a new order in the new epoch


@pytest.mark.parametrize('layers,expected', [
    (['configs/quickstart.yaml'], {'alpha': 2.0, 'normalize': True, 'descriptor_size': 256}),
    (['configs/quickstart.yaml', 'configs/ablations/gat.yaml'], {'normalize': False}),
    (['configs/quickstart.yaml', 'configs/ablations/alpha3.yaml'], {'alpha': 3.0}),
    (['configs/quickstart.yaml', 'configs/ablations/no_descriptor.yaml'],
     {'descriptor_size': None}),
    (['configs/quickstart.yaml', 'configs/ablations/z512.yaml'], {'descriptor_size': 512}),
    (['configs/swingar.yaml'], {'channels': 128, 'heads': 4}),
])
def test_configs_parse_and_ablations_change_only_their_knob(layers, expected, capsys):
    import yaml

    from swingar_pyg.training.cli import build_cli

    args = ['fit']
    for layer in layers:
        args += ['-c', layer]
    with pytest.raises(SystemExit):
        build_cli([*args, '--print_config'])
    config = yaml.safe_load(capsys.readouterr().out)
    assert config['model']['class_path'] == 'swingar_pyg.training.SwinGarModule'
    data = config['data']['init_args']
    estimator = config['model']['init_args']['estimator']['init_args']
    # set once, under data:, and linked into the estimator (so not printed there)
    assert 'descriptor_size' not in estimator and 'history' not in estimator
    linked = {**estimator, 'descriptor_size': data['descriptor_size'], 'history': data['history']}
    assert {k: linked[k] for k in expected} == expected
    if len(layers) > 1:
        assert config['trainer']['default_root_dir'].startswith('runs/ablations/')


@pytest.mark.parametrize('ablation,size', [('z128', 128), ('no_descriptor', None)])
def test_the_estimator_takes_descriptor_size_and_history_from_the_data(ablation, size):
    from swingar_pyg.training.cli import build_cli

    cli = build_cli(['-c', 'configs/quickstart.yaml', '-c', f'configs/ablations/{ablation}.yaml',
                     '--data.generate', 'false', '--data.history', '12'], run=False)
    assert cli.model.estimator.descriptor_size == size == cli.datamodule.hparams.descriptor_size
    assert cli.model.estimator.history == 12


def test_the_body_sdf_config_parses_with_its_own_module(capsys):
    import yaml

    from swingar_pyg.training.cli import build_cli

    with pytest.raises(SystemExit):
        build_cli(['fit', '-c', 'configs/body_sdf.yaml', '--print_config'])
    config = yaml.safe_load(capsys.readouterr().out)
    assert config['model']['class_path'] == 'swingar_pyg.training.BodySDFModule'
    assert config['data']['class_path'] == 'datamodules.BodySDFDataModule'
    assert config['checkpoint']['monitor'] == 'val/near_mean_mm'


def test_checkpoints_follow_the_run_folder():
    from swingar_pyg.training.cli import build_cli

    cli = build_cli(['-c', 'configs/quickstart.yaml', '-c', 'configs/ablations/alpha1.yaml'],
                    run=False)
    assert cli.trainer.checkpoint_callback.dirpath.endswith('runs/ablations/alpha1/checkpoints')
    assert cli.model.estimator.detail.input_maps.alpha == 1.0


@pytest.mark.slow
def test_compiled_estimator_gives_the_same_predictions(tiny_windows):
    from swingar_pyg.training import SwinGarModule

    estimator = SwinGarEstimator(**SMALL_ESTIMATOR)
    plain, compiled = SwinGarModule(estimator), SwinGarModule(estimator, compile=True)
    batch = next(iter(tiny_windows.test_dataloader()))
    with torch.no_grad():
        assert torch.allclose(plain(batch).vertices, compiled(batch).vertices, atol=1e-5)


def test_datamodule_warns_about_sequences_from_an_older_simulator(tiny_windows, tmp_path):
    import h5py

    from datamodules import SwinGarDataModule
    from swingar_pyg.sim import SIMULATOR_REVISION

    for split in ('train', 'val', 'test'):
        shutil.copyfile(tiny_windows.split_path(split), tmp_path / f'{split}.h5')
    module = SwinGarDataModule(config=tiny_windows.hparams.config, root=str(tmp_path),
                               **SMALL_FEATURES)
    module.prepare_data()  # current revision everywhere: silent (warnings are errors here)
    with h5py.File(tmp_path / 'val.h5', 'a') as file:
        assert {int(g.attrs['simulator_revision'])
                for g in file['sequences'].values()} == {SIMULATOR_REVISION}
        del next(iter(file['sequences'].values())).attrs['simulator_revision']
    with pytest.warns(UserWarning, match=r'simulator revision\(s\) \[0\]'):
        module.prepare_data()


def test_error_statistics_match_torch_and_take_a_large_test_split():
    from swingar_pyg.training.vertex_errors import error_stats

    errors = torch.rand(1001, dtype=torch.float64) * 50
    stats = error_stats(errors)
    assert stats['p95_mm'] == pytest.approx(float(torch.quantile(errors, 0.95)), rel=1e-12)
    assert stats['rmse_mm'] == pytest.approx(float(errors.square().mean().sqrt()))
    large = torch.arange(2**24 + 3, dtype=torch.float32)  # torch.quantile refuses this many
    assert error_stats(large)['p95_mm'] == pytest.approx(0.95 * (2**24 + 2), rel=1e-9)
