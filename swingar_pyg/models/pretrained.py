"""Estimator weights as a plain file (``<name>.pt``): what the package ships in
``swingar_pyg/weights/`` and what ``swingar ship-weights`` writes.

A weights file is a dict of tensors and plain values, read with
``torch.load(weights_only=True)`` (no pickled code runs):

- ``format``: :data:`WEIGHTS_FORMAT`;
- ``estimator``: the :class:`~swingar_pyg.models.SwinGarEstimator` init arguments;
- ``state_dict``: its parameters;
- ``data``: the descriptor settings the network was trained with (``sigma``,
  ``seed``), which a new garment's descriptor must be computed with.

The model card (what the network was trained on, how, and what it measured)
is a JSON file beside it, ``<name>.json``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import torch

from swingar_pyg.atomic import atomic_path

WEIGHTS_FORMAT = 1
WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights"
_KEYS = ("format", "estimator", "state_dict", "data")


def weights_sha256(path: str | Path) -> str:
    """The hex sha256 of a weights file, which names its exact contents."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def shipped_weights() -> list[str]:
    """Names of the weights that ship with the package (``"base"``, ...)."""
    return sorted(path.stem for path in WEIGHTS_DIR.glob("*.pt"))


def weights_path(name_or_path: str | Path) -> Path:
    """A shipped model's file by name, or any ``.pt`` path."""
    path = Path(name_or_path)
    if path.suffix == ".pt":
        if not path.is_file():
            raise ValueError(f"no weights file at {path}")
        return path
    shipped = WEIGHTS_DIR / f"{name_or_path}.pt"
    if not shipped.is_file():
        raise ValueError(f"no shipped weights named {name_or_path!r}; the package has "
                         f"{shipped_weights() or 'none'} (or give a .pt path)")
    return shipped


def read_weights(name_or_path: str | Path = "base") -> dict:
    """The contents of a weights file, checked for its format and keys."""
    path = weights_path(name_or_path)
    try:
        record = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # a truncated or foreign file: say which
        raise ValueError(f"{path} is not a readable weights file: {error}") from None
    missing = [key for key in _KEYS if not isinstance(record, dict) or key not in record]
    if missing:
        raise ValueError(f"{path} lacks {missing}; is it a `swingar ship-weights` file?")
    if not (isinstance(record["estimator"], dict) and isinstance(record["state_dict"], dict)
            and isinstance(record["data"], dict)):
        raise ValueError(f"{path}: its estimator, state_dict and data entries must be dicts")
    if record["format"] != WEIGHTS_FORMAT:
        raise ValueError(f"{path} has weights format {record['format']}; this version of "
                         f"swingar_pyg reads format {WEIGHTS_FORMAT}")
    return record


def write_weights(path: str | Path, estimator_arguments: dict, state_dict: dict,
                  data_settings: dict) -> Path:
    """Writes a weights file atomically (tensors moved to the CPU, so the file
    loads on any device)."""
    record = {"format": WEIGHTS_FORMAT, "estimator": dict(estimator_arguments),
              "state_dict": {k: v.detach().cpu().contiguous() for k, v in state_dict.items()},
              "data": dict(data_settings)}
    with atomic_path(path) as tmp:
        torch.save(record, tmp)
    return Path(path)
