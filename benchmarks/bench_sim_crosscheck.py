"""How far two simulators disagree on the same scene: the noise floor of "ground truth".

    OMP_NUM_THREADS=1 python benchmarks/bench_sim_crosscheck.py           # ~25 minutes, one core
    OMP_NUM_THREADS=1 python benchmarks/bench_sim_crosscheck.py --quick   # one short scene
    # the bending model alone: XPBD with dihedral (hinge) bending against VBD, ~25 minutes
    OMP_NUM_THREADS=1 python benchmarks/bench_sim_crosscheck.py --name bench_sim_dihedral \
        --runs "XPBD 50x2" "XPBD 100x4" "XPBD dihedral 50x2" "XPBD dihedral 100x4" "VBD 20x20"

Scene: a procedural knee-length skirt (``--vertices``) on the default anny body, for each of
``--motions``. Runs: the XPBD solver at its library default (50x2; revision 5's dataset
setting, the datasets now use 100x1 and 200x1) and at the fine reference (100x4); newton's VBD
solver (``pip install swingar-pyg[newton]``) at its default (10x10) and at a fine setting
(20x20), with cloth-like bending and with very stiff bending; XPBD with dihedral bending at
VBD's bending stiffness (``bending="dihedral"``). Each solver's own convergence error (default
vs fine of the same solver) is set against the disagreement of the two fine solutions: if the
second is much larger, the models, not the solves, decide where the cloth goes, and no
estimator can be said to be closer to the truth than that. Also recorded: cost, largest strain,
share of vertices inside the body, and how far the hem hangs from the body axis (a flared
skirt's flare is where the two models differ).

Writes ``benchmarks/results/<--name>.json`` and ``.png`` (default ``bench_sim_crosscheck``);
``--runs`` keeps some of the runs, and the comparisons between them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, write_results  # noqa: E402

from swingar_pyg.sim import VBDSettings, XPBDSettings  # noqa: E402
from swingar_pyg.world.body import AnnyBody  # noqa: E402
from swingar_pyg.world.motion import procedural_motion  # noqa: E402
from swingar_pyg.world.sequence import simulate_sequence  # noqa: E402
from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt  # noqa: E402

STIFF_BENDING = 10.0


def runs(fps: float) -> dict[str, XPBDSettings | VBDSettings]:
    """The solver settings compared, by name."""
    return {
        "XPBD 50x2": XPBDSettings(fps=fps),
        "XPBD 100x4": XPBDSettings(fps=fps, substeps=100, iterations=4),
        "VBD 10x10": VBDSettings(fps=fps),
        "VBD 20x20": VBDSettings(fps=fps, substeps=20, iterations=20),
        "VBD 10x10 stiff bending": VBDSettings(fps=fps, bend_stiffness=STIFF_BENDING),
        "XPBD dihedral 50x2": XPBDSettings(fps=fps, bending="dihedral",
                                           bend_stiffness=VBDSettings.bend_stiffness),
        "XPBD dihedral 100x4": XPBDSettings(fps=fps, substeps=100, iterations=4,
                                            bending="dihedral",
                                            bend_stiffness=VBDSettings.bend_stiffness),
    }


# (label, run, reference): each solver's own convergence error, then the cross-model gaps.
COMPARISONS = [
    ("XPBD 50x2 vs XPBD 100x4", "XPBD 50x2", "XPBD 100x4"),
    ("VBD 10x10 vs VBD 20x20", "VBD 10x10", "VBD 20x20"),
    ("XPBD 100x4 vs VBD 20x20", "XPBD 100x4", "VBD 20x20"),
    ("XPBD 100x4 vs VBD stiff bending", "XPBD 100x4", "VBD 10x10 stiff bending"),
    ("XPBD dihedral 50x2 vs 100x4", "XPBD dihedral 50x2", "XPBD dihedral 100x4"),
    ("XPBD distance vs dihedral bending", "XPBD 100x4", "XPBD dihedral 100x4"),
    ("XPBD dihedral 100x4 vs VBD 20x20", "XPBD dihedral 100x4", "VBD 20x20"),
]


def hem_radius(positions: torch.Tensor, hem: np.ndarray) -> np.ndarray:
    """Mean horizontal distance of the hem vertices from their centroid, per frame (m)."""
    xy = positions[:, hem, :2]
    return (xy - xy.mean(dim=1, keepdim=True)).norm(dim=-1).mean(dim=1).numpy()


def plot(scenes: list[dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (gap_axis, hem_axis) = plt.subplots(1, 2, figsize=(12, 4.2))
    labels = list(scenes[0]["comparisons"])
    width = 0.8 / len(labels)
    for k, label in enumerate(labels):
        means = [scene["comparisons"][label]["mean_mm"] for scene in scenes]
        p95 = [scene["comparisons"][label]["p95_mm"] for scene in scenes]
        positions = np.arange(len(scenes)) + (k - (len(labels) - 1) / 2) * width
        gap_axis.bar(positions, means, width, label=label)
        gap_axis.errorbar(positions, means, yerr=[np.zeros(len(p95)), np.subtract(p95, means)],
                          fmt="none", ecolor="k", capsize=2, lw=0.8)
    gap_axis.set_xticks(np.arange(len(scenes)), [scene["motion"] for scene in scenes])
    gap_axis.set(ylabel="mean vertex distance (mm; whisker: p95)",
                 title="own convergence error vs disagreement of the two solvers")
    gap_axis.legend(fontsize=7)
    gap_axis.grid(alpha=0.3, axis="y")
    scene = scenes[-1]
    for name, run in scene["runs"].items():
        hem_axis.plot(1e2 * np.asarray(run["hem_radius_m"]), label=name)
    hem_axis.axhline(1e2 * scene["rest_hem_radius_m"], color="k", ls=":", lw=0.8,
                     label="rest (as cut)")
    hem_axis.set(xlabel="frame", ylabel="hem radius (cm)",
                 title=f"how far the flare hangs out ({scene['motion']})")
    hem_axis.legend(fontsize=7)
    hem_axis.grid(alpha=0.3)
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vertices", type=int, default=1500)
    parser.add_argument("--motions", nargs="+", default=["sway", "walk", "spin_stop"])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--quick", action="store_true", help="500 vertices, sway, 0.5 s")
    parser.add_argument("--runs", nargs="+", default=None, help="only these runs (names as in "
                        "the output); comparisons need both of their runs")
    parser.add_argument("--name", default="bench_sim_crosscheck", help="results file name")
    args = parser.parse_args()
    chosen = runs(30.0)
    unknown = set(args.runs or ()) - set(chosen)
    if unknown:
        parser.error(f"unknown runs {sorted(unknown)}; choose from {', '.join(chosen)}")
    if args.quick:
        args.vertices, args.motions, args.seconds = 500, ["sway"], 0.5
    torch.set_num_threads(1)

    body = AnnyBody()
    shape = body.default_shape()
    garment = fit_procedural_skirt(SkirtSpec(vertices=args.vertices), body, shape)
    height = garment.mesh.vertices[:, 2]
    hem = np.flatnonzero(height < np.quantile(height, 0.1))
    rest_hem = hem_radius(torch.as_tensor(garment.mesh.vertices)[None], hem)[0]
    scenes = []
    for motion_name in args.motions:
        motion = procedural_motion(motion_name, body.joint_names, seconds=args.seconds)
        positions, scene_runs = {}, {}
        for name, settings in runs(motion.fps).items():
            if args.runs and name not in args.runs:
                continue
            result = simulate_sequence(body, shape, garment, motion, settings).result
            positions[name] = result.positions
            scene_runs[name] = {
                "settings": result.settings,
                "ms_per_frame": 1e3 * float(np.median(result.seconds_per_frame)),
                "max_strain": float(result.max_stretch.max()),
                "mean_strain": float(result.mean_stretch.mean()),
                "max_penetration": float(np.nanmax(result.penetration)),
                "hem_radius_m": hem_radius(result.positions, hem).tolist()}
            r = scene_runs[name]
            print(f"{motion_name:>9} {name:<24} {r['ms_per_frame']:7.0f} ms/frame, max strain "
                  f"{100 * r['max_strain']:5.1f} %, inside {100 * r['max_penetration']:.2f} %, "
                  f"hem radius {100 * np.mean(r['hem_radius_m']):.1f} cm", flush=True)
        comparisons = {}
        for label, run, reference in COMPARISONS:
            if run not in positions or reference not in positions:
                continue
            distance = (positions[run] - positions[reference]).norm(dim=-1)
            comparisons[label] = {"mean_mm": 1e3 * float(distance.mean()),
                                  "p95_mm": 1e3 * float(distance.quantile(0.95)),
                                  "per_frame_mm": (1e3 * distance.mean(dim=1)).tolist()}
            print(f"{motion_name:>9} {label:<34} mean {comparisons[label]['mean_mm']:6.1f} mm, "
                  f"p95 {comparisons[label]['p95_mm']:6.1f} mm", flush=True)
        scenes.append({"motion": motion_name, "runs": scene_runs, "comparisons": comparisons,
                       "rest_hem_radius_m": float(rest_hem)})

    payload = {"machine": machine_info(), "garment": garment.name,
               "vertices": garment.mesh.num_vertices, "seconds": args.seconds,
               "scenes": scenes}
    path = write_results(args.name + ("_quick" if args.quick else ""), payload,
                         plot(scenes))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
