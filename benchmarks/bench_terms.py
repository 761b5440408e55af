"""What each learned term of a trained estimator adds: its error per garment family with one
term switched off at a time, against rigid skinning, on a dataset's test split.

The estimator's output is

.. math::
    \\mathbf{M} = \\mathrm{LBS}(\\mathbf{M}^0 + \\mathbf{B}, \\boldsymbol\\theta,
        \\mathrm{softmax}(\\mathbf{L} + \\log \\mathbf{W}_0)) + \\mathbf{R}_c\\,\\mathbf{d},

with learned skinning logits :math:`\\mathbf{L}`, blend shapes :math:`\\mathbf{B}` and detail
correction :math:`\\mathbf{d}`. Each comes from a head whose last layer starts at zero, so
zeroing that layer switches the term off; with all three off an estimator trained with the
skinning prior is rigid skinning with the weights :math:`\\mathbf{W}_0` transferred from the
body (each row also carries the baseline's figures, to compare). A term that helps on the
training families but hurts a family shows as a variant that beats the full model there.

    python benchmarks/bench_terms.py --weights base --data configs/data/base.yaml \\
        --extra-test "overall=configs/data/jumpsuit.yaml" --stride 4
"""

from __future__ import annotations

import argparse
import copy

import torch
from common import clearance_gate, machine_info, write_results

from swingar_pyg.eval.error_vs_time import load_test_sequences
from swingar_pyg.eval.model_card import labelled_configs, made_split, measure
from swingar_pyg.training import load_pretrained
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.sequence_file import sequence_ids

# variant -> the heads whose last layer is zeroed
VARIANTS = {
    "full": (),
    "no correction": ("correction",),
    "no blend shapes": ("blend_head",),
    "skinning weights only": ("correction", "blend_head"),
    "rigid (all off)": ("correction", "blend_head", "skinning_head"),
}


def switched_off(estimator: torch.nn.Module, heads: tuple[str, ...]) -> torch.nn.Module:
    """A copy of ``estimator`` with the last layer of each of ``heads`` set to zero."""
    variant = copy.deepcopy(estimator)
    for name in heads:
        head = getattr(variant, name)
        if head is None:
            raise ValueError(f"the estimator has no {name} (trained without it)")
        torch.nn.init.zeros_(head.weight)
        torch.nn.init.zeros_(head.bias)
    return variant


def split_sequences(config_path: str, body, stride: int, split: str = "test") -> list:
    """Every ``stride``-th sequence of a split of a dataset config (made beforehand by
    ``make-dataset``), in the order of their ids."""
    _, path = made_split(config_path, split)
    return load_test_sequences(path, body, ids=sequence_ids(path)[::stride])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--weights", default="base", help="a shipped name or a .pt file")
    parser.add_argument("--data", default="configs/data/base.yaml")
    parser.add_argument("--extra-test", action="append", default=[], metavar="LABEL=CONFIG",
                        help="another dataset config whose test split is measured")
    parser.add_argument("--stride", type=int, default=1,
                        help="every k-th sequence of each split (default: all)")
    parser.add_argument("--name", default="bench_terms")
    args = parser.parse_args()
    if args.stride < 1:
        raise ValueError(f"--stride must be >= 1, got {args.stride}")
    splits = {"test": args.data, **labelled_configs(args.extra_test, "--extra-test")}

    estimator, data_settings = load_pretrained(args.weights)
    body = AnnyBody()
    sequences = {label: split_sequences(config, body, args.stride)
                 for label, config in splits.items()}
    figures = {label: {variant: measure(switched_off(estimator, heads), data_settings, chosen)
                       for variant, heads in VARIANTS.items()}
               for label, chosen in sequences.items()}
    for label, by_variant in figures.items():
        for variant, rows in by_variant.items():
            print(f"{label:>10} {variant:>22}: " + ", ".join(
                f"{family} {row['estimator_mean_mm']:.1f} ({row['mean_ratio']:.2f})"
                for family, row in rows.items()))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(label, family) for label, by_variant in figures.items()
              for family in by_variant["full"]]
    figure, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 3.6), squeeze=False)
    for axis, (label, family) in zip(axes[0], panels):
        rows = figures[label]
        axis.bar(range(len(VARIANTS)), [rows[v][family]["estimator_mean_mm"] for v in VARIANTS],
                 color=["C0", "C1", "C2", "C3", "grey"])
        axis.set_xticks(range(len(VARIANTS)), list(VARIANTS), rotation=60, ha="right")
        axis.set(title=f"{label}: {family}", ylabel="mean vertex error (mm)")
        axis.grid(alpha=0.3, axis="y")
    write_results(args.name, {"machine": machine_info(), "weights": str(args.weights),
                              "clearance_gate": clearance_gate(estimator),
                              "splits": splits, "stride": args.stride,
                              "variants": {k: list(v) for k, v in VARIANTS.items()},
                              "figures": figures}, figure)


if __name__ == "__main__":
    main()
