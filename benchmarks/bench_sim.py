"""The ground-truth simulator's own error against run time, per solver path.

    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py            # ~30 minutes on one core
    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py --quick    # one small skirt

Scene: a procedural knee-length skirt on the default anny body doing ``--motion`` (walk by
default) for ``--seconds``. For each garment resolution, a fine reference (``--reference``,
400 substeps x 2 sweeps on the torch path: the smallest time step the quickstart data take,
where a frame is re-run, swept twice) and the coarser ``--settings`` run on the same scene;
the error of a setting is the distance of its vertices from the reference's (mean over
vertices and frames, and the 95th percentile, mm), its cost the mean wall time per frame (the
re-runs of an error-controlled setting ``SxI:M`` included). Also recorded: the mean substeps a
frame, the largest edge strain, the share of frames above the 6 % stretch bar and of vertices
inside the body. This is the curve the estimator is later placed on (``swingar report`` draws
the same curve on the test data).

Every setting runs on each of ``--solvers``, side by side in one run: ``torch`` (the tensor
path, the reference implementation), ``warp`` (the same steps in one compiled kernel) and
``warp/bN`` (the kernel with bending solved on one substep in N, ``bend_every``). Each run
records its throughput, simulated vertex-frames per second of one core. The summary gives,
per garment, each other path's speed-up over the torch path at the same setting and **at
equal error**: the torch path's time interpolated (log-log, between its settings) at the
other run's error, over that run's time.

The reference itself is run a second time on the same scene with the rest garment moved by
``PERTURBATION`` (1 micrometre, random per vertex): how far that run drifts from the first is
the floor below which no setting can be called closer to the reference, because the swinging
cloth is chaotic (a dotted line in the plot).

Writes ``benchmarks/results/bench_sim.json`` and ``bench_sim.png`` with the simulator
revision that made them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import (  # noqa: E402
    Setting,
    machine_info,
    parse_setting,
    perturbed,
    setting_label,
    write_results,
)

from swingar_pyg.sim import SIMULATOR_REVISION, STRETCH_BAR, XPBDSettings  # noqa: E402
from swingar_pyg.world.body import AnnyBody  # noqa: E402
from swingar_pyg.world.motion import procedural_motion  # noqa: E402
from swingar_pyg.world.sequence import simulate_sequence  # noqa: E402
from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt  # noqa: E402

REFERENCE: Setting = (400, 2, None, None)
# one sweep at growing substeps, the library default (50x2), and the datasets' settings:
# the quickstart's 100x1 doubled up to 400 on frames above the bar, the full set's 200x1
SETTINGS: list[Setting] = [(10, 1, None, None), (20, 1, None, None), (50, 1, None, None),
                           (50, 2, None, None), (100, 1, None, None), (100, 1, 400, None),
                           (200, 1, None, None)]
PERTURBATION = 1e-6  # metres; float32 positions near 1 m resolve ~1e-7
MOVED = f"{PERTURBATION * 1e6:g} µm"


def parse_solver(text: str) -> tuple[str, int]:
    """``torch``, ``warp`` or ``warp/bN`` as (backend, bend_every)."""
    backend, _, every = text.partition("/b")
    if backend not in ("torch", "warp") or (every and not every.isdigit()):
        raise ValueError(f"--solvers takes torch, warp or warp/bN, got {text!r}")
    return backend, int(every) if every else 1


def _equal_error_ms(torch_runs: list[dict], error: float) -> float | None:
    """The torch path's time a frame at ``error``, log-log between its two settings
    around it (``None`` outside the range its settings span)."""
    points = sorted((r["mean_error_mm"], r["ms_per_frame"]) for r in torch_runs)
    for (e0, t0), (e1, t1) in zip(points, points[1:]):
        if e0 <= error <= e1 and e0 < e1:
            share = np.log(error / e0) / np.log(e1 / e0)
            return float(np.exp(np.log(t0) + share * np.log(t1 / t0)))
    return None


def speedups(rows: list[dict]) -> list[dict]:
    """Per garment, each run off the torch path: its speed-up over the torch path at the
    same setting and at equal error, with both errors against the reference."""
    table = []
    for row in rows:
        runs = [r for r in row["runs"] if not r["reference"] and not r["perturbed"]]
        torch_runs = [r for r in runs if r["solver"] == "torch"]
        by_setting = {r["setting"]: r for r in torch_runs}
        for run in runs:
            if run["solver"] == "torch":
                continue
            same = by_setting.get(run["setting"])
            equal = _equal_error_ms(torch_runs, run["mean_error_mm"])
            table.append({
                "vertices": row["vertices"], "setting": run["setting"], "solver": run["solver"],
                "error_mm": run["mean_error_mm"], "ms_per_frame": run["ms_per_frame"],
                "torch_error_mm": same["mean_error_mm"] if same else None,
                "speedup_same_setting": same["ms_per_frame"] / run["ms_per_frame"]
                if same else None,
                "speedup_equal_error": equal / run["ms_per_frame"] if equal else None,
                "vertex_frames_per_second": run["vertex_frames_per_second"]})
    return table


def plot(rows: list[dict], reference: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    figure, (error_axis, strain_axis, speed_axis) = plt.subplots(1, 3, figsize=(16, 4.5))
    styles = ["o-", "s--", "^:", "v-."]
    solvers = list(dict.fromkeys(r["solver"] for row in rows for r in row["runs"]))
    colours = {row["vertices"]: f"C{k}" for k, row in enumerate(rows)}
    for row in rows:
        colour = colours[row["vertices"]]
        for solver, style in zip(solvers, styles):
            runs = sorted((r for r in row["runs"] if r["solver"] == solver
                           and not r["reference"] and not r["perturbed"]),
                          key=lambda r: r["ms_per_frame"])
            if not runs:
                continue
            times = [r["ms_per_frame"] for r in runs]
            error_axis.plot(times, [r["mean_error_mm"] for r in runs], style, color=colour,
                            label=f"{row['vertices']} vertices, {solver}")
            for r, t in zip(runs, times):
                error_axis.annotate(r["setting"], (t, r["mean_error_mm"]),
                                    fontsize=6, xytext=(3, 3), textcoords="offset points")
            strain_axis.plot(times, [100 * r["max_strain"] for r in runs], style,
                             color=colour, label=f"{row['vertices']} vertices, {solver}")
        floor = next(r for r in row["runs"] if r["perturbed"])["mean_error_mm"]
        error_axis.axhline(floor, color=colour, linestyle=":", linewidth=0.8,
                           label=f"{row['vertices']}: reference moved {MOVED}")
    table = speedups(rows)
    for solver, style in zip(solvers[1:], styles[1:]):
        for count in sorted({r["vertices"] for r in table}):
            points = sorted((r["error_mm"], r["speedup_equal_error"]) for r in table
                            if r["vertices"] == count and r["solver"] == solver
                            and r["speedup_equal_error"])
            if points:
                speed_axis.plot(*zip(*points), style, color=colours[count],
                                label=f"{count} vertices, {solver}")
    speed_axis.set(xscale="log", xlabel="mean vertex error vs reference (mm)",
                   ylabel="speed-up over the torch path (x)",
                   title="speed-up at equal error")
    speed_axis.grid(alpha=0.3)
    speed_axis.legend(fontsize=7)
    strain_axis.axhline(100 * STRETCH_BAR, color="grey", linestyle=":", linewidth=0.8,
                        label="stretch bar")
    error_axis.set(xscale="log", yscale="log", xlabel="ms per frame (one core)",
                   ylabel="mean vertex error vs reference (mm)",
                   title=f"simulator error vs run time (reference {reference}, torch)")
    strain_axis.set(xscale="log", xlabel="ms per frame", ylabel="largest edge strain (%)",
                    title="largest edge strain")
    error_axis.yaxis.set_major_formatter(ScalarFormatter())
    error_axis.yaxis.set_minor_formatter(ScalarFormatter())
    for axis in (error_axis, strain_axis):
        axis.xaxis.set_minor_formatter(NullFormatter())
        axis.grid(alpha=0.3, which="both")
        axis.legend(fontsize=6)
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vertices", type=int, nargs="+", default=[500, 1500, 4000])
    parser.add_argument("--motion", default="walk")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--settings", nargs="+", metavar="SxI[:M[/R]]",
                        help="settings to place on the curve (default: " +
                        " ".join(setting_label(s) for s in SETTINGS) + ")")
    parser.add_argument("--solvers", nargs="+", default=["torch", "warp", "warp/b10"],
                        help="torch, warp or warp/bN (bending on one substep in N) to run every "
                             "setting on (default: %(default)s)")
    parser.add_argument("--reference", metavar="SxI", default=setting_label(REFERENCE),
                        help="the fine setting errors are measured from (default: %(default)s)")
    parser.add_argument("--quick", action="store_true", help="300 vertices, 0.5 s")
    parser.add_argument("--replot", action="store_true",
                        help="redraw the PNG from the last results/bench_sim.json")
    args = parser.parse_args()
    if args.replot:
        import json

        from common import RESULTS

        payload = json.loads((RESULTS / "bench_sim.json").read_text())
        write_results("bench_sim", payload, plot(payload["rows"], payload["reference"]))
        return
    settings = SETTINGS if not args.settings else [parse_setting(s) for s in args.settings]
    reference = parse_setting(args.reference)
    if args.quick:
        args.vertices, args.seconds = [300], 0.5
    if min(args.vertices) < 64 or args.seconds <= 0:
        raise ValueError("--vertices must be >= 64 and --seconds > 0")
    torch.set_num_threads(1)

    body = AnnyBody()
    shape = body.default_shape()
    motion = procedural_motion(args.motion, body.joint_names, seconds=args.seconds)
    rows = []
    for count in args.vertices:
        garment = fit_procedural_skirt(SkirtSpec(vertices=count), body, shape)
        moved = perturbed(garment, PERTURBATION)
        runs, reference_positions = [], None
        schedule = ([(reference, garment, "torch"), (reference, moved, "torch")]
                    + [(setting, garment, solver) for setting in settings
                       for solver in args.solvers])
        for setting, scene, solver in schedule:
            substeps, iterations, max_substeps, stall_ratio = setting
            backend, bend_every = parse_solver(solver)
            solver_settings = XPBDSettings(
                fps=motion.fps, substeps=substeps, iterations=iterations,
                max_substeps=max_substeps, stall_ratio=stall_ratio, backend=backend,
                bend_every=bend_every)
            result = simulate_sequence(body, shape, scene, motion, solver_settings).result
            if reference_positions is None:
                reference_positions = result.positions
            error = (result.positions - reference_positions).norm(dim=-1)
            ms_per_frame = 1e3 * float(np.mean(result.seconds_per_frame))
            runs.append({"setting": setting_label(setting), "solver": solver,
                         "substeps": substeps,
                         "iterations": iterations, "max_substeps": max_substeps,
                         "stall_ratio": stall_ratio,
                         "reference": scene is garment and setting == reference
                         and solver == "torch",
                         "perturbed": scene is moved,
                         "ms_per_frame": ms_per_frame,
                         "vertex_frames_per_second": 1e3 * garment.mesh.num_vertices
                         / ms_per_frame,
                         "mean_substeps": float(np.mean(result.substeps_per_frame)),
                         "mean_error_mm": 1e3 * float(error.mean()),
                         "p95_error_mm": 1e3 * float(error.quantile(0.95)),
                         "max_strain": float(result.max_stretch.max()),
                         "frames_above_bar": float(np.mean(result.max_stretch > STRETCH_BAR)),
                         "mean_strain": float(result.mean_stretch.mean()),
                         "max_penetration": float(np.nanmax(result.penetration))})
            r = runs[-1]
            print(f"N={garment.mesh.num_vertices:>5} {r['setting']:>9} {solver:>8}"
                  f"{f' moved {MOVED}' if scene is moved else ''}: "
                  f"{r['ms_per_frame']:7.1f} ms/frame ({r['mean_substeps']:.0f} substeps), "
                  f"error {r['mean_error_mm']:6.1f} mm (p95 {r['p95_error_mm']:6.1f}), "
                  f"max strain {100 * r['max_strain']:5.1f} %, inside "
                  f"{100 * r['max_penetration']:.2f} %", flush=True)
        rows.append({"vertices": garment.mesh.num_vertices, "runs": runs})

    payload = {"machine": machine_info(), "simulator_revision": SIMULATOR_REVISION,
               "motion": motion.name, "seconds": args.seconds,
               "reference": setting_label(reference), "perturbation_m": PERTURBATION,
               "rows": rows, "speedups": speedups(rows)}
    for r in payload["speedups"]:
        equal = (f"{r['speedup_equal_error']:.1f}x" if r["speedup_equal_error"]
                 else "outside the torch curve")
        print(f"N={r['vertices']:>5} {r['setting']:>9} {r['solver']:>8}: "
              f"{r['speedup_same_setting']:.1f}x the torch path's speed at this setting "
              f"(error {r['error_mm']:.1f} mm against {r['torch_error_mm']:.1f}), "
              f"{equal} at equal error")
    name = "bench_sim" + ("_quick" if args.quick else "")
    path = write_results(name, payload, plot(rows, payload["reference"]))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
