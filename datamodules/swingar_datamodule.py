"""The Lightning datamodule of SwinGar: simulated sequences → windows → Batches
of disjoint garment graphs."""

from __future__ import annotations

import warnings
from pathlib import Path

import lightning as L
from torch.utils.data import DataLoader
from torch_geometric.loader import DataLoader as GraphLoader

from datamodules.feature_cache import FeatureSettings, ensure_feature_cache
from datamodules.garment_windows import GarmentWindowDataset
from datamodules.resumable_loader import ResumableGraphLoader
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.sim import SIMULATOR_REVISION
from swingar_pyg.world.dataset import DatasetConfig, make_dataset
from swingar_pyg.world.sequence_file import simulator_revisions

SPLITS = ("train", "val", "test")


class SwinGarDataModule(L.LightningDataModule):
    """Serves :class:`~swingar_pyg.models.GarmentWindow` batches from the HDF5
    split files of a dataset config (``configs/data/<name>.yaml``).

    ``prepare_data`` generates the dataset if a split file is missing (through
    :func:`~swingar_pyg.world.dataset.make_dataset`), then computes each file's
    feature cache (descriptor, graph, body poses), stored beside it
    (:mod:`datamodules.feature_cache`), unless one with the same settings was
    computed from the file as it is. ``setup`` reads the splits, which the generator already made
    disjoint by garment and by motion family.

    Args:
        config: dataset config file.
        root: directory of the split files (default: the config's ``output``).
        generate: create a missing dataset; :obj:`False` raises instead.
        generation_workers: processes for the simulator when generating.
        descriptor_size: descriptor length ``z``, or :obj:`None` for none.
        sigma: descriptor kernel width (m).
        history: pose history ``m``.
        body_points: body surface samples for the collision loss.
        batch_size: windows (garments) per batch.
        train_stride, eval_stride: keep every k-th target frame of a sequence.
        num_workers, pin_memory, persistent_workers: as in
            :class:`torch.utils.data.DataLoader`.
        seed: first farthest-point sample of the descriptor, and the seed of
            the training order (resumable mid-epoch from a checkpoint).
    """

    def __init__(self, config: str = "configs/data/quickstart.yaml", root: str | None = None,
                 generate: bool = True, generation_workers: int = 2,
                 descriptor_size: int | None = 256, sigma: float = DESCRIPTOR_SIGMA,
                 history: int = 64,
                 body_points: int = 1024, batch_size: int = 4, train_stride: int = 1,
                 eval_stride: int = 1, num_workers: int = 0, pin_memory: bool = False,
                 persistent_workers: bool = False, seed: int = 0):
        super().__init__()
        self.save_hyperparameters()
        self.settings = FeatureSettings(descriptor_size=descriptor_size, sigma=sigma,
                                        seed=seed, body_points=body_points)
        self.datasets: dict[str, GarmentWindowDataset] = {}

    @property
    def root(self) -> Path:
        if self.hparams.root is not None:
            return Path(self.hparams.root)
        return Path(DatasetConfig.from_yaml(self.hparams.config).output)

    def split_path(self, split: str) -> Path:
        return self.root / f"{split}.h5"

    def prepare_data(self) -> None:
        missing = [s for s in SPLITS if not self.split_path(s).exists()]
        if missing:
            if not self.hparams.generate:
                raise ValueError(f"{', '.join(str(self.split_path(s)) for s in missing)} "
                                 "missing and generate=False; run `swingar make-dataset -c "
                                 f"{self.hparams.config}`")
            make_dataset(DatasetConfig.from_yaml(self.hparams.config), self.root,
                         workers=self.hparams.generation_workers)
        _warn_if_stale(self.split_path(s) for s in SPLITS)
        for split in SPLITS:
            ensure_feature_cache(self.split_path(split), self.settings)

    def setup(self, stage: str | None = None) -> None:
        wanted = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",),
                  "predict": ("test",)}.get(stage, SPLITS)
        for split in wanted:
            if split not in self.datasets:
                stride = self.hparams.train_stride if split == "train" else \
                    self.hparams.eval_stride
                self.datasets[split] = GarmentWindowDataset(
                    self.split_path(split), self.settings, self.hparams.history, stride)

    def _loader_options(self) -> dict:
        workers = self.hparams.num_workers
        return dict(batch_size=self.hparams.batch_size, num_workers=workers,
                    pin_memory=self.hparams.pin_memory,
                    persistent_workers=self.hparams.persistent_workers and workers > 0)

    def _loader(self, split: str) -> DataLoader:
        return GraphLoader(self.datasets[split], shuffle=False, **self._loader_options())

    def train_dataloader(self) -> DataLoader:
        trainer = self.trainer  # None outside a Trainer
        replicas, rank = (trainer.world_size, trainer.global_rank) if trainer else (1, 0)
        return ResumableGraphLoader(self.datasets["train"], seed=self.hparams.seed,
                                    num_replicas=replicas, rank=rank, **self._loader_options())

    def val_dataloader(self) -> DataLoader:
        return self._loader("val")

    def test_dataloader(self) -> DataLoader:
        return self._loader("test")

    def predict_dataloader(self) -> DataLoader:
        return self._loader("test")


def _warn_if_stale(paths) -> None:
    for path in paths:
        older = sorted(r for r in simulator_revisions(path) if r != SIMULATOR_REVISION)
        if older:
            warnings.warn(f"{path} holds sequences from simulator revision(s) {older} (0: made "
                          f"before revisions were recorded), this code simulates revision "
                          f"{SIMULATOR_REVISION}; delete the dataset folder to regenerate it "
                          "with the current simulator", stacklevel=3)

