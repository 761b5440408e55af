"""Networks out of ``swingar fit`` checkpoints, in eval mode, for the layers above
training to pass down (inference and collisions take modules, never paths)."""

from __future__ import annotations

from pathlib import Path

import torch

from swingar_pyg.models import BodySDF, SwinGarEstimator
from swingar_pyg.training.body_sdf_module import BodySDFModule
from swingar_pyg.training.module import SwinGarModule


def _existing(checkpoint: str | Path, missing: str) -> Path:
    path = Path(checkpoint)
    if not path.is_file():
        raise ValueError(f"{missing} at {checkpoint}")
    return path


def load_estimator(checkpoint: str | Path) -> tuple[SwinGarEstimator, dict]:
    """The estimator of a ``swingar fit -c configs/<name>.yaml`` checkpoint (in eval
    mode), and the hyperparameters of the datamodule it was trained with (the
    descriptor's ``sigma`` and ``seed``)."""
    path = _existing(checkpoint, "no checkpoint")
    saved = torch.load(path, map_location="cpu", weights_only=False)
    module = SwinGarModule.load_from_checkpoint(path, map_location="cpu")
    return module.estimator.eval(), saved.get("datamodule_hyper_parameters", {})


def load_body_sdf(checkpoint: str | Path) -> BodySDF:
    """The :class:`~swingar_pyg.models.BodySDF` of a ``swingar fit -c
    configs/body_sdf.yaml`` checkpoint, in eval mode."""
    path = _existing(checkpoint, "no body SDF checkpoint")
    return BodySDFModule.load_from_checkpoint(path, map_location="cpu").body_sdf.eval()
