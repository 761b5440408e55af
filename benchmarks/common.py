"""What every benchmark here shares: the machine record, timing, and atomic output."""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import statistics
import time
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.geometry import as_mesh
from swingar_pyg.sim import XPBDSettings
from swingar_pyg.world.garment import Garment

RESULTS = Path(__file__).resolve().parent / "results"


def machine_info() -> dict[str, Any]:
    """Where and with what a benchmark ran, stored with its figures."""
    versions = {}
    for package in ("torch", "torch-geometric", "torch-scatter", "scipy", "numpy", "swingar-pyg"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = None
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "python": platform.python_version(),
        "versions": versions,
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    }


def clearance_gate(estimator: torch.nn.Module) -> dict[str, float | None]:
    """The clearance gate a trained estimator runs with, stored with its figures: shipped
    weights may carry one (``swingar ship-weights --clearance-scale --anchor-scale``)."""
    return {"clearance_scale": estimator.clearance_scale,
            "contact_clearance": estimator.contact_clearance,
            "anchor_scale": estimator.anchor_scale}


def median_seconds(function: Callable[[], Any], repeats: int, warmup: int = 1) -> float:
    """Median wall time of ``function`` over ``repeats`` calls, after ``warmup`` calls."""
    for _ in range(warmup):
        function()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def write_results(name: str, payload: dict[str, Any], figure: Any | None = None) -> Path:
    """Writes ``results/<name>.json`` (and ``<name>.png``) atomically; returns the JSON path."""
    json_path = RESULTS / f"{name}.json"
    with atomic_path(json_path) as tmp:
        tmp.write_text(json.dumps(payload, indent=2, default=float))
    if figure is not None:
        with atomic_path(RESULTS / f"{name}.png") as tmp:
            figure.savefig(tmp, format="png", dpi=120, bbox_inches="tight")
    return json_path


def perturbed(garment: Garment, scale: float, seed: int = 0) -> Garment:
    """``garment`` with every rest vertex moved by ``scale`` times a standard normal: the
    same scene again, to see how far a chaotic run's figures move by themselves."""
    vertices = garment.mesh.vertices + scale * np.random.default_rng(seed).standard_normal(
        garment.mesh.vertices.shape)
    return dataclasses.replace(garment, mesh=as_mesh(vertices, garment.mesh.faces))


Setting = tuple[int, int, int | None, float | None]  # substeps, iterations, cap, stall


def setting_label(setting: Setting) -> str:
    """``SxI``, ``SxI:M`` for substeps doubled up to ``M`` where a frame breaks the bar,
    ``SxI:M/R`` with the doubling stopped where a re-run gains less than ``R``."""
    substeps, iterations, max_substeps, stall_ratio = setting
    return (f"{substeps}x{iterations}" + (f":{max_substeps}" if max_substeps else "")
            + (f"/{stall_ratio:g}" if stall_ratio else ""))


def parse_setting(text: str) -> Setting:
    """The inverse of :func:`setting_label`."""
    bad = ValueError("--settings takes SUBSTEPSxITERATIONS[:MAX_SUBSTEPS[/STALL_RATIO]], "
                     f"got {text!r}")
    fixed, _, adaptive = text.lower().partition(":")
    cap, _, stall = adaptive.partition("/")
    numbers = fixed.split("x")
    if len(numbers) != 2 or not all(n.isdigit() for n in numbers) or (
            adaptive and not cap.isdigit()):
        raise bad
    try:
        stall_ratio = float(stall) if stall else None
    except ValueError:
        raise bad from None
    setting = int(numbers[0]), int(numbers[1]), int(cap) if cap else None, stall_ratio
    XPBDSettings(substeps=setting[0], iterations=setting[1], max_substeps=setting[2],
                 stall_ratio=stall_ratio)  # its ValueError names a bad value
    return setting
