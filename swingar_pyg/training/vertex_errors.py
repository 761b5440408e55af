"""Per-vertex error statistics in millimetres, over an epoch and per group."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import torch
from torch import Tensor


def garment_family(name: str) -> str:
    """``"skirt-l0.45-...@shape0"`` → ``"skirt"``."""
    return name.split("-", 1)[0]


def error_stats(errors_mm: Tensor) -> dict[str, float]:
    """Mean, RMSE and 95th percentile of per-vertex errors (mm). The percentile
    is numpy's (linear interpolation, as :func:`torch.quantile`, which refuses
    more than 2**24 values: a test split of 100 sequences has more)."""
    errors = errors_mm.detach().double().cpu()
    return {"mean_mm": float(errors.mean()), "rmse_mm": float(errors.square().mean().sqrt()),
            "p95_mm": float(np.quantile(errors.numpy(), 0.95))}


class VertexErrors:
    """Collects per-vertex errors of several methods, labelled by garment and
    motion, and summarises them.

    >>> errors = VertexErrors()                                  # doctest: +SKIP
    >>> errors.add("estimator", distances_mm, batch, garments, motions)
    >>> errors.summary()["estimator"]["all"]["mean_mm"]
    """

    def __init__(self):
        self._errors: dict[str, list[Tensor]] = defaultdict(list)
        self._labels: dict[str, list[tuple[str, str]]] = defaultdict(list)
        self._counts: dict[str, list[int]] = defaultdict(list)

    def add(self, method: str, errors_mm: Tensor, batch: Tensor, garments: list[str],
            motions: list[str]) -> None:
        counts = torch.bincount(batch, minlength=len(garments)).tolist()
        self._errors[method].append(errors_mm.detach().float().cpu())
        self._labels[method].extend(zip(garments, motions))
        self._counts[method].extend(counts)

    def __bool__(self) -> bool:
        return bool(self._errors)

    def summary(self) -> dict[str, dict[str, dict[str, float]]]:
        """``{method: {"all" | "garment:<name>" | "family:<family>" | "motion:<name>":
        stats}}``, the family being :func:`garment_family` of the garment's name."""
        out = {}
        for method, pieces in self._errors.items():
            errors = torch.cat(pieces)
            pieces_per_window = torch.split(errors, self._counts[method])
            groups: dict[str, list[Tensor]] = defaultdict(list)
            for (garment, motion), part in zip(self._labels[method], pieces_per_window):
                groups[f"garment:{garment}"].append(part)
                groups[f"family:{garment_family(garment)}"].append(part)
                groups[f"motion:{motion}"].append(part)
            out[method] = {"all": error_stats(errors)}
            out[method].update({k: error_stats(torch.cat(v)) for k, v in sorted(groups.items())})
        return out
