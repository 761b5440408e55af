"""How good the simulated truth is, by garment family and motion: the share of frames whose
largest edge strain ends above the 6 % stretch bar.

    OMP_NUM_THREADS=1 python benchmarks/bench_truth.py            # ~50 minutes on one core
    OMP_NUM_THREADS=1 python benchmarks/bench_truth.py --quick    # two garments, two motions

Each garment of ``GARMENTS`` (one or two of every family the world makes: procedural skirts
and dresses, sewn t-shirts and jumpsuits, the shipped MakeHuman pieces as they are and each
with its short edges merged) is dressed on the default anny body and simulated for
``--seconds`` on each motion of ``MOTIONS`` (procedural families, some played fast, and the
shipped captured clips) at the datasets' setting (100 x 1, frames above the bar re-run up to
400 substeps, warp backend, bending every 10th substep); the captured clips also with their
upper arms turned 20 degrees from the body (``arms_out``).
Recorded per run: the share of frames above the bar, the median and largest of the frames'
largest strain, the mean substeps a frame and the time a frame. One run's largest strain is
chaotic (``bench_strain.py`` repeats runs); the share of frames above the bar is the steadier
figure, and the one a dataset config is chosen by.

Writes ``benchmarks/results/bench_truth.json`` and a heat map ``bench_truth.png`` (``--name``
for another name, when ``--garments`` or ``--motions`` pick a subset).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, write_results  # noqa: E402

from swingar_pyg.sim import SIMULATOR_REVISION, STRETCH_BAR, XPBDSettings  # noqa: E402
from swingar_pyg.world.body import AnnyBody  # noqa: E402
from swingar_pyg.world.catalogue import fit_garment, garment_spec  # noqa: E402
from swingar_pyg.world.garment_assets import shipped_garments  # noqa: E402
from swingar_pyg.world.motion_library import make_motion  # noqa: E402
from swingar_pyg.world.sequence import simulate_sequence  # noqa: E402

GARMENTS = {
    "skirt, knee": {"length": 0.55, "flare": 0.4, "vertices": 1200, "jitter": 0.3, "seed": 3},
    "skirt, long flared": {"length": 0.72, "flare": 0.6, "vertices": 1970, "jitter": 0.3,
                           "seed": 7},
    "dress": {"kind": "dress", "length": 0.95, "flare": 0.25, "vertices": 1500},
    "t-shirt (sewn)": {"kind": "tshirt", "length": 0.75, "sleeve": 0.4, "vertices": 1500},
    "jumpsuit (sewn)": {"kind": "jumpsuit", "leg": 1.0, "vertices": 2000},
    "jumpsuit (sewn), loose": {"kind": "jumpsuit", "leg": 1.0, "vertices": 2000, "ease": 0.08,
                               "flare": 0.1, "clearance": 0.05, "crotch_drop": 0.2},
    "MakeHuman tshirt_loose": {"kind": "shipped", "name": "tshirt_loose"},
    "MakeHuman top_short_sleeve": {"kind": "shipped", "name": "top_short_sleeve"},
    "MakeHuman dress_skirt_knee": {"kind": "shipped", "name": "dress_skirt_knee"},
    "MakeHuman dress_bodice": {"kind": "shipped", "name": "dress_bodice"},
    "MakeHuman trousers": {"kind": "shipped", "name": "trousers"},
    "MakeHuman shorts": {"kind": "shipped", "name": "shorts"},
    "MakeHuman overall": {"kind": "shipped", "name": "overall_jumpsuit"},
}
# Every shipped piece with its edges under half the median merged
# (swingar_pyg.geometry.merge_short_edges; the base data's setting for its MakeHuman tops).
GARMENTS.update({f"MakeHuman {name}, edges merged": {"kind": "shipped", "name": name,
                                                      "merge_edges_below": 0.5}
                 for name in shipped_garments()})
# name: (source, speed, amplitude, arms out in degrees)
MOTIONS = {
    "sway": ("sway", 1.0, 1.0, 0.0), "twist": ("twist", 1.0, 1.0, 0.0),
    "walk": ("walk", 1.0, 1.0, 0.0), "walk x2": ("walk", 2.0, 1.0, 0.0),
    "jump": ("jump", 1.0, 1.0, 0.0), "spin and stop": ("spin_stop", 1.0, 1.0, 0.0),
    "kick 45°": ("kick", 1.0, 0.7, 0.0), "kick 45° x2": ("kick", 2.0, 0.7, 0.0),
    "walk clip": ("cmu_02_01_walk_delfem2", 1.0, 1.0, 0.0),
    "walk clip, arms 20° out": ("cmu_02_01_walk_delfem2", 1.0, 1.0, 20.0),
    "walk clip 2": ("cmu_12_03_walk_makehuman", 1.0, 1.0, 0.0),
    "walk clip 2, arms 20° out": ("cmu_12_03_walk_makehuman", 1.0, 1.0, 20.0),
    "run clip": ("cmu_02_03_run_cgspeed_style", 1.0, 1.0, 0.0),
    "run clip, arms 20° out": ("cmu_02_03_run_cgspeed_style", 1.0, 1.0, 20.0),
}
SETTINGS = dict(substeps=100, iterations=1, max_substeps=400, backend="warp", bend_every=10)


def plot(rows: list[dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    garments = list(dict.fromkeys(r["garment"] for r in rows))
    motions = list(dict.fromkeys(r["motion"] for r in rows))
    share = np.full((len(garments), len(motions)), np.nan)
    for r in rows:
        share[garments.index(r["garment"]), motions.index(r["motion"])] = \
            100 * r["frames_above_bar"]
    figure, axis = plt.subplots(figsize=(1.1 * len(motions) + 3, 0.45 * len(garments) + 1.5))
    image = axis.imshow(share, cmap="Reds", vmin=0, vmax=100)
    for (i, j), value in np.ndenumerate(share):
        axis.text(j, i, f"{value:.0f}", ha="center", va="center", fontsize=7,
                  color="white" if value > 60 else "black")
    axis.set_xticks(range(len(motions)), motions, rotation=40, ha="right", fontsize=8)
    axis.set_yticks(range(len(garments)), garments, fontsize=8)
    axis.set_title(f"frames above the {100 * STRETCH_BAR:g} % stretch bar (%)")
    figure.colorbar(image, ax=axis, fraction=0.03)
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--garments", nargs="+", choices=list(GARMENTS), default=list(GARMENTS))
    parser.add_argument("--motions", nargs="+", choices=list(MOTIONS), default=list(MOTIONS))
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--name", default="bench_truth",
                        help="results/<name>.json and .png (a subset of rows under its own name)")
    parser.add_argument("--quick", action="store_true",
                        help="a skirt and the sewn t-shirt on sway and the walk clip, 1 s")
    args = parser.parse_args()
    if args.quick:
        args.garments, args.motions, args.seconds = (["skirt, knee", "t-shirt (sewn)"],
                                                     ["sway", "walk clip"], 1.0)
    if args.seconds <= 0:
        raise ValueError("--seconds must be > 0")
    torch.set_num_threads(1)
    body = AnnyBody()
    shape = body.default_shape()
    rows = []
    for garment_name in args.garments:
        garment = fit_garment(garment_spec(GARMENTS[garment_name]), body, shape)
        for motion_name in args.motions:
            source, speed, amplitude, arms = MOTIONS[motion_name]
            options = {"amplitude": amplitude} if amplitude != 1.0 else {}
            if arms:
                options["arms_out_degrees"] = arms
            motion = make_motion(source, body, shape, seconds=args.seconds, speed=speed,
                                 **options)
            settings = XPBDSettings(fps=motion.fps, **SETTINGS)
            result = simulate_sequence(body, shape, garment, motion, settings).result
            rows.append({"garment": garment_name, "motion": motion_name,
                         "vertices": garment.mesh.num_vertices,
                         "frames_above_bar": float(np.mean(result.max_stretch > STRETCH_BAR)),
                         "median_largest_strain": float(np.median(result.max_stretch)),
                         "largest_strain": float(result.max_stretch.max()),
                         "mean_substeps": float(result.substeps_per_frame.mean()),
                         "ms_per_frame": 1e3 * float(np.mean(result.seconds_per_frame))})
            r = rows[-1]
            print(f"{garment_name:27s} {motion_name:14s} N={r['vertices']:5d}: "
                  f"{100 * r['frames_above_bar']:5.1f} % of frames above the bar, largest "
                  f"strain median {100 * r['median_largest_strain']:5.1f} %, worst "
                  f"{100 * r['largest_strain']:6.1f} %, {r['mean_substeps']:.0f} substeps, "
                  f"{r['ms_per_frame']:.0f} ms/frame", flush=True)
    payload = {"machine": machine_info(), "simulator_revision": SIMULATOR_REVISION,
               "seconds": args.seconds, "settings": SETTINGS, "rows": rows}
    path = write_results(args.name + ("_quick" if args.quick else ""), payload, plot(rows))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
