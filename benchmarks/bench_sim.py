"""The ground-truth simulator's own error against run time.

    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py            # ~10 minutes on one core
    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py --quick    # one small skirt

Scene: a procedural knee-length skirt on the default anny body doing ``--motion`` (walk by
default) for ``--seconds``. For each garment resolution, a fine reference (100 substeps x 4
iterations) and coarser settings run on the same scene; the error of a setting is the distance of
its vertices from the reference's (mean over vertices and frames, and the 95th percentile, mm),
its cost the median wall time per frame. Also recorded: largest edge strain and the share of
vertices inside the body. This is the curve the estimator is later placed on.

The reference itself is run a second time on the same scene with the rest garment moved by
``PERTURBATION`` (1 micrometre, random per vertex): how far that run drifts from the first is
the floor below which no setting can be called closer to the reference, because the swinging
cloth is chaotic (a dashed line in the plot).

Writes ``benchmarks/results/bench_sim.json`` and ``bench_sim.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, perturbed, write_results  # noqa: E402

from swingar_pyg.sim import XPBDSettings  # noqa: E402
from swingar_pyg.world.body import AnnyBody  # noqa: E402
from swingar_pyg.world.garment import SkirtSpec, fit_procedural_skirt  # noqa: E402
from swingar_pyg.world.motion import procedural_motion  # noqa: E402
from swingar_pyg.world.sequence import simulate_sequence  # noqa: E402

REFERENCE = (100, 4)
SETTINGS = [(5, 2), (10, 2), (20, 2), (50, 2), (20, 5), (50, 4)]
PERTURBATION = 1e-6  # metres; float32 positions near 1 m resolve ~1e-7
MOVED = f"{PERTURBATION * 1e6:g} µm"


def plot(rows: list[dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from matplotlib.ticker import NullFormatter

    figure, (error_axis, strain_axis) = plt.subplots(1, 2, figsize=(11, 4))
    for row in rows:
        runs = sorted((r for r in row["runs"] if not r["reference"] and not r["perturbed"]),
                      key=lambda r: r["ms_per_frame"])
        times = [r["ms_per_frame"] for r in runs]
        line, = error_axis.plot(times, [r["mean_error_mm"] for r in runs], "o-",
                                label=f"{row['vertices']} vertices")
        floor = next(r for r in row["runs"] if r["perturbed"])["mean_error_mm"]
        error_axis.axhline(floor, color=line.get_color(), linestyle="--", linewidth=0.8,
                           label=f"{row['vertices']}: reference moved {MOVED}")
        for r, t in zip(runs, times):
            error_axis.annotate(f"{r['substeps']}x{r['iterations']}", (t, r["mean_error_mm"]),
                                fontsize=6, xytext=(3, 3), textcoords="offset points")
        strain_axis.plot(times, [100 * r["max_strain"] for r in runs], "o-",
                         label=f"{row['vertices']} vertices")
    error_axis.set(xscale="log", yscale="log", xlabel="ms per frame (one core)",
                   ylabel="mean vertex error vs reference (mm)",
                   title=f"simulator error vs run time (reference {REFERENCE[0]}x{REFERENCE[1]})")
    strain_axis.set(xscale="log", xlabel="ms per frame", ylabel="largest edge strain (%)",
                    title="largest edge strain")
    for axis in (error_axis, strain_axis):
        axis.xaxis.set_minor_formatter(NullFormatter())
        axis.grid(alpha=0.3, which="both")
        axis.legend(fontsize=7)
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vertices", type=int, nargs="+", default=[500, 1500, 4000])
    parser.add_argument("--motion", default="walk")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--quick", action="store_true", help="300 vertices, 0.5 s")
    parser.add_argument("--replot", action="store_true",
                        help="redraw the PNG from the last results/bench_sim.json")
    args = parser.parse_args()
    if args.replot:
        import json

        from common import RESULTS

        payload = json.loads((RESULTS / "bench_sim.json").read_text())
        write_results("bench_sim", payload, plot(payload["rows"]))
        return
    if args.quick:
        args.vertices, args.seconds = [300], 0.5
    torch.set_num_threads(1)

    body = AnnyBody()
    shape = body.default_shape()
    motion = procedural_motion(args.motion, body.joint_names, seconds=args.seconds)
    rows = []
    for count in args.vertices:
        garment = fit_procedural_skirt(SkirtSpec(vertices=count), body, shape)
        moved = perturbed(garment, PERTURBATION)
        runs, reference = [], None
        schedule = [(REFERENCE, garment), (REFERENCE, moved)] + [(s, garment) for s in SETTINGS]
        for (substeps, iterations), scene in schedule:
            settings = XPBDSettings(fps=motion.fps, substeps=substeps, iterations=iterations)
            result = simulate_sequence(body, shape, scene, motion, settings).result
            if reference is None:
                reference = result.positions
            error = (result.positions - reference).norm(dim=-1)
            runs.append({"substeps": substeps, "iterations": iterations,
                         "reference": scene is garment and (substeps, iterations) == REFERENCE,
                         "perturbed": scene is moved,
                         "ms_per_frame": 1e3 * float(np.median(result.seconds_per_frame)),
                         "mean_error_mm": 1e3 * float(error.mean()),
                         "p95_error_mm": 1e3 * float(error.quantile(0.95)),
                         "max_strain": float(result.max_stretch.max()),
                         "mean_strain": float(result.mean_stretch.mean()),
                         "max_penetration": float(np.nanmax(result.penetration))})
            r = runs[-1]
            print(f"N={garment.mesh.num_vertices:>5} {substeps:>3}x{iterations}"
                  f"{f' moved {MOVED}' if scene is moved else ''}: "
                  f"{r['ms_per_frame']:7.1f} ms/frame, error {r['mean_error_mm']:6.1f} mm "
                  f"(p95 {r['p95_error_mm']:6.1f}), max strain {100 * r['max_strain']:5.1f} %, "
                  f"inside {100 * r['max_penetration']:.2f} %", flush=True)
        rows.append({"vertices": garment.mesh.num_vertices, "runs": runs})

    payload = {"machine": machine_info(), "motion": motion.name, "seconds": args.seconds,
               "reference": {"substeps": REFERENCE[0], "iterations": REFERENCE[1]},
               "perturbation_m": PERTURBATION,
               "rows": rows}
    path = write_results("bench_sim" + ("_quick" if args.quick else ""), payload, plot(rows))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
