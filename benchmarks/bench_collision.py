"""Collision handling after inference: the neural body SDF and the neighbour-aware
correction (paper §3.4) against TailorNet's fixed-offset push.

    OMP_NUM_THREADS=1 python benchmarks/bench_collision.py     # ~20 minutes on one core
    OMP_NUM_THREADS=1 python benchmarks/bench_collision.py --quick

Garments: the estimator's predictions (``--estimator``, default the quickstart's best
checkpoint) on the test split (``--data``: unseen garments and motions), every
``--every``-th frame; without an estimator checkpoint, the ground truth pushed 1-3 cm
into the body along its inward normal in patches. Methods, each on the same frames:

- ``none``;
- ``tailornet``: every vertex inside by TailorNet's test (the tangent plane of the nearest
  body vertex) goes ``--offset`` out along that vertex's normal;
- ``push (exact)``: the same fixed-offset push, but with the exact SDF;
- ``ours (exact)``: the neighbour-aware correction with the exact SDF;
- ``ours (neural)``: the same with the neural body SDF (``--body-sdf``), after the
  bone-capsule broad phase.

Measured with the exact SDF (closest point + ray parity): share of vertices inside the body
after (%), mean and largest depth of those left inside (mm), added roughness (mean growth of
the uniform-Laplacian magnitude at moved vertices and their neighbours, mm), distance to the
simulated garment before and after (mm), and time per frame (ms, one thread). Then the
network's accuracy near the surface (|s| < 2 cm: mean and p95 |S - s|, sign accuracy beyond
2 mm, normal cosine) on the training shapes in unseen motions, on unseen shapes, and in the
extreme poses (legs split, arms crossed), and its detection of inside vertices on the garments.

Writes ``benchmarks/results/bench_collision.json`` and ``bench_collision.png``.
"""

from __future__ import annotations

import argparse
import glob
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, write_results  # noqa: E402

from swingar_pyg.collision import (  # noqa: E402
    NeuralCollisions,
    exact_signed_distance,
    fixed_offset_push,
    nearest_vertex_signed_distance,
    resolve_collisions,
)
from swingar_pyg.models.losses import uniform_laplacian  # noqa: E402
from swingar_pyg.training import load_body_sdf, load_estimator  # noqa: E402
from swingar_pyg.world.body import AnnyBody  # noqa: E402
from swingar_pyg.world.sequence_file import read_garment, read_sequence, sequence_ids  # noqa: E402

METHODS = ("none", "tailornet", "push (exact)", "ours (exact)", "ours (neural)")


def latest(pattern: str) -> str | None:
    found = sorted(glob.glob(pattern), key=lambda p: Path(p).stat().st_mtime)
    return found[-1] if found else None


def garment_frames(data: Path, checkpoint: str | None, every: int, sequences: int | None,
                   body: AnnyBody):
    """Per test sequence: predicted (or perturbed) and simulated garments at the chosen
    frames, with the posed body."""
    from swingar_pyg.geometry import mesh_edge_index
    from swingar_pyg.inference.prediction import animate, garment_graph

    ids = sequence_ids(data)[:sequences]
    estimator = settings = None
    if checkpoint:
        estimator, settings = load_estimator(checkpoint)
    rng = np.random.default_rng(0)
    for sequence_id in ids:
        sequence = read_sequence(data, sequence_id)
        garment = read_garment(data, sequence["garment"])
        shape = torch.as_tensor(sequence["body_shape"])
        rotations = torch.as_tensor(sequence["rotations"])
        translation = torch.as_tensor(sequence["translation"])
        posed = body.pose(shape, rotations, translation)
        truth = torch.as_tensor(sequence["garment_vertices"]).double()
        if estimator is not None:
            graph = garment_graph(garment, len(body.joint_names), estimator.descriptor_size,
                                  sigma=settings.get("sigma", 0.1), seed=settings.get("seed", 0))
            predicted, _ = animate(estimator, graph, shape, rotations, translation,
                                   posed.joint_transforms, posed.joint_positions,
                                   sequence["fps"], progress=False)
            predicted = predicted.double()
        else:
            predicted = perturb(truth, posed.vertices, body.faces, rng)
        frames = list(range(0, len(truth), every))
        yield {"id": sequence_id, "garment": sequence["garment"], "motion": sequence["motion"],
               "shape": shape, "edge_index": mesh_edge_index(garment.mesh),
               "frames": [(predicted[t], truth[t], posed.vertices[t].double(),
                           posed.joint_transforms[t], posed.joint_positions[t])
                          for t in frames]}


