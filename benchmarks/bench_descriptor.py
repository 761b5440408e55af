"""Nyström spectral descriptor against the exact eigendecomposition: time and error.

    OMP_NUM_THREADS=1 python benchmarks/bench_descriptor.py             # ~5 minutes on 2 cores
    OMP_NUM_THREADS=1 python benchmarks/bench_descriptor.py --quick     # a smoke run

Meshes: skirt-like tubes (an irregularly triangulated sheet, 1.6 m round and 0.6 m tall, rolled
into a cylinder whose seam is welded) at N = 1k ... 50k vertices, so the shape is the same and
only the resolution changes. For each N: the Nyström descriptor at z = 64 ... 512 (Voronoi
weights, and at z = 256 also the unweighted textbook formula), and the exact spectrum (all-pairs
Dijkstra + ``numpy.linalg.eigh``) where N <= ``--exact-max``. Error: the largest relative error
of the top-32 eigenvalues against the exact ones. Times are medians of ``--repeats`` runs.

Writes ``benchmarks/results/bench_descriptor.json`` and ``bench_descriptor.png``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, median_seconds, write_results  # noqa: E402

from swingar_pyg.geometry import (  # noqa: E402
    exact_affinity_spectrum,
    roll_into_cylinder,
    sheet,
    spectral_descriptor,
)

CIRCUMFERENCE, HEIGHT, SIGMA, TOP = 1.6, 0.6, 0.1, 32


def tube(num_vertices: int):
    cols = max(4, round(math.sqrt(num_vertices * CIRCUMFERENCE / HEIGHT)))
    rows = max(3, round(num_vertices / cols))
    flat = sheet(rows, cols, width=CIRCUMFERENCE, height=HEIGHT, jitter=0.3, seed=rows)
    return roll_into_cylinder(flat, radius=CIRCUMFERENCE / (2 * math.pi))


def top_error(approx: np.ndarray, exact: np.ndarray) -> float:
    return float(np.max(np.abs(approx[:TOP] - exact[:TOP]) / np.abs(exact[:TOP])))


def plot(rows: list[dict], zs: list[int]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (time_axis, error_axis) = plt.subplots(1, 2, figsize=(11, 4))
    sizes = [r["vertices"] for r in rows]
    for z in zs:
        time_axis.plot(sizes, [r["nystrom"][str(z)]["seconds"] for r in rows], "o-",
                       label=f"Nyström z={z}")
        errors = [(r["vertices"], r["nystrom"][str(z)].get("top32_error")) for r in rows]
        errors = [(n, e) for n, e in errors if e is not None]
        if errors:
            error_axis.plot(*zip(*errors), "o-", label=f"z={z}")
    uniform = [(r["vertices"], r["uniform_256"].get("top32_error")) for r in rows]
    uniform = [(n, e) for n, e in uniform if e is not None]
    if uniform:
        error_axis.plot(*zip(*uniform), "x--", color="gray", label="z=256 unweighted")
    exact = [(r["vertices"], r["exact"]["seconds"]) for r in rows if r.get("exact")]
    if exact:
        time_axis.plot(*zip(*exact), "ks-", label="exact (Dijkstra + eigh)")
    time_axis.axhline(3.0, color="k", ls=":", lw=1, label="3 s target")
    time_axis.set(xscale="log", yscale="log", xlabel="vertices N", ylabel="seconds",
                  title="descriptor time")
    error_axis.axhline(0.05, color="k", ls=":", lw=1, label="5 % target")
    error_axis.set(xscale="log", yscale="log", xlabel="vertices N",
                   ylabel=f"max relative error, top-{TOP}", title="error against exact")
    for axis in (time_axis, error_axis):
        axis.legend(fontsize=7)
        axis.grid(alpha=0.3, which="both")
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+",
                        default=[1000, 2000, 5000, 10000, 20000, 50000])
    parser.add_argument("--z", type=int, nargs="+", default=[64, 128, 256, 512])
    parser.add_argument("--exact-max", type=int, default=5000,
                        help="largest N for the exact spectrum (default: 5000)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="N = 500, 1000; z = 64, 128")
    args = parser.parse_args()
    if args.quick:
        args.sizes, args.z, args.repeats = [500, 1000], [64, 128], 1

    rows = []
    for target in args.sizes:
        mesh = tube(target)
        row: dict = {"target": target, "vertices": mesh.num_vertices, "nystrom": {}}
        exact_values = None
        if mesh.num_vertices <= args.exact_max:
            start = time.perf_counter()
            exact_values, _ = exact_affinity_spectrum(mesh, sigma=SIGMA)
            row["exact"] = {"seconds": time.perf_counter() - start,
                            "top_eigenvalues": exact_values[:TOP].tolist()}
        for z in args.z:
            seconds = median_seconds(lambda: spectral_descriptor(mesh, z=z, sigma=SIGMA),
                                     args.repeats, warmup=0)
            values = spectral_descriptor(mesh, z=z, sigma=SIGMA).eigenvalues
            entry = {"seconds": seconds}
            if exact_values is not None:
                entry["top32_error"] = top_error(values, exact_values)
                entry["speedup_vs_exact"] = row["exact"]["seconds"] / seconds
            row["nystrom"][str(z)] = entry
        uniform = spectral_descriptor(mesh, z=256, sigma=SIGMA, weighting="uniform").eigenvalues
        row["uniform_256"] = ({"top32_error": top_error(uniform, exact_values)}
                              if exact_values is not None else {})
        rows.append(row)
        summary = ", ".join(
            f"z={z}: {e['seconds']:.2f} s" + (f" err {100 * e['top32_error']:.1f} %"
                                              if "top32_error" in e else "")
            for z, e in row["nystrom"].items())
        exact_text = f"; exact {row['exact']['seconds']:.1f} s" if "exact" in row else ""
        print(f"N={mesh.num_vertices:>6}: {summary}{exact_text}", flush=True)

    payload = {"machine": machine_info(), "sigma_m": SIGMA, "top": TOP,
               "mesh": f"tube {CIRCUMFERENCE} m round, {HEIGHT} m tall, jittered triangulation",
               "rows": rows,
               "targets": {"z256_at_20k_seconds_max": 3.0, "speedup_at_5k_min": 50,
                           "top32_error_at_5k_max": 0.05}}
    path = write_results("bench_descriptor" + ("_quick" if args.quick else ""), payload,
                         plot(rows, args.z))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
