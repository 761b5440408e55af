"""The Lightning datamodule of the neural body SDF: frames of points near posed
bodies with exact signed distances (:mod:`datamodules.body_sdf_data`)."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import torch
from torch.utils.data import DataLoader, Dataset

from datamodules.body_sdf_data import (
    FIELDS,
    SDFSampleSettings,
    generate_split,
    read_split,
    split_settings,
)


class BodySDFFrames(Dataset):
    """The frames of a split file; an item is one frame's tensors (``points``
    ``(P, 3)``, ``sdf`` ``(P,)``, ``normal`` ``(P, 3)``, ``joint_transforms``
    ``(J, 4, 4)``, ``joint_positions`` ``(J, 3)``, ``body_shape`` ``(S,)``).

    Args:
        path: a split file.
        points: points per item: a fresh random subset of the frame's each
            time (training), or :obj:`None` for all of them in order.
        seed: of the subsets.
    """

    def __init__(self, path: str | Path, points: int | None = None, seed: int = 0):
        data = read_split(path)
        self.arrays = {name: torch.as_tensor(data[name]) for name in FIELDS}
        self.motions: list[str] = data["motion"]
        self.points = points
        self.generator = torch.Generator().manual_seed(seed)

    def __len__(self) -> int:
        return len(self.arrays["points"])

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        item = {name: value[index] for name, value in self.arrays.items()}
        total = item["points"].shape[0]
        if self.points is not None and self.points < total:
            chosen = torch.randperm(total, generator=self.generator)[:self.points]
            for name in ("points", "sdf", "normal"):
                item[name] = item[name][chosen]
        return item


class BodySDFDataModule(L.LightningDataModule):
    """Serves frames of SDF samples, generating the split files under ``root``
    when they are missing or were made with other settings.

    Args:
        root: folder of ``train.h5`` and ``val.h5``.
        samples: what the splits hold (:class:`SDFSampleSettings` fields as a
            mapping, so a YAML config can set them).
        frames_per_batch: frames (bodies) per batch.
        points_per_frame: points drawn from each training frame per batch.
        workers: processes generating samples.
        num_workers: DataLoader workers.
        seed: of the training order and point subsets.
    """

    def __init__(self, root: str = "data/body_sdf", samples: dict | None = None,
                 frames_per_batch: int = 8, points_per_frame: int = 512, workers: int = 2,
                 num_workers: int = 0, seed: int = 0):
        super().__init__()
        self.save_hyperparameters()
        self.settings = _settings(samples or {})
        self.datasets: dict[str, BodySDFFrames] = {}

    def split_path(self, split: str) -> Path:
        return Path(self.hparams.root) / f"{split}.h5"

    def prepare_data(self) -> None:
        for split in ("train", "val"):
            path = self.split_path(split)
            if split_settings(path) != self.settings.to_json():
                generate_split(self.settings, split, path, workers=self.hparams.workers)

    def setup(self, stage: str | None = None) -> None:
        if "train" not in self.datasets and stage in (None, "fit"):
            self.datasets["train"] = BodySDFFrames(self.split_path("train"),
                                                   self.hparams.points_per_frame,
                                                   self.hparams.seed)
        if "val" not in self.datasets:
            self.datasets["val"] = BodySDFFrames(self.split_path("val"))

    def train_dataloader(self) -> DataLoader:
        generator = torch.Generator().manual_seed(self.hparams.seed)
        return DataLoader(self.datasets["train"], batch_size=self.hparams.frames_per_batch,
                          shuffle=True, generator=generator, drop_last=True,
                          num_workers=self.hparams.num_workers)

    def val_dataloader(self) -> DataLoader:
        return DataLoader(self.datasets["val"], batch_size=self.hparams.frames_per_batch,
                          num_workers=self.hparams.num_workers)

    test_dataloader = val_dataloader


def _settings(samples: dict) -> SDFSampleSettings:
    tuples = {"shapes": lambda v: tuple(tuple(float(x) for x in s) for s in v),
              "motions": tuple, "val_motions": tuple, "offsets": tuple,
              "offset_weights": tuple, "amplitudes": tuple, "garment_datasets": tuple}
    unknown = set(samples) - set(SDFSampleSettings.__dataclass_fields__)
    if unknown:
        raise ValueError(f"unknown SDF sample settings {sorted(unknown)}; use "
                         f"{', '.join(SDFSampleSettings.__dataclass_fields__)}")
    return SDFSampleSettings(**{k: tuples[k](v) if k in tuples else v
                                for k, v in samples.items()})