def perturb(truth: torch.Tensor, bodies: torch.Tensor, faces: torch.Tensor,
            rng: np.random.Generator) -> torch.Tensor:
    """Ground truth with patches pushed into the body: every vertex within 3 cm of the
    body moves 1-3 cm along the inward normal of its nearest body vertex."""
    from swingar_pyg.geometry import vertex_normals

    out = truth.clone()
    for t in range(len(truth)):
        normals = vertex_normals(bodies[t], faces).double()
        nearest = torch.cdist(truth[t], bodies[t].double()).argmin(dim=1)
        gap = ((truth[t] - bodies[t, nearest].double()) * normals[nearest]).sum(-1)
        depth = torch.as_tensor(rng.uniform(0.01, 0.03, len(gap)))
        out[t] = torch.where((gap < 0.03)[:, None], truth[t] - (gap + depth)[:, None] *
                             normals[nearest], truth[t])
    return out


def roughness_added(before: torch.Tensor, after: torch.Tensor, moved: torch.Tensor,
                    edge_index: torch.Tensor) -> float:
    """Mean growth (mm) of |L x| over moved vertices and their neighbours."""
    if not moved.any():
        return 0.0
    src, dst = edge_index
    region = moved.clone()
    region[dst[moved[src]]] = True
    magnitude = [uniform_laplacian(x[None], edge_index)[0].norm(dim=-1) for x in (before, after)]
    return 1e3 * float((magnitude[1] - magnitude[0])[region].mean())


def run_methods(sequences, neural_for, faces: torch.Tensor, offset: float) -> dict:
    rows = {m: {"inside": 0, "vertices": 0, "depths": [], "roughness": [], "error_mm": [],
                "seconds": []} for m in METHODS}
    detection = {"true_inside": 0, "detected": 0, "false_alarms": 0, "outside": 0}
    for sequence in sequences:
        edges = sequence["edge_index"]
        neural = neural_for(sequence["shape"])
        for predicted, truth, body, transforms, joints in sequence["frames"]:
            exact = exact_signed_distance(body, faces)
            inside_before = exact(predicted)[0] > 0
            net = neural.body_sdf.bind(transforms, joints, sequence["shape"])(
                predicted.float())[0] > -offset
            detection["true_inside"] += int(inside_before.sum())
            detection["detected"] += int((net & inside_before).sum())
            detection["false_alarms"] += int((net & ~inside_before).sum())
            detection["outside"] += int((~inside_before).sum())
            for method in METHODS:
                start = time.perf_counter()
                if method == "none":
                    corrected, moved = predicted, torch.zeros(len(predicted), dtype=torch.bool)
                elif method == "tailornet":
                    result = fixed_offset_push(predicted, nearest_vertex_signed_distance(
                        body, faces), offset=offset)
                    corrected, moved = result.vertices, result.moved
                elif method == "push (exact)":
                    result = fixed_offset_push(predicted, exact, offset=offset)
                    corrected, moved = result.vertices, result.moved
                elif method == "ours (exact)":
                    result = resolve_collisions(predicted, edges, exact)
                    corrected, moved = result.vertices, result.moved
                else:
                    result = neural.correct(predicted.float(), edges, transforms, joints)
                    corrected, moved = result.vertices.double(), result.moved
                seconds = time.perf_counter() - start
                depth = exact(corrected)[0]
                row = rows[method]
                row["inside"] += int((depth > 0).sum())
                row["vertices"] += len(depth)
                row["depths"].append(depth[depth > 0])
                row["roughness"].append(roughness_added(predicted, corrected, moved, edges))
                row["error_mm"].append(1e3 * float((corrected - truth).norm(dim=-1).mean()))
                row["seconds"].append(seconds)
    summary = {}
    for method, row in rows.items():
        depths = torch.cat(row["depths"]) if row["depths"] else torch.zeros(0)
        summary[method] = {
            "inside_percent": 100.0 * row["inside"] / max(row["vertices"], 1),
            "depth_mean_mm": 1e3 * float(depths.mean()) if len(depths) else 0.0,
            "depth_max_mm": 1e3 * float(depths.max()) if len(depths) else 0.0,
            "roughness_added_mm": float(np.mean(row["roughness"])),
            "error_mm": float(np.mean(row["error_mm"])),
            "ms_per_frame": 1e3 * float(np.median(row["seconds"]))}
    summary["detection"] = {
        "recall": detection["detected"] / max(detection["true_inside"], 1),
        "false_alarm_rate": detection["false_alarms"] / max(detection["outside"], 1),
        "inside_vertices": detection["true_inside"]}
    return summary


