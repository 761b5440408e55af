"""Streaming speed per garment size and per stage, this tree against an older revision.

    OMP_NUM_THREADS=1 python benchmarks/bench_stream.py            # ~6 minutes on one core
    OMP_NUM_THREADS=1 python benchmarks/bench_stream.py --quick    # 1k and 5k, 20 frames

Every variant runs the same measurement (:func:`swingar_pyg.eval.stream_speed.stream_speed`:
a procedural skirt on the walking default body, median wall time per frame after three
warm-up frames, one thread) on an estimator of the quickstart's sizes with the same seed:

- ``baseline``: the package as it was at ``--baseline`` (a revision of this repository,
  exported with ``git archive`` to a temporary folder and run there in a subprocess), so the
  old path is measured by its own code, side by side in the same run;
- ``eager``: this tree;
- ``compiled``: this tree with ``SwinGarStream(..., compile=True)``; its compilation time is
  recorded apart (``first_frames_s``).

Writes ``benchmarks/results/bench_stream.json`` and ``bench_stream.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, write_results  # noqa: E402

from swingar_pyg.eval.stream_speed import stream_speed  # noqa: E402
from swingar_pyg.models import SwinGarEstimator  # noqa: E402
from swingar_pyg.world.body import AnnyBody  # noqa: E402

REPOSITORY = Path(__file__).resolve().parents[1]
MEASUREMENT = REPOSITORY / "swingar_pyg" / "eval" / "stream_speed.py"
# The streaming path before the detail network's input terms were cached, the FCA
# aggregation fused and skinning stopped gathering per-vertex transforms.
BASELINE = "186cb08"
# configs/quickstart.yaml's estimator
ESTIMATOR = dict(channels=32, detail_channels=32, descriptor_size=256, history=64)
GOALS_FPS = {1000: 200.0, 5000: 60.0}

# Run in a subprocess whose `swingar_pyg` is the exported revision; the measurement
# module is loaded from this tree's file, so both sides time the same way.
_SUBPROCESS = """
import json, sys, importlib.util, torch
import swingar_pyg
assert swingar_pyg.__file__.startswith(sys.argv[1]), swingar_pyg.__file__
spec = importlib.util.spec_from_file_location("stream_speed", sys.argv[2])
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.world.body import AnnyBody
torch.set_num_threads(1)
torch.manual_seed(0)
estimator = SwinGarEstimator(**json.loads(sys.argv[3]))
rows = module.stream_speed(estimator, AnnyBody(), json.loads(sys.argv[4]), int(sys.argv[5]))
print("ROWS" + json.dumps(rows))
"""


def measure_baseline(revision: str, vertices: list[int], frames: int) -> list[dict]:
    """The old revision's stream, measured in a subprocess on an exported copy of it."""
    archive = subprocess.run(["git", "-C", str(REPOSITORY), "archive", revision],
                             check=True, capture_output=True).stdout
    with tempfile.TemporaryDirectory(prefix="bench_stream_") as folder:
        with tarfile.open(fileobj=BytesIO(archive)) as tar:
            tar.extractall(folder, filter="data")
        environment = {**os.environ, "PYTHONPATH": folder, "OMP_NUM_THREADS": "1"}
        result = subprocess.run(
            [sys.executable, "-c", _SUBPROCESS, folder, str(MEASUREMENT), json.dumps(ESTIMATOR),
             json.dumps(vertices), str(frames)],
            cwd=folder, env=environment, check=True, capture_output=True, text=True)
    line = next(x for x in result.stdout.splitlines() if x.startswith("ROWS"))
    return json.loads(line[4:])


def plot(variants: dict[str, list[dict]]):
    figure, (speed, stages) = plt.subplots(1, 2, figsize=(11, 4))
    for name, rows in variants.items():
        speed.plot([r["vertices"] for r in rows], [r["fps"] for r in rows], "o-", label=name)
    for size, goal in GOALS_FPS.items():
        speed.plot([size], [goal], "k_", markersize=18)
    speed.set(xscale="log", yscale="log", xlabel="garment vertices",
              ylabel="frames per second (one thread)", title="streaming (— goal)")
    speed.legend()
    names = [k for k in next(iter(variants.values()))[0] if k.startswith("ms ")]
    labels = []
    for index, (variant, rows) in enumerate(variants.items()):
        for position, row in enumerate(rows):
            x = position * (len(variants) + 1) + index
            bottom = 0.0
            for colour, name in enumerate(names):
                value = row.get(name, 0.0)
                stages.bar(x, value, bottom=bottom, color=f"C{colour}",
                           label=name[3:] if (index, position) == (0, 0) else None)
                bottom += value
            labels.append((x, f"{variant}\n{row['vertices']}"))
    stages.set_xticks([x for x, _ in labels], [text for _, text in labels], fontsize=6,
                      rotation=90)
    stages.set(ylabel="ms per frame (median per stage)", title="where a frame goes")
    stages.legend(fontsize=7)
    return figure


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--vertices", type=int, nargs="+", default=[1000, 5000, 20000])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--baseline", default=BASELINE,
                        help="the revision measured as the old path (default: %(default)s)")
    parser.add_argument("--quick", action="store_true", help="1k and 5k vertices, 20 frames")
    args = parser.parse_args(argv)
    vertices, frames = ([1000, 5000], 20) if args.quick else (args.vertices, args.frames)
    torch.set_num_threads(1)
    body = AnnyBody()
    variants = {"baseline " + args.baseline: measure_baseline(args.baseline, vertices, frames)}
    for compile in (False, True):
        torch.manual_seed(0)
        estimator = SwinGarEstimator(**ESTIMATOR)
        variants["compiled" if compile else "eager"] = stream_speed(
            estimator, body, vertices, frames, compile=compile)
    baseline = next(iter(variants.values()))
    speedups = {name: [new["fps"] / old["fps"] for new, old in zip(rows, baseline)]
                for name, rows in variants.items()}
    for name, rows in variants.items():
        print(name)
        for row, speedup in zip(rows, speedups[name]):
            print(f"  {row['vertices']:>6} vertices  {row['ms_per_frame']:7.2f} ms  "
                  f"{row['fps']:7.1f} fps  x{speedup:.2f}  " +
                  "  ".join(f"{k[3:]} {v:.2f}" for k, v in row.items() if k.startswith("ms ")))
    path = write_results("bench_stream", {
        "machine": machine_info(), "estimator": ESTIMATOR, "frames": frames,
        "baseline": args.baseline, "goals_fps": GOALS_FPS, "variants": variants,
        "speedup_over_baseline": speedups}, plot(variants))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
