"""FCAConv against GATConv and GATv2Conv: time and peak memory on mesh graphs.

    OMP_NUM_THREADS=1 python benchmarks/bench_fca.py            # ~3 minutes on 2 cores
    OMP_NUM_THREADS=1 python benchmarks/bench_fca.py --quick    # small graphs, for a smoke run

Graphs: irregular sheet meshes of about 1k, 5k and 20k vertices, and a Batch of 16 garments
(the 10 shipped ones and 6 procedural sheets). Every layer maps 64 channels to 4 heads x 16.
Two input styles: ``tensor`` (a plain edge_index; the layer adds self-loops on every call, PyG's
default) and ``prepared`` (``swingar_pyg.nn.attention_edge_index``: self-loops added once, edges
sorted by destination, layers built with ``add_self_loops=False``).
Times are medians over interleaved rounds (each round runs every layer once), so the ratios to
GATConv compare layers measured side by side. Peak memory of forward + backward is measured in
a fresh process per (layer, graph): the rise of the resident set (VmHWM) on the CPU, or
``torch.cuda.max_memory_allocated`` on a GPU. ``--scatter both`` repeats the timing with
torch-scatter importable and blocked (it must be installed for that), alternating processes.

Writes ``benchmarks/results/bench_fca.json`` and ``bench_fca.png``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
LAYERS = ("GATConv", "GATv2Conv", "FCAConv")
INPUTS = ("tensor", "prepared")
CHANNELS, HEADS, OUT = 64, 4, 16


def build_graphs(quick: bool):
    import torch
    from torch_geometric.data import Batch, Data

    from swingar_pyg.geometry import mesh_edge_index, sheet
    from swingar_pyg.world.garment_assets import load_shipped_garment, shipped_garments

    generator = torch.Generator().manual_seed(0)

    def graph(mesh):
        x = torch.randn(mesh.num_vertices, CHANNELS, generator=generator)
        return Data(x=x, edge_index=mesh_edge_index(mesh))

    sides = {"1k": 32, "5k": 71, "20k": 141} if not quick else {"1k": 32, "2k": 45}
    graphs = {f"sheet_{name}": graph(sheet(side, side, jitter=0.3, seed=side))
              for name, side in sides.items()}
    garments = [graph(load_shipped_garment(name)) for name in shipped_garments()]
    garments += [graph(sheet(20 + 6 * k, 25 + 4 * k, jitter=0.3, seed=k)) for k in range(6)]
    graphs["batch_16_garments"] = Batch.from_data_list(garments if not quick else garments[:4])
    return graphs


def make_layer(name: str, input_style: str):
    from torch_geometric.nn import GATConv, GATv2Conv

    from swingar_pyg.nn import FCAConv

    cls = {"GATConv": GATConv, "GATv2Conv": GATv2Conv, "FCAConv": FCAConv}[name]
    return cls(CHANNELS, OUT, heads=HEADS, add_self_loops=input_style == "tensor")


def edges_for(graph, input_style: str):
    from swingar_pyg.nn import attention_edge_index

    if input_style == "tensor":
        return graph.edge_index
    return attention_edge_index(graph.edge_index, graph.num_nodes)


def _block_torch_scatter() -> None:
    sys.modules["torch_scatter"] = None  # makes `import torch_scatter` fail


def child_timing(args) -> dict:
    """Interleaved timing of every layer on every graph, in this process."""
    import time

    import torch

    device = torch.device(args.device)
    graphs = {k: g.to(device) for k, g in build_graphs(args.quick).items()}
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)

    def forward(layer, x, edges):
        with torch.no_grad():
            layer(x, edges)

    def forward_backward(layer, x, edges):
        x = x.detach().requires_grad_()
        layer(x, edges).square().mean().backward()

    results = {}
    for input_style in INPUTS:
        layers = {name: make_layer(name, input_style).to(device) for name in LAYERS}
        for graph_name, g in graphs.items():
            edges = edges_for(g, input_style)
            for mode, run in (("forward", forward), ("forward_backward", forward_backward)):
                samples = {name: [] for name in LAYERS}
                for layer in layers.values():
                    run(layer, g.x, edges)  # warm-up
                for _ in range(args.repeats):
                    for name, layer in layers.items():
                        sync()
                        start = time.perf_counter()
                        run(layer, g.x, edges)
                        sync()
                        samples[name].append(time.perf_counter() - start)
                results[f"{graph_name}/{input_style}/{mode}"] = samples
    return results


def child_memory(args) -> dict:
    """Peak memory of one forward + backward of one layer on one graph, in this process."""
    import ctypes
    import gc

    import torch

    device = torch.device(args.device)
    g = build_graphs(args.quick)[args.graph].to(device)
    edges = edges_for(g, args.input)
    layer = make_layer(args.layer, args.input).to(device)

    def step():
        x = g.x.detach().requires_grad_()
        layer(x, edges).square().mean().backward()
        layer.zero_grad(set_to_none=True)

    step()  # warm-up: lazy initialisation is not the layer's working memory
    gc.collect()
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
        base = torch.cuda.memory_allocated(device)
        step()
        return {"peak_bytes": torch.cuda.max_memory_allocated(device) - base}
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    base = _status_kib("VmRSS")
    Path("/proc/self/clear_refs").write_text("5")  # resets VmHWM to the current RSS
    step()
    return {"peak_bytes": 1024 * (_status_kib("VmHWM") - base)}


def _status_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"/proc/self/status has no {field}")


def run_child(args, *extra: str, env_scatter: bool = True) -> dict:
    command = [sys.executable, __file__, "--repeats", str(args.repeats), "--device", args.device,
               *(["--quick"] if args.quick else []), *([] if env_scatter else ["--no-scatter"]),
               *extra]
    result = subprocess.run(command, capture_output=True, text=True, check=True,
                            env={**__import__("os").environ, "MALLOC_MMAP_THRESHOLD_": "65536"})
    return json.loads(result.stdout.strip().splitlines()[-1])


def merge(runs: list[dict]) -> dict:
    merged: dict = {}
    for run in runs:
        for key, samples in run.items():
            for name, values in samples.items():
                merged.setdefault(key, {}).setdefault(name, []).extend(values)
    return merged


def summarise(samples: dict) -> dict:
    import statistics

    table = {}
    for key, per_layer in samples.items():
        medians = {name: statistics.median(values) for name, values in per_layer.items()}
        table[key] = {name: {"median_ms": 1e3 * m, "ratio_to_GATConv": m / medians["GATConv"]}
                      for name, m in medians.items()}
    return table


def plot(times: dict, memory: dict, scatter: dict | None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    graphs = list(dict.fromkeys(key.split("/")[0] for key in times))
    panels = [(f"fwd+bwd time / GATConv, {style} input",
               {name: [times[f"{g}/{style}/forward_backward"][name]["ratio_to_GATConv"]
                       for g in graphs] for name in LAYERS}, 1.25) for style in INPUTS]
    panels += [(f"peak memory (fwd+bwd) / GATConv, {style} input",
                {name: [memory[f"{g}/{style}"][name]["ratio_to_GATConv"] for g in graphs]
                 for name in LAYERS}, 1.3) for style in INPUTS]
    if scatter:
        panels.append(("time with torch-scatter / without (tensor input)",
                       {name: [row[g] for g in graphs] for name, row in scatter.items()}, 1.0))
    figure, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 4), squeeze=False)
    for axis, (title, bars, line) in zip(axes[0], panels):
        width = 0.8 / len(bars)
        for k, (name, values) in enumerate(bars.items()):
            axis.bar([p + k * width for p in range(len(graphs))], values, width, label=name)
        axis.axhline(line, color="k", ls="--", lw=1, label=f"{line}x")
        axis.set_title(title, fontsize=9)
        axis.set_xticks([p + 0.4 - width / 2 for p in range(len(graphs))], graphs,
                        rotation=20, fontsize=8)
        axis.legend(fontsize=7)
    figure.tight_layout()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--quick", action="store_true", help="small graphs, for a smoke run")
    parser.add_argument("--scatter", choices=("auto", "both"), default="auto")
    parser.add_argument("--no-scatter", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--child", choices=("timing", "memory"), help=argparse.SUPPRESS)
    parser.add_argument("--layer", help=argparse.SUPPRESS)
    parser.add_argument("--graph", help=argparse.SUPPRESS)
    parser.add_argument("--input", choices=INPUTS, help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.no_scatter:
        _block_torch_scatter()
    if args.child:
        import torch

        torch.manual_seed(0)
        print(json.dumps(child_timing(args) if args.child == "timing" else child_memory(args)))
        return

    sys.path.insert(0, str(BENCHMARKS))
    from common import machine_info, write_results

    rounds = 2
    timing_runs = [run_child(args, "--child", "timing") for _ in range(rounds)]
    times = summarise(merge(timing_runs))
    graphs = list(dict.fromkeys(key.split("/")[0] for key in times))

    memory = {}
    for graph_name in graphs:
        for style in INPUTS:
            peaks = {name: run_child(args, "--child", "memory", "--layer", name, "--graph",
                                     graph_name, "--input", style)["peak_bytes"]
                     for name in LAYERS}
            memory[f"{graph_name}/{style}"] = {
                name: {"peak_mib": peak / 2**20, "ratio_to_GATConv": peak / peaks["GATConv"]}
                for name, peak in peaks.items()}

    scatter = None
    if args.scatter == "both":
        import importlib.util

        if importlib.util.find_spec("torch_scatter") is None:
            parser.error("--scatter both needs torch-scatter installed (extra 'scatter')")
        with_runs, without_runs = [], []
        for _ in range(rounds):  # alternate the two settings
            with_runs.append(run_child(args, "--child", "timing"))
            without_runs.append(run_child(args, "--child", "timing", env_scatter=False))
        with_t, without_t = summarise(merge(with_runs)), summarise(merge(without_runs))
        key = "{}/tensor/forward_backward"
        scatter = {f"{name} fwd+bwd": {g: with_t[key.format(g)][name]["median_ms"] /
                                       without_t[key.format(g)][name]["median_ms"]
                                       for g in graphs} for name in ("GATConv", "FCAConv")}

    payload = {"machine": machine_info(), "channels": CHANNELS, "heads": HEADS,
               "out_channels": OUT, "repeats_per_round": args.repeats, "rounds": rounds,
               "graphs": {name: {"nodes": int(g.num_nodes), "edges": int(g.num_edges)}
                          for name, g in build_graphs(args.quick).items()},
               "time": times, "peak_memory": memory,
               "torch_scatter_time_ratio": scatter,
               "targets": {"time_ratio_max": 1.25, "memory_ratio_max": 1.3}}
    path = write_results("bench_fca" + ("_quick" if args.quick else ""), payload,
                         plot(times, memory, scatter))
    print(f"{'graph / input / measure':<46}" + "".join(f"{n:>22}" for n in LAYERS))
    for key, row in times.items():
        print(f"{key:<46}" + "".join(
            f"{row[n]['median_ms']:>12.1f} ms {row[n]['ratio_to_GATConv']:>5.2f}x" for n in LAYERS))
    for key, row in memory.items():
        print(f"{key + '/peak memory':<46}" + "".join(
            f"{row[n]['peak_mib']:>11.1f} MiB {row[n]['ratio_to_GATConv']:>5.2f}x" for n in LAYERS))
    if scatter:
        for name, row in scatter.items():
            print(f"torch-scatter/native {name}: " +
                  ", ".join(f"{g} {r:.2f}x" for g, r in row.items()))
    print(f"wrote {path} and its .png")


if __name__ == "__main__":
    main()