def sdf_accuracy(network, body: AnnyBody, seen_shapes, points: int, seed: int) -> dict:
    """The network against the exact SDF near the surface, on three kinds of bodies."""
    from datamodules.body_sdf_data import SDFSampleSettings, sample_motion_frames

    settings = SDFSampleSettings(frames_per_motion=2, points_per_frame=points)
    rng = np.random.default_rng(seed)
    unseen = [tuple(float(v) for v in rng.uniform(0, 1, 6)) for _ in range(4)]
    cases = {
        "seen shapes, unseen motions": [(s, ("spin_stop", "cmu_02_03_run_cgspeed_style"))
                                        for s in seen_shapes],
        "unseen shapes, seen motions": [(s, ("walk", "kick")) for s in unseen],
        "extreme poses (seen shape)": [(seen_shapes[0], ("leg_split", "arm_cross"))],
        "extreme poses (unseen shapes)": [(s, ("leg_split", "arm_cross")) for s in unseen[:2]],
    }
    out = {}
    for name, jobs in cases.items():
        errors, signs, cosines = [], [], []
        for shape, motions in jobs:
            frames, _ = sample_motion_frames(body, shape, motions, settings, rng)
            for k in range(len(frames["points"])):
                value, gradient = network.signed_distance(
                    torch.as_tensor(frames["points"][k]),
                    torch.as_tensor(frames["joint_transforms"][k])[None],
                    torch.as_tensor(frames["joint_positions"][k])[None],
                    torch.as_tensor(frames["body_shape"][k])[None].float())
                sdf = torch.as_tensor(frames["sdf"][k])
                normal = torch.as_tensor(frames["normal"][k])
                near = sdf.abs() < 0.02
                errors.append((value - sdf).abs()[near])
                signs.append(((value > 0) == (sdf > 0))[near & (sdf.abs() > 0.002)].float())
                cosines.append(-(torch.nn.functional.normalize(gradient, dim=-1) *
                                 normal).sum(-1)[near])
        error = torch.cat(errors).double()
        out[name] = {"near_mean_mm": 1e3 * float(error.mean()),
                     "near_p95_mm": 1e3 * float(torch.quantile(error, 0.95)),
                     "sign_accuracy": float(torch.cat(signs).mean()),
                     "normal_cosine": float(torch.cat(cosines).mean()),
                     "points": int(len(error))}
    return out


