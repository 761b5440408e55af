"""How large a trained estimator's blend shapes and detail correction are, and how much of
each is a fixed shift rather than motion, per garment family on a dataset's test split.

For every window of every ``stride``-th test sequence it takes, at the newest frame, the blend
shapes :math:`\\mathbf{B}` (rest frame) and the correction :math:`\\mathbf{M} - \\mathbf{M}_c`
(world frame) of each vertex, and reports per family the mean length of each and the mean
length of its change over the sequence, :math:`\\lVert \\mathbf{B}^t - \\bar{\\mathbf{B}}
\\rVert` with :math:`\\bar{\\mathbf{B}}` the sequence's time mean. A term much larger than its
change is a shift that does not follow the motion; two such terms of equal size that cancel
show in ``bench_terms.py`` as a large error when either is switched off.

    python benchmarks/term_sizes.py --weights base --data configs/data/base.yaml --stride 4
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import torch
from common import clearance_gate, machine_info, write_results
from torch_geometric.data import Batch

from datamodules import SwinGarDataModule
from swingar_pyg.training import garment_family, load_pretrained


def sequence_terms(estimator, dataset, stride: int) -> dict[int, dict[str, list]]:
    """Per test sequence (every ``stride``-th), the blend shapes and corrections
    ``(N, 3)`` at the newest frame of each of its windows."""
    terms: dict[int, dict[str, list]] = defaultdict(lambda: {"blend": [], "correction": []})
    for index, (sequence, _) in enumerate(dataset.windows):
        if sequence % stride:
            continue
        with torch.no_grad():
            output = estimator(Batch.from_data_list([dataset[index]]))
        terms[sequence]["blend"].append(output.blend[-1])
        terms[sequence]["correction"].append(output.vertices[-1] - output.skinned[-1])
    return terms


def family_sizes(terms: dict, dataset) -> dict[str, dict[str, float]]:
    """Per family: mean length (mm) of each term and of its change over a sequence."""
    sums: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for sequence, by_term in terms.items():
        family = garment_family(dataset.sequences[sequence].garment)
        for name, frames in by_term.items():
            stacked = torch.stack(frames)  # (T, N, 3)
            change = stacked - stacked.mean(dim=0)
            for group in ("all", family):
                sums[group][f"{name}_mm"].append(1e3 * stacked.norm(dim=-1).mean().item())
                sums[group][f"{name}_change_mm"].append(1e3 * change.norm(dim=-1).mean().item())
    return {group: {key: sum(values) / len(values) for key, values in columns.items()}
            | {"sequences": len(columns["blend_mm"])}
            for group, columns in sorted(sums.items())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--weights", default="base", help="a shipped name or a .pt file")
    parser.add_argument("--data", default="configs/data/base.yaml")
    parser.add_argument("--stride", type=int, default=4, help="every k-th test sequence")
    parser.add_argument("--name", default="term_sizes")
    args = parser.parse_args()
    if args.stride < 1:
        raise ValueError(f"--stride must be >= 1, got {args.stride}")
    estimator, settings = load_pretrained(args.weights)
    data = SwinGarDataModule(config=args.data, descriptor_size=estimator.descriptor_size,
                             history=estimator.history, sigma=settings["sigma"],
                             seed=settings["seed"], eval_stride=4)
    data.prepare_data()
    data.setup("test")
    dataset = data.test_dataloader().dataset
    sizes = family_sizes(sequence_terms(estimator, dataset, args.stride), dataset)
    for group, row in sizes.items():
        print(f"{group:>10}: " + ", ".join(f"{k} {v:.1f}" if isinstance(v, float) else f"{k} {v}"
                                           for k, v in row.items()))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = ("blend_mm", "blend_change_mm", "correction_mm", "correction_change_mm")
    figure, axis = plt.subplots(figsize=(8.5, 3.6))
    width = 0.8 / len(keys)
    for k, key in enumerate(keys):
        axis.bar([g + k * width for g in range(len(sizes))], [row[key] for row in sizes.values()],
                 width, label=key.removesuffix("_mm").replace("_", " "))
    axis.set_xticks([g + 0.4 - width / 2 for g in range(len(sizes))], list(sizes))
    axis.set(ylabel="mean length (mm)", title=f"learned offsets: {args.weights}")
    axis.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    axis.grid(alpha=0.3, axis="y")
    write_results(args.name, {"machine": machine_info(), "weights": str(args.weights),
                              "clearance_gate": clearance_gate(estimator),
                              "data": args.data, "stride": args.stride, "sizes": sizes}, figure)


if __name__ == "__main__":
    main()
