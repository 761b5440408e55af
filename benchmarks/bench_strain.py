"""The ground-truth simulator's largest edge strain, by motion and solver setting.

    OMP_NUM_THREADS=1 python benchmarks/bench_strain.py            # ~27 minutes, 2 processes
    OMP_NUM_THREADS=1 python benchmarks/bench_strain.py --quick    # 300 vertices, 1 s, 2 motions
    OMP_NUM_THREADS=1 python benchmarks/bench_strain.py --jitter 0.3  # irregular triangulation
    OMP_NUM_THREADS=1 python benchmarks/bench_strain.py --settings 100x1 100x1:400  # error control
    OMP_NUM_THREADS=1 python benchmarks/bench_strain.py --settings 100x1:400 100x1:400/0.9  # stall

Scene: a procedural knee-length skirt (a quad grid, or with ``--jitter`` an irregular
triangulation as in the datasets) on the default anny body doing each motion of ``MOTIONS``
for ``--seconds`` (the kick at the datasets' amplitude, 0.7 = 45 degrees, and at 1.0 = 65).
One run's largest strain is not a stable figure: the swinging cloth is chaotic, and moving the
garment by a micrometre (or running on another CPU, whose float rounding differs) moves the
largest strain of a run by several points while its mean stays put. So each motion and setting
runs ``--repeats`` times, the rest garment moved each time by a different random
``PERTURBATION`` (1 micrometre), and the figures are the median and the range over those runs.

The strain of an edge is :math:`l / L - 1` (current over rest length), split into stretch
(its largest positive value over edges and frames) and compression (its largest negative
value, which XPBD's distance constraints resist as they resist stretch, where a real cloth
would buckle); also the 99.9th percentile of :math:`|l / L - 1|` over edges and frames, the
median wall time per frame, and the largest share of vertices inside the body.

Each run also splits its largest stretch by where it happens (``stretch_by_place``):
within two edges of the pins (the rows carrying the skirt and the waistband's pull), touching
the body (an end within 1 cm of it) and free cloth, since the remedies differ: iterations for
the first, the contact model for the second. ``--length``, ``--flare`` and ``--slit`` choose
another skirt (the quickstart's narrow long one is ``--length 0.75 --flare 0.15``).

A setting ``SxI:M`` runs ``S`` substeps of ``I`` sweeps and re-runs each frame that ends above
the bar at twice the substeps, up to ``M`` (``XPBDSettings.max_substeps``); its runs record
the mean substeps a frame, and the cost is the mean wall time a frame (re-runs included);
``SxI:M/R`` also stops the doubling once a re-run fails to lower the frame's largest strain
below ``R`` times the previous run's (``XPBDSettings.stall_ratio``). Each run records the
share of its frames that end above the bar (``frames_above_bar``).

Writes ``benchmarks/results/bench_strain.json`` and ``bench_strain.png`` (``bench_strain_jitter``
with ``--jitter``, ``bench_strain_l0.75_f0.15`` for another skirt, ``_s0.3`` after it with a
slit, ``_adaptive`` when a setting has ``:M``, then ``_stall`` with ``/R``), with the
simulator revision that made them.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from functools import lru_cache
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
from swingar_pyg.sim.recording import (  # noqa: E402
    garment_edge_strain,
    nearest_body_distance,
    stretch_by_place,
)
from swingar_pyg.world.body import AnnyBody  # noqa: E402
from swingar_pyg.world.motion import procedural_motion  # noqa: E402
from swingar_pyg.world.sequence import simulate_sequence  # noqa: E402
from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt  # noqa: E402

MOTIONS = [("sway", 1.0), ("twist", 1.0), ("spin_stop", 1.0), ("walk", 1.0), ("jump", 1.0),
           ("kick", 0.7), ("kick", 1.0)]
SETTINGS = [(50, 2, None, None), (100, 1, None, None), (100, 2, None, None),
            (200, 1, None, None), (50, 4, None, None)]
PERTURBATION = 1e-6  # metres
PLACES = ("near_pins", "touching", "free")  # the keys of stretch_by_place


@lru_cache(maxsize=1)
def _body() -> AnnyBody:
    torch.set_num_threads(1)
    return AnnyBody()


def run(vertices: int, jitter: float, length: float, flare: float, slit: float, motion: str,
        amplitude: float, seconds: float, substeps: int, iterations: int,
        max_substeps: int | None, stall_ratio: float | None, repeat: int) -> dict:
    """One simulated sequence and its strain figures."""
    body = _body()
    shape = body.default_shape()
    spec = SkirtSpec(length=length, flare=flare, vertices=vertices, jitter=jitter, slit=slit)
    garment = perturbed(fit_procedural_skirt(spec, body, shape), PERTURBATION, seed=repeat)
    sequence = procedural_motion(motion, body.joint_names, seconds=seconds, amplitude=amplitude)
    settings = XPBDSettings(fps=sequence.fps, substeps=substeps, iterations=iterations,
                            max_substeps=max_substeps, stall_ratio=stall_ratio)
    simulated = simulate_sequence(body, shape, garment, sequence, settings)
    result = simulated.result
    edges, strain = garment_edge_strain(garment.mesh, result.positions)
    places = stretch_by_place(strain, edges, garment.pinned, garment.mesh.num_vertices,
                              nearest_body_distance(result.positions, simulated.body_vertices))
    return {"motion": motion, "amplitude": amplitude, "substeps": substeps,
            "iterations": iterations, "max_substeps": max_substeps,
            "stall_ratio": stall_ratio, "repeat": repeat,
            "ms_per_frame": 1e3 * float(np.median(result.seconds_per_frame)),
            "mean_ms_per_frame": 1e3 * float(np.mean(result.seconds_per_frame)),
            "mean_substeps": float(np.mean(result.substeps_per_frame)),
            "max_stretch": float(strain.max()), "max_compression": float(-strain.min()),
            **{f"max_stretch_{place}": value for place, value in places.items()},
            "p999_strain": float(strain.abs().flatten().quantile(0.999)),
            "mean_strain": float(strain.abs().mean()),
            "frames_above_bar": float(np.mean(result.max_stretch > STRETCH_BAR)),
            "max_penetration": float(np.nanmax(result.penetration))}


def summarise(runs: list[dict]) -> list[dict]:
    """Median and range over the repeats of each motion and setting."""
    groups: dict[tuple, list[dict]] = {}
    for r in runs:
        groups.setdefault((r["motion"], r["amplitude"], *_setting(r)), []).append(r)
    rows = []
    for (motion, amplitude, substeps, iterations, max_substeps, stall_ratio), group in (
            groups.items()):
        row = {"motion": motion, "amplitude": amplitude, "substeps": substeps,
               "iterations": iterations, "max_substeps": max_substeps,
               "stall_ratio": stall_ratio, "repeats": len(group)}
        for key in ("ms_per_frame", "mean_ms_per_frame", "mean_substeps", "max_stretch",
                    "max_compression", "p999_strain", "mean_strain", "frames_above_bar",
                    "max_penetration",
                    *(f"max_stretch_{place}" for place in PLACES)):
            values = np.array([r[key] for r in group])
            row[key] = {"median": float(np.median(values)), "min": float(values.min()),
                        "max": float(values.max())}
        rows.append(row)
    return rows


def label(row: dict) -> str:
    return row["motion"] + (f" a{row['amplitude']:g}" if row["amplitude"] != 1.0 else "")


def _setting(row: dict) -> Setting:
    return row["substeps"], row["iterations"], row["max_substeps"], row.get("stall_ratio")


def plot(rows: list[dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    motions = list(dict.fromkeys(label(r) for r in rows))
    settings = list(dict.fromkeys(_setting(r) for r in rows))
    figure, (stretch_axis, cost_axis) = plt.subplots(
        1, 2, figsize=(13, 4.2), gridspec_kw={"width_ratios": [3, 1]})
    width = 0.8 / len(settings)
    for k, setting in enumerate(settings):
        chosen = {label(r): r for r in rows if _setting(r) == setting}
        position = np.arange(len(motions)) + (k - (len(settings) - 1) / 2) * width
        stretch = [chosen[m]["max_stretch"] for m in motions]
        median = 100 * np.array([s["median"] for s in stretch])
        spread = 100 * np.array([[s["median"] - s["min"] for s in stretch],
                                 [s["max"] - s["median"] for s in stretch]])
        stretch_axis.bar(position, median, width, yerr=spread, capsize=2,
                         label=setting_label(setting))
        cost_axis.bar(k, np.median([chosen[m]["mean_ms_per_frame"]["median"]
                                    for m in motions]), 0.6)
    stretch_axis.axhline(100 * STRETCH_BAR, color="k", linestyle="--", linewidth=0.8,
                         label=f"{100 * STRETCH_BAR:g} % bar")
    repeats = rows[0]["repeats"]
    stretch_axis.set(xticks=np.arange(len(motions)), xticklabels=motions,
                     ylabel="largest stretch (%)",
                     title=f"largest edge stretch: median and range of {repeats} runs, "
                           f"garment moved {PERTURBATION * 1e6:g} µm")
    stretch_axis.legend(fontsize=7)
    cost_axis.set(xticks=range(len(settings)),
                  xticklabels=[setting_label(s) for s in settings],
                  ylabel="mean ms per frame (median over motions)", title="cost")
    cost_axis.tick_params(axis="x", labelrotation=20, labelsize=8)
    for axis in (stretch_axis, cost_axis):
        axis.grid(alpha=0.3, axis="y")
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vertices", type=int, default=1500)
    parser.add_argument("--jitter", type=float, default=0.0,
                        help="irregular triangulation: SkirtSpec jitter (0 = quad grid)")
    parser.add_argument("--length", type=float, default=SkirtSpec.length,
                        help="skirt length, m")
    parser.add_argument("--flare", type=float, default=SkirtSpec.flare,
                        help="how far the hem stands out: sine of the cone's half-angle")
    parser.add_argument("--slit", type=float, default=0.0,
                        help="a vent at the back this high up from the hem, m (SkirtSpec.slit)")
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=2, help="worker processes, one thread each")
    parser.add_argument("--settings", nargs="+", metavar="SxI[:M[/R]]",
                        help="substeps x iterations to run, :M to double the substeps up to "
                        "M on frames that end above the bar, /R to stop doubling where a "
                        "re-run gains less than a factor R (default: " +
                        " ".join(setting_label(s) for s in SETTINGS) + ")")
    parser.add_argument("--motions", nargs="+", metavar="NAME[@AMPLITUDE]",
                        help="motions to run (default: " +
                        " ".join(f"{m}@{a:g}" for m, a in MOTIONS) + ")")
    parser.add_argument("--quick", action="store_true",
                        help="300 vertices, 1 s, walk and kick, 2 repeats")
    args = parser.parse_args()
    motions = MOTIONS if not args.motions else [
        (name, float(amplitude or 1.0)) for name, _, amplitude in
        (m.partition("@") for m in args.motions)]
    settings = SETTINGS if not args.settings else [parse_setting(s) for s in args.settings]
    if args.quick:
        args.vertices, args.seconds, args.repeats = 300, 1.0, 2
        motions = [("walk", 1.0), ("kick", 1.0)]
    if args.vertices < 64 or args.seconds <= 0 or args.repeats < 1 or args.jobs < 1:
        raise ValueError("--vertices must be >= 64, --seconds > 0, --repeats and --jobs >= 1")

    tasks = [(args.vertices, args.jitter, args.length, args.flare, args.slit, motion, amplitude,
              args.seconds, *setting, repeat)
             for motion, amplitude in motions for setting in settings
             for repeat in range(args.repeats)]
    with ProcessPoolExecutor(args.jobs) as pool:
        runs = []
        for r in pool.map(run, *zip(*tasks)):
            runs.append(r)
            print(f"{r['motion']:>9} a{r['amplitude']:g} {setting_label(_setting(r)):>9} "
                  f"#{r['repeat']}: {r['mean_ms_per_frame']:6.1f} ms/frame "
                  f"({r['mean_substeps']:.0f} substeps), frames above the bar "
                  f"{100 * r['frames_above_bar']:4.1f} %, stretch "
                  f"{100 * r['max_stretch']:5.1f} %, compression {100 * r['max_compression']:5.1f}"
                  f" %, p99.9 {100 * r['p999_strain']:4.2f} %, inside "
                  f"{100 * r['max_penetration']:.2f} %; stretch near pins / touching / free "
                  + " / ".join(f"{100 * r['max_stretch_' + p]:.1f}" for p in PLACES) + " %",
                  flush=True)
    rows = summarise(runs)
    payload = {"machine": machine_info(), "simulator_revision": SIMULATOR_REVISION,
               "vertices": args.vertices, "jitter": args.jitter, "length": args.length,
               "flare": args.flare, "slit": args.slit, "seconds": args.seconds,
               "perturbation_m": PERTURBATION, "jobs": args.jobs, "rows": rows, "runs": runs}
    shape = ("" if (args.length, args.flare) == (SkirtSpec.length, SkirtSpec.flare)
             else f"_l{args.length:g}_f{args.flare:g}")
    shape += f"_s{args.slit:g}" if args.slit else ""
    stem = ("bench_strain" + ("_jitter" if args.jitter else "") + shape
            + ("_adaptive" if any(s[2] for s in settings) else "")
            + ("_stall" if any(s[3] for s in settings) else "")
            + ("_quick" if args.quick else ""))
    path = write_results(stem, payload, plot(rows))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
