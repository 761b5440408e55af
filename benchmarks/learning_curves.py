"""Learning curves of training runs side by side: the validation error of the estimator
and of rigid skinning per garment family at every validation step, read from each run's
CSV log (``<run>/logs/version_*/metrics.csv``).

    python benchmarks/learning_curves.py runs/base runs/base-c64 --name base_training
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

from common import write_results


def validation_rows(run: Path) -> list[dict]:
    """Every validation step of a run, over all its log versions (a resumed run
    logs to a new one; a step logged twice keeps its latest figures)."""
    logs = sorted(run.glob("logs/version_*/metrics.csv"),
                  key=lambda path: int(path.parent.name.split("_")[1]))
    if not logs:
        raise ValueError(f"{run} has no logs/version_*/metrics.csv")
    by_step = {}
    for log in logs:
        for row in csv.DictReader(log.open()):
            if row.get("val/estimator_mean_mm"):
                by_step[int(row["step"]) + 1] = {
                    k: float(v) for k, v in row.items() if k.startswith("val/") and v}
    return [{"step": step, **figures} for step, figures in sorted(by_step.items())]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--name", default="learning_curves")
    args = parser.parse_args()
    curves = {str(run): validation_rows(run) for run in args.runs}

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    families = sorted({k.split("/")[1] for rows in curves.values() for row in rows
                       for k in row if k.count("/") == 2})
    panels = ["all", *families]
    figure, axes = plt.subplots(1, len(panels), figsize=(4.5 * len(panels), 3.6), squeeze=False)
    for axis, panel in zip(axes[0], panels):
        prefix = "val/" if panel == "all" else f"val/{panel}/"
        for run, rows in curves.items():
            rows = [r for r in rows if f"{prefix}estimator_mean_mm" in r]
            axis.plot([r["step"] for r in rows], [r[f"{prefix}estimator_mean_mm"] for r in rows],
                      marker="o", label=run)
        rigid = [r[f"{prefix}rigid_mean_mm"] for rows in curves.values() for r in rows
                 if f"{prefix}rigid_mean_mm" in r]
        if rigid:  # the same validation split in every run
            axis.axhline(rigid[0], color="grey", linestyle="--", label="rigid skinning")
        axis.set(title=f"validation, {panel}", xlabel="step", ylabel="mean vertex error (mm)")
        axis.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    figure.tight_layout()
    path = write_results(args.name, {"command": "python benchmarks/learning_curves.py " +
                                     " ".join(map(str, args.runs)), "curves": curves}, figure)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
