"""How far trained attention is from the plain mean over a vertex's neighbours.

For every attention layer of the garment encoder :math:`M_g`, on garments of each family on
the default body, the weight of each edge times its destination's in-degree,
:math:`d_i \\alpha_{i,j}`, is 1 everywhere for mean aggregation. FCA bounds it to
:math:`[e^{-(1+s)\\alpha}, e^{(1+s)\\alpha}]`; GAT does not bound it. Reported per weights file
and layer: quantiles of :math:`d_i \\alpha_{i,j}` and the mean normalised entropy of each
vertex's weights (1 for the mean). If trained FCA and GAT weights both stay near the mean,
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

from swingar_pyg.inference.prediction import garment_graph
from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.models.pretrained import read_weights
from swingar_pyg.nn import attention_edge_index
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.catalogue import fit_garment, garment_spec

# one unseen garment of each family of the base test split
GARMENTS = {
    "skirt": {"length": 0.50, "flare": 0.30, "vertices": 1500},
    "dress": {"kind": "dress", "length": 1.00, "flare": 0.25, "vertices": 1800},
    "t-shirt": {"kind": "tshirt", "length": 0.92, "sleeve": 0.3, "flare": 0.18,
                "vertices": 1900},
    "sport top": {"kind": "shipped", "name": "sport_top", "merge_edges_below": 0.5},
}
QUANTILES = (0.01, 0.05, 0.5, 0.95, 0.99)


@torch.no_grad()
def layer_spread(estimator: SwinGarEstimator, graph) -> list[dict]:
    """Per layer of ``estimator.garment_encoder``: quantiles of :math:`d_i \\alpha_{i,j}`
    over edges (heads averaged) and the mean normalised entropy per vertex."""
    edge_index = attention_edge_index(graph.edge_index, graph.num_nodes)
    x = torch.cat([graph.normal, graph.rest, graph.fit.unsqueeze(-1)], dim=-1)
    rows = []
    for layer in estimator.garment_encoder.layers:
        out, (edges, weights) = layer(x, edge_index, return_attention_weights=True)
        edges = torch.as_tensor(edges)
        weights = weights.mean(dim=-1).double()
        target = edges[1]
        in_degree = degree(target, graph.num_nodes, dtype=torch.float64)
        relative = weights * in_degree[target]
        entropy = scatter(-weights * weights.clamp_min(1e-300).log(), target,
                          dim_size=graph.num_nodes, reduce="sum")
        attending = in_degree > 1  # a vertex with only its self-loop has no choice to make
        normalised = entropy[attending] / in_degree[attending].log()
        rows.append({"relative_weight_quantiles": dict(zip(
            map(str, QUANTILES), torch.quantile(relative, torch.tensor(
                QUANTILES, dtype=torch.float64)).tolist())),
            "mean_normalised_entropy": float(normalised.mean())})
        x = F.elu(out)
    return rows


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
                          "normalize": record["estimator"]["normalize"], "garments": {}}
        for family, garment in garments.items():
            graph = garment_graph(garment, len(body.joint_names), estimator.descriptor_size,
                                  record["data"]["sigma"], record["data"]["seed"])
            rows = layer_spread(estimator, graph)
            figures[label]["garments"][family] = rows
            print(f"{label:>14} {family:>9}: " + "; ".join(
                f"layer {k}: d*a 1-99 % {r['relative_weight_quantiles']['0.01']:.2f}-"
                f"{r['relative_weight_quantiles']['0.99']:.2f}, entropy "
                f"{r['mean_normalised_entropy']:.3f}" for k, r in enumerate(rows)), flush=True)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    layers = len(next(iter(figures.values()))["garments"]["skirt"])
    figure, axes = plt.subplots(1, layers, figsize=(4.5 * layers, 3.5), squeeze=False)
    for k, axis in enumerate(axes[0]):
        for i, (label, entry) in enumerate(figures.items()):
            for j, family in enumerate(GARMENTS):
                q = entry["garments"][family][k]["relative_weight_quantiles"]
                position = i + 0.18 * (j - 1.5)
                axis.vlines(position, q["0.01"], q["0.99"], color=f"C{j}", lw=1)
                axis.vlines(position, q["0.05"], q["0.95"], color=f"C{j}", lw=4,
                            label=family if i == 0 else None)
                axis.plot(position, q["0.5"], "k_")
        axis.axhline(1.0, color="black", lw=0.8)
        axis.set_xticks(range(len(figures)), list(figures), rotation=30, ha="right")
        axis.set(yscale="log", title=f"M_g layer {k}",
                 ylabel="weight x in-degree (1 = mean)" if k == 0 else None)
        axis.grid(alpha=0.3, which="both")
    axes[0][0].legend(fontsize=7)
    write_results(args.name, {"machine": machine_info(), "garments": GARMENTS,
                              "figures": figures}, figure)


if __name__ == "__main__":
    main()
