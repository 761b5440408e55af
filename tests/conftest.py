import pytest
import torch

from tests.extras import require

# Two threads on a busy 2-core machine can be 10x slower than one.
torch.set_num_threads(1)


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(12345)


@pytest.fixture(scope='session')
def tiny_windows(tmp_path_factory):
    """A prepared SwinGarDataModule over a tiny simulated dataset."""
    require('anny')
    require('lightning')
    from datamodules import SwinGarDataModule
    from tests.windows import SMALL_FEATURES, write_tiny_config

    config = write_tiny_config(tmp_path_factory.mktemp('windows'))
    module = SwinGarDataModule(config=str(config), generation_workers=1, batch_size=2,
                               **SMALL_FEATURES)
    module.prepare_data()
    module.setup()
    return module


@pytest.fixture(scope='session')
def tiny_body_sdf(tiny_windows, tmp_path_factory):
    """A checkpoint of `swingar fit -c configs/body_sdf.yaml` on tiny samples (4 steps)."""
    from swingar_pyg.cli import main
    from tests.windows import TINY_BODY_SDF

    root = tmp_path_factory.mktemp('body_sdf')
    config = root / 'tiny_sdf.yaml'
    config.write_text(TINY_BODY_SDF.format(root=root, dataset=tiny_windows.hparams.config))
    assert main(['fit', '-c', 'configs/body_sdf.yaml', '-c', str(config)]) == 0
    return root / 'checkpoints' / 'last.ckpt'


@pytest.fixture(scope='session')
def tiny_checkpoint(tiny_windows, tmp_path_factory):
    """A checkpoint of `swingar fit` (3 steps on the tiny dataset)."""
    from swingar_pyg.cli import main
    from tests.windows import SMALL_ESTIMATOR, SMALL_FEATURES

    root = tmp_path_factory.mktemp('fit')
    main(['fit', '-c', 'configs/quickstart.yaml', '--data.config', tiny_windows.hparams.config,
          '--data.batch_size', '2', *[f'--data.{k}={v}' for k, v in SMALL_FEATURES.items()],
          *[f'--model.estimator.init_args.{k}={v}' for k, v in SMALL_ESTIMATOR.items()],
          '--trainer.max_steps', '3', '--trainer.limit_val_batches', '1',
          '--trainer.log_every_n_steps', '1', '--trainer.enable_progress_bar', 'false',
          '--trainer.enable_model_summary', 'false', '--trainer.default_root_dir', str(root)])
    return root / 'checkpoints' / 'last.ckpt'
