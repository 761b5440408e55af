"""How far trained attention is from the plain mean over a vertex's neighbours.

For every attention layer of the garment encoder :math:`M_g`, and for each gate of the detail
network :math:`M_d` (the four heads of its input maps and of its state maps, captured at the
last frame of a kick streamed on the default body), on garments of each family, the weight of
each edge times its destination's in-degree,
:math:`d_i \\alpha_{i,j}`, is 1 everywhere for mean aggregation. FCA bounds it to
:math:`[e^{-(1+s)\\alpha}, e^{(1+s)\\alpha}]`; GAT does not bound it. Reported per weights file
and layer: quantiles of :math:`d_i \\alpha_{i,j}` and the mean normalised entropy of each
vertex's weights (1 for the mean); :math:`M_g`'s heads are averaged, :math:`M_d`'s are
reported per gate. If trained FCA and GAT weights both stay near the mean,
their ablation rows cannot differ much whatever ``alpha`` is.

    python benchmarks/attention_spread.py benchmarks/results/ablations_base/alpha2.pt \\
        benchmarks/results/ablations_base/gat.pt benchmarks/results/ablations_base/alpha1.pt
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
import torch.nn.functional as F
from common import machine_info, write_results
from torch_geometric.utils import degree, scatter

from swingar_pyg.inference import SwinGarStream
from swingar_pyg.inference.prediction import garment_graph
from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.models.pretrained import read_weights
from swingar_pyg.nn import attention_edge_index
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.catalogue import fit_garment, garment_spec
from swingar_pyg.world.motion_library import make_motion

# one unseen garment of each family of the base test split
GARMENTS = {
    "skirt": {"length": 0.50, "flare": 0.30, "vertices": 1500},
    "dress": {"kind": "dress", "length": 1.00, "flare": 0.25, "vertices": 1800},
    "t-shirt": {"kind": "tshirt", "length": 0.92, "sleeve": 0.3, "flare": 0.18,
                "vertices": 1900},
    "sport top": {"kind": "shipped", "name": "sport_top", "merge_edges_below": 0.5},
}
QUANTILES = (0.01, 0.05, 0.5, 0.95, 0.99)
GATES = ("input", "forget", "cell", "output")  # the heads of M_d's maps, in FCALSTM's order
MOTION, FRAMES = "kick", 45


def spread(edges: torch.Tensor, weights: torch.Tensor, num_nodes: int) -> dict:
    """Quantiles of :math:`d_i \\alpha_{i,j}` over the edges ``(2, E)`` with ``weights`` ``(E,)``
    and the mean normalised entropy of each vertex's weights."""
    weights = weights.double()
    target = edges[1]
    in_degree = degree(target, num_nodes, dtype=torch.float64)
    relative = weights * in_degree[target]
    entropy = scatter(-weights * weights.clamp_min(1e-300).log(), target, dim_size=num_nodes,
                      reduce="sum")
    attending = in_degree > 1  # a vertex with only its self-loop has no choice to make
    normalised = entropy[attending] / in_degree[attending].log()
    return {"relative_weight_quantiles": dict(zip(map(str, QUANTILES), torch.quantile(
        relative, torch.tensor(QUANTILES, dtype=torch.float64)).tolist())),
        "mean_normalised_entropy": float(normalised.mean())}


@torch.no_grad()
def layer_spread(estimator: SwinGarEstimator, graph) -> list[dict]:
    """Per layer of ``estimator.garment_encoder``: :func:`spread` of its weights, heads
    averaged."""
    edge_index = attention_edge_index(graph.edge_index, graph.num_nodes)
    x = torch.cat([graph.normal, graph.rest, graph.fit.unsqueeze(-1)], dim=-1)
    rows = []
    for layer in estimator.garment_encoder.layers:
        out, (edges, weights) = layer(x, edge_index, return_attention_weights=True)
        rows.append(spread(torch.as_tensor(edges), weights.mean(dim=-1), graph.num_nodes))
        x = F.elu(out)
    return rows