def plot(methods: dict, accuracy: dict):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    names = list(METHODS)
    for name in names:
        row = methods[name]
        axes[0].scatter(max(row["ms_per_frame"], 1e-3), row["inside_percent"], s=40, label=name)
    axes[0].set(xscale="log", xlabel="ms per frame (one core)",
                ylabel="vertices inside the body after (%)", title="penetration vs time")
    axes[0].axhline(0.5, color="grey", lw=0.8, ls="--")
    axes[0].legend(fontsize=7)
    axes[1].bar(range(len(names)), [methods[n]["roughness_added_mm"] for n in names],
                color=[f"C{k}" for k in range(len(names))])
    axes[1].set_xticks(range(len(names)), names, rotation=25, fontsize=7)
    axes[1].set(ylabel="added |Lx| around moved vertices (mm)", title="bulges")
    cases = list(accuracy)
    axes[2].bar(range(len(cases)), [accuracy[c]["near_mean_mm"] for c in cases], color="C4")
    for k, case in enumerate(cases):
        axes[2].annotate(f"sign {100 * accuracy[case]['sign_accuracy']:.1f} %",
                         (k, accuracy[case]["near_mean_mm"]), ha="center", fontsize=7,
                         xytext=(0, 3), textcoords="offset points")
    axes[2].set_xticks(range(len(cases)), [c.replace(", ", ",\n").replace(" (", "\n(")
                                           for c in cases], fontsize=7)
    axes[2].set(ylabel="mean |S - s| within 2 cm of the surface (mm)", title="neural SDF")
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--estimator", default=latest("runs/quickstart/checkpoints/best-*.ckpt"),
                        help="estimator checkpoint (default: the quickstart's best); "
                             "'none' perturbs the ground truth instead")
    parser.add_argument("--body-sdf", default=latest("runs/body_sdf/checkpoints/best-*.ckpt"),
                        help="body SDF checkpoint (default: configs/body_sdf.yaml's best)")
    parser.add_argument("--data", default="data/quickstart/test.h5")
    parser.add_argument("--every", type=int, default=3, help="every n-th frame")
    parser.add_argument("--offset", type=float, default=0.004,
                        help="fixed offset of the push, and the neural correction's band (m)")
    parser.add_argument("--quick", action="store_true", help="two sequences, every 10th frame")
    parser.add_argument("--replot", action="store_true",
                        help="redraw the PNG from the last results/bench_collision.json")
    args = parser.parse_args()
    if args.replot:
        import json

        from common import RESULTS

        payload = json.loads((RESULTS / "bench_collision.json").read_text())
        write_results("bench_collision", payload, plot(payload["methods"],
                                                       payload["sdf_accuracy"]))
        return
    if not args.body_sdf:
        raise SystemExit("no body SDF checkpoint: run `swingar fit -c configs/body_sdf.yaml`")
    torch.manual_seed(0)
    body = AnnyBody()
    estimator = None if args.estimator in (None, "none") else args.estimator
    every, count = (10, 2) if args.quick else (args.every, None)
    sequences = list(garment_frames(Path(args.data), estimator, every, count, body))
    body_sdf = load_body_sdf(args.body_sdf)
    cache: dict = {}

    def neural_for(shape):
        key = tuple(shape.tolist())
        if key not in cache:
            cache[key] = NeuralCollisions.for_body(body_sdf, body, shape, offset=args.offset)
        return cache[key]

    methods = run_methods(sequences, neural_for, body.faces, args.offset)
    seen = sorted({tuple(float(v) for v in s["shape"]) for s in sequences})
    network = next(iter(cache.values())).body_sdf
    accuracy = sdf_accuracy(network, body, seen, 512 if args.quick else 2048, seed=1)
    frames = sum(len(s["frames"]) for s in sequences)
    payload = {"machine": machine_info(), "estimator": estimator, "body_sdf": args.body_sdf,
               "data": args.data, "frames": frames, "every": every, "offset_m": args.offset,
               "garments": sorted({s["garment"] for s in sequences}), "methods": methods,
               "sdf_accuracy": accuracy}
    name = "bench_collision_quick" if args.quick else "bench_collision"
    path = write_results(name, payload, plot(methods, accuracy))
    source = "estimator" if estimator else "perturbed ground truth"
    print(f"{frames} frames of {len(sequences)} sequences ({source})")
    print(f"{'method':<15} {'inside %':>9} {'depth mean/max mm':>18} {'rough mm':>9} "
          f"{'error mm':>9} {'ms/frame':>9}")
    for method in METHODS:
        row = methods[method]
        print(f"{method:<15} {row['inside_percent']:>9.3f} {row['depth_mean_mm']:>8.1f} / "
              f"{row['depth_max_mm']:<7.1f} {row['roughness_added_mm']:>9.2f} "
              f"{row['error_mm']:>9.1f} {row['ms_per_frame']:>9.1f}")
    d = methods["detection"]
    print(f"network detection: recall {100 * d['recall']:.1f} % of {d['inside_vertices']} inside "
          f"vertices, false alarms {100 * d['false_alarm_rate']:.2f} % of the others")
    for case, row in accuracy.items():
        print(f"SDF {case:<32} |S-s| {row['near_mean_mm']:.2f} mm (p95 {row['near_p95_mm']:.1f}), "
              f"sign {100 * row['sign_accuracy']:.1f} %, normal cos {row['normal_cosine']:.3f}")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
