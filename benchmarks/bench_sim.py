"""The ground-truth simulator's own error against run time, per backend.

    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py            # ~25 minutes on one core
    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py --quick    # one small skirt

Scene: a procedural knee-length skirt on the default anny body doing ``--motion`` (walk by
default) for ``--seconds``. For each garment resolution, a fine reference (``--reference``,
400 substeps x 2 sweeps: the smallest time step the quickstart data take, where a frame is
re-run, swept twice) and the coarser ``--settings`` run on the same scene; the error of a
setting is the distance of its vertices from the reference's (mean over vertices and frames,
and the 95th percentile, mm), its cost the mean wall time per frame (the re-runs of an
error-controlled setting ``SxI:M`` included). Also recorded: the mean substeps a frame, the
largest edge strain, the share of frames above the 6 % stretch bar and of vertices inside the
body. This is the curve the estimator is later placed on (``swingar report`` draws the same
curve on the test data).

Every setting runs on each ``--backends`` (the torch path and the warp kernel, side by side
in one run); the reference is always the torch path. Each run also records its throughput,
simulated vertex-frames per second of one core, and the summary gives the warp kernel's
speed-up over the torch path per garment and setting (the ratio of their times a frame)
next to both errors.

The reference itself is run a second time on the same scene with the rest garment moved by
``PERTURBATION`` (1 micrometre, random per vertex): how far that run drifts from the first is
the floor below which no setting can be called closer to the reference, because the swinging
cloth is chaotic (a dashed line in the plot).

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


def speedups(rows: list[dict]) -> list[dict]:
    """Per garment and setting run on both backends: the warp kernel's speed-up over the
    torch path (their times a frame) and both errors against the reference."""
    table = []
    for row in rows:
        runs = {(r["setting"], r["backend"]): r for r in row["runs"]
                if not r["reference"] and not r["perturbed"]}
        for (setting, backend), warp in runs.items():
            if backend != "warp" or (setting, "torch") not in runs:
                continue
            torch_run = runs[(setting, "torch")]
            table.append({"vertices": row["vertices"], "setting": setting,
                          "speedup": torch_run["ms_per_frame"] / warp["ms_per_frame"],
                          "torch_error_mm": torch_run["mean_error_mm"],
                          "warp_error_mm": warp["mean_error_mm"],
                          "warp_vertex_frames_per_second": warp["vertex_frames_per_second"],
                          "torch_vertex_frames_per_second":
                              torch_run["vertex_frames_per_second"]})
    return table


def plot(rows: list[dict], reference: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    figure, (error_axis, strain_axis, speed_axis) = plt.subplots(1, 3, figsize=(16, 4.5))
    styles = {"torch": "o-", "warp": "s--"}
    for row in rows:
        colour = None
        for backend in sorted({r["backend"] for r in row["runs"]}):
            runs = sorted((r for r in row["runs"] if r["backend"] == backend
                           and not r["reference"] and not r["perturbed"]),
                          key=lambda r: r["ms_per_frame"])
            if not runs:
                continue
            times = [r["ms_per_frame"] for r in runs]
            line, = error_axis.plot(times, [r["mean_error_mm"] for r in runs], styles[backend],
                                    color=colour, label=f"{row['vertices']} vertices, {backend}")
            colour = line.get_color()
            for r, t in zip(runs, times):
                error_axis.annotate(r["setting"], (t, r["mean_error_mm"]),
                                    fontsize=6, xytext=(3, 3), textcoords="offset points")
            strain_axis.plot(times, [100 * r["max_strain"] for r in runs], styles[backend],
                             color=colour, label=f"{row['vertices']} vertices, {backend}")
        floor = next(r for r in row["runs"] if r["perturbed"])["mean_error_mm"]
        error_axis.axhline(floor, color=colour, linestyle=":", linewidth=0.8,
                           label=f"{row['vertices']}: reference moved {MOVED}")
    table = speedups(rows)
    settings = list(dict.fromkeys(r["setting"] for r in table))
    for count in sorted({r["vertices"] for r in table}):
        values = {r["setting"]: r["speedup"] for r in table if r["vertices"] == count}
        speed_axis.plot(range(len(settings)), [values.get(s, float("nan")) for s in settings],
                        "o-", label=f"{count} vertices")
    speed_axis.set_xticks(range(len(settings)), settings, rotation=45, fontsize=7)
    speed_axis.set(ylabel="warp speed-up over torch (x)", title="time a frame, torch / warp")
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
    parser.add_argument("--backends", nargs="+", choices=("torch", "warp"),
                        default=["torch", "warp"], help="XPBD backends to run every setting on")
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
                    + [(setting, garment, backend) for setting in settings
                       for backend in args.backends])
        for setting, scene, backend in schedule:
            substeps, iterations, max_substeps, stall_ratio = setting
            solver = XPBDSettings(fps=motion.fps, substeps=substeps, iterations=iterations,
                                  max_substeps=max_substeps, stall_ratio=stall_ratio,
                                  backend=backend)
            result = simulate_sequence(body, shape, scene, motion, solver).result
            if reference_positions is None:
                reference_positions = result.positions
            error = (result.positions - reference_positions).norm(dim=-1)
            ms_per_frame = 1e3 * float(np.mean(result.seconds_per_frame))
            runs.append({"setting": setting_label(setting), "backend": backend,
                         "substeps": substeps,
                         "iterations": iterations, "max_substeps": max_substeps,
                         "stall_ratio": stall_ratio,
                         "reference": scene is garment and setting == reference,
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
            print(f"N={garment.mesh.num_vertices:>5} {r['setting']:>9} {backend:>5}"
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
        print(f"N={r['vertices']:>5} {r['setting']:>9}: warp {r['speedup']:.1f}x faster, "
              f"error {r['warp_error_mm']:.1f} mm against torch's {r['torch_error_mm']:.1f}")
    name = "bench_sim" + ("_quick" if args.quick else "")
    path = write_results(name, payload, plot(rows, payload["reference"]))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