@torch.no_grad()
def gate_spread(estimator: SwinGarEstimator, graph, body: AnnyBody,
                shape: torch.Tensor) -> dict[str, dict]:
    """Per map of ``estimator.detail`` (``input``, ``state``) and gate: :func:`spread` of its
    weights at the last of ``FRAMES`` frames of ``MOTION`` streamed through
    :class:`SwinGarStream` (the inputs each map last saw, captured by a forward pre-hook)."""
    motion = make_motion(MOTION, body, shape, seconds=FRAMES / 30.0)
    posed = body.pose(shape, motion.rotations, motion.translation)
    seen: dict[str, tuple] = {}
    maps = {"input": estimator.detail.input_maps, "state": estimator.detail.state_maps}
    hooks = [module.register_forward_pre_hook(
        lambda module, args, name=name: seen.__setitem__(name, args))
        for name, module in maps.items()]
    try:
        stream = SwinGarStream(estimator, graph, shape, motion.fps)
        for t in range(motion.num_frames):
            stream.step(motion.rotations[t], motion.translation[t], posed.joint_transforms[t],
                        posed.joint_positions[t])
    finally:
        for hook in hooks:
            hook.remove()
    rows = {}
    for name, module in maps.items():
        x, edge_index = seen[name][:2]
        _, (edges, weights) = module(x, edge_index, return_attention_weights=True)
        edges = torch.as_tensor(edges)
        rows[name] = {gate: spread(edges, weights[:, k], x.size(0))
                      for k, gate in enumerate(GATES)}
    return rows


def _summary(row: dict) -> str:
    q = row["relative_weight_quantiles"]
    return (f"d*a 1-99 % {q['0.01']:.2f}-{q['0.99']:.2f}, "
            f"entropy {row['mean_normalised_entropy']:.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("weights", nargs="+", help="weights files (.pt) or shipped names")
    parser.add_argument("--name", default="attention_spread")
    args = parser.parse_args()
    body = AnnyBody()
    shape = torch.full((6,), 0.5)
    garments = {family: fit_garment(garment_spec(entry), body, shape)
                for family, entry in GARMENTS.items()}
    figures = {}
    for source in args.weights:
        record = read_weights(source)
        estimator = SwinGarEstimator.from_weights(record)
        label = Path(source).stem
        figures[label] = {"alpha": record["estimator"]["alpha"],
                          "normalize": record["estimator"]["normalize"], "garments": {},
                          "detail_gates": {}}
        for family, garment in garments.items():
            graph = garment_graph(garment, len(body.joint_names), estimator.descriptor_size,
                                  record["data"]["sigma"], record["data"]["seed"])
            rows = layer_spread(estimator, graph)
            # a network without M_d (``detail=False``) has no gates to measure
            gates = {} if estimator.detail is None else gate_spread(estimator, graph, body,
                                                                     shape)
            figures[label]["garments"][family] = rows
            figures[label]["detail_gates"][family] = gates
            print(f"{label:>14} {family:>9}: " + "; ".join(
                f"M_g layer {k}: {_summary(r)}" for k, r in enumerate(rows)), flush=True)
            for name, per_gate in gates.items():
                print(f"{'':>25}M_d {name} maps: " + "; ".join(
                    f"{gate} {_summary(r)}" for gate, r in per_gate.items()), flush=True)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    layers = len(next(iter(figures.values()))["garments"]["skirt"])
    panels = [(f"M_g layer {k}", lambda entry, family, k=k: entry["garments"][family][k])
              for k in range(layers)]
    with_gates = all(entry["detail_gates"]["skirt"] for entry in figures.values())
    panels += [(f"M_d {name} maps, {gate} gate",
                lambda entry, family, name=name, gate=gate:
                entry["detail_gates"][family][name][gate])
               for name in ("input", "state") for gate in GATES if with_gates]
    columns = len(GATES)
    rows_ = -(-len(panels) // columns)
    figure, axes = plt.subplots(rows_, columns, figsize=(4.5 * columns, 3.8 * rows_),
                                squeeze=False, sharey=True)  # one scale: spreads compare
    for axis in axes.flat[len(panels):]:
        axis.set_visible(False)
    for axis, (title, row_of) in zip(axes.flat, panels):
        for i, (label, entry) in enumerate(figures.items()):
            for j, family in enumerate(GARMENTS):
                q = row_of(entry, family)["relative_weight_quantiles"]
                position = i + 0.18 * (j - 1.5)
                axis.vlines(position, q["0.01"], q["0.99"], color=f"C{j}", lw=1)
                axis.vlines(position, q["0.05"], q["0.95"], color=f"C{j}", lw=4,
                            label=family if i == 0 else None)
                axis.plot(position, q["0.5"], "k_")
        axis.axhline(1.0, color="black", lw=0.8)
        axis.set_xticks(range(len(figures)), list(figures), rotation=30, ha="right")
        axis.set(yscale="log", title=title)
        axis.grid(alpha=0.3, which="both")
    for axis in axes[:, 0]:
        axis.set_ylabel("weight x in-degree (1 = mean)")
    axes[0][0].legend(fontsize=7)
    figure.tight_layout()
    write_results(args.name, {"machine": machine_info(), "garments": GARMENTS,
                              "detail_motion": {"motion": MOTION, "frames": FRAMES},
                              "figures": figures}, figure)


if __name__ == "__main__":
    main()
