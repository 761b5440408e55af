"""Networks out of ``swingar fit`` checkpoints, in eval mode, for the layers above
training to pass down (inference and collisions take modules, never paths)."""

from __future__ import annotations

from pathlib import Path

import torch

from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.models import BodySDF, SwinGarEstimator
from swingar_pyg.models.pretrained import read_weights, write_weights
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


def load_pretrained(name_or_path: str | Path = "base") -> tuple[SwinGarEstimator, dict]:
    """A shipped estimator (by name) or a weights file (``.pt``), in eval mode, and
    the descriptor settings (``sigma``, ``seed``) it was trained with: the pair
    :func:`load_estimator` returns for a checkpoint."""
    record = read_weights(name_or_path)
    return SwinGarEstimator.from_weights(record), record["data"]


#: Estimator arguments that hold no parameters and may be set on a trained
#: network when it is exported: the clearance gate.
EXPORT_SETTINGS = ("clearance_scale", "contact_clearance", "anchor_scale")


def write_exported_weights(out: str | Path, arguments: dict, settings: dict | None,
                           state_dict: dict, data_settings: dict) -> dict:
    """Writes a trained network (its init ``arguments`` and ``state_dict``) as a
    weights file with its :data:`EXPORT_SETTINGS` replaced by ``settings``, and
    returns the arguments written. Raises ``ValueError`` on any other setting, on a
    contact clearance without a clearance or anchor scale and on a setting the
    estimator refuses."""
    unknown = set(settings or {}) - set(EXPORT_SETTINGS)
    if unknown:
        raise ValueError(f"only {', '.join(EXPORT_SETTINGS)} can be set at export, "
                         f"got {', '.join(sorted(unknown))}")
    arguments = {**arguments, **(settings or {})}
    if (arguments.get("clearance_scale") is None and arguments.get("anchor_scale") is None
            and arguments.get("contact_clearance")):
        raise ValueError("a contact_clearance does nothing without a clearance_scale or an "
                         "anchor_scale")
    exported = SwinGarEstimator(**arguments)  # its ValueError names a bad setting
    exported.load_state_dict(state_dict)
    write_weights(out, arguments, exported.state_dict(), data_settings)
    return arguments


def export_weights(checkpoint: str | Path, out: str | Path,
                   settings: dict | None = None) -> dict:
    """Writes the estimator of a ``swingar fit`` checkpoint as a weights file
    (:mod:`swingar_pyg.models.pretrained`), with its :data:`EXPORT_SETTINGS`
    replaced by ``settings``; returns what the model card needs from the
    checkpoint: the estimator's arguments, the data and training
    hyperparameters, the step and the settings set at export."""
    path = _existing(checkpoint, "no checkpoint")
    saved = torch.load(path, map_location="cpu", weights_only=False)
    network = saved["hyper_parameters"].get("estimator")
    if not isinstance(network, dict) or "init_args" not in network:
        raise ValueError(f"{checkpoint} was not written by `swingar fit` with a config "
                         "(its hyperparameters lack the estimator's init_args)")
    data = saved.get("datamodule_hyper_parameters", {})
    descriptor = {"sigma": float(data.get("sigma", DESCRIPTOR_SIGMA)),
                  "seed": int(data.get("seed", 0))}
    trained, _ = load_estimator(path)
    arguments = write_exported_weights(out, network["init_args"], settings,
                                       trained.state_dict(), descriptor)
    training = {k: v for k, v in saved["hyper_parameters"].items()
                if k != "estimator" and not k.startswith("_")}
    return {"estimator": arguments, "data": descriptor, "training": training,
            "datamodule": {k: v for k, v in data.items() if not k.startswith("_")},
            "step": int(saved["global_step"]), "set_at_export": dict(settings or {})}


def load_body_sdf(checkpoint: str | Path) -> BodySDF:
    """The :class:`~swingar_pyg.models.BodySDF` of a ``swingar fit -c
    configs/body_sdf.yaml`` checkpoint, in eval mode."""
    path = _existing(checkpoint, "no body SDF checkpoint")
    return BodySDFModule.load_from_checkpoint(path, map_location="cpu").body_sdf.eval()
