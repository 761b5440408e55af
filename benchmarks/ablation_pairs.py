"""Ablation differences paired by seed, from the measurements a report stored.

``swingar report`` stores each model and seed's per-vertex errors in ``<output>/measured/``
(:mod:`swingar_pyg.eval.measurements`). Its own table gives each model's mean over seeds with a
confidence interval; models that share most of their training noise are compared more sharply
by the difference of each model's run of seed ``k`` against the reference model's run of seed
``k``. Per garment family (and ``all``): the mean of those differences over seeds (mm) and the
half-width of its 95 % Student-t interval, ``t_{0.975, n-1} s / sqrt(n)``.

    python benchmarks/ablation_pairs.py runs/report/ablations_base data/base/test.h5 \\
        --reference "FCA alpha 2 (z 256)" --name ablation_pairs_base
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import h5py
import numpy as np
import torch
from common import machine_info, write_results
from scipy.stats import t

from swingar_pyg.training.vertex_errors import garment_family


def family_means(errors: dict[str, torch.Tensor], families: dict[str, str]) -> dict[str, float]:
    """Mean per-vertex error (mm) over every frame and vertex, per family and ``all``."""
    groups: dict[str, list[torch.Tensor]] = {}
    for sequence_id, error in errors.items():
        groups.setdefault(families[sequence_id], []).append(error.reshape(-1).double())
        groups.setdefault("all", []).append(error.reshape(-1).double())
    return {family: float(torch.cat(parts).mean()) for family, parts in groups.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("report", help="the report's output folder (holds measured/)")
    parser.add_argument("test_split", help="the test split file the report measured")
    parser.add_argument("--reference", required=True, help="the model the others are paired with")
    parser.add_argument("--name", default="ablation_pairs")
    args = parser.parse_args()
    with h5py.File(args.test_split, "r") as file:
        families = {k: garment_family(str(v.attrs["garment"]))
                    for k, v in file["sequences"].items()}
    runs: dict[str, dict[int, dict[str, float]]] = {}
    for path in sorted(Path(args.report, "measured").glob("*.pt")):
        stored = torch.load(path, map_location="cpu", weights_only=True)
        identity = json.loads(stored["identity"])
        runs.setdefault(identity["label"], {})[identity["seed"]] = family_means(
            stored["result"]["errors"], families)
    if args.reference not in runs:
        raise ValueError(f"no stored measurement of {args.reference!r}; found {sorted(runs)}")
    reference = runs[args.reference]
    rows = []
    for label, seeds in runs.items():
        if label == args.reference:
            continue
        shared = sorted(set(seeds) & set(reference))
        for family in reference[shared[0]]:
            differences = np.array([seeds[k][family] - reference[k][family] for k in shared])
            half = (float(t.ppf(0.975, len(shared) - 1) * differences.std(ddof=1)
                          / np.sqrt(len(shared))) if len(shared) > 1 else None)
            rows.append({"model": label, "family": family, "seeds": shared,
                         "differences_mm": differences.tolist(),
                         "mean_mm": float(differences.mean()), "ci95_mm": half})
            print(f"{label:>22} {family:>9}: {differences.mean():+6.2f}"
                  + (f" ± {half:.2f} mm" if half is not None else " mm")
                  + f"  (per seed {np.round(differences, 2).tolist()})", flush=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = list(dict.fromkeys(r["model"] for r in rows))
    family_names = ["all"] + sorted({r["family"] for r in rows} - {"all"})
    figure, axis = plt.subplots(figsize=(7, 0.5 + 0.45 * len(models) * len(family_names) ** 0.5))
    for j, family in enumerate(family_names):
        mine = {r["model"]: r for r in rows if r["family"] == family}
        positions = [i + 0.8 * (j - (len(family_names) - 1) / 2) / len(family_names)
                     for i in range(len(models))]
        axis.errorbar([mine[m]["mean_mm"] for m in models], positions,
                      xerr=[mine[m]["ci95_mm"] or 0.0 for m in models], fmt="o", ms=4,
                      capsize=2, color=f"C{j}", label=family)
    axis.axvline(0.0, color="black", lw=0.8)
    axis.set_yticks(range(len(models)), models)
    axis.invert_yaxis()
    axis.set(xlabel=f"mean error minus {args.reference}'s, same seed (mm; 95 % interval)")
    axis.grid(alpha=0.3)
    axis.legend(fontsize=7, loc="best")
    write_results(args.name, {"machine": machine_info(), "report": args.report,
                              "reference": args.reference,
                              "reference_means": {str(k): v for k, v in reference.items()},
                              "rows": rows}, figure)


if __name__ == "__main__":
    main()
