"""The clearance gate set on a trained estimator: its error per garment family against rigid
skinning for several gates, on a split of datasets (choose on the val splits, confirm on test).

Each learned term of vertex :math:`i` (skinning logits, blend shape, detail correction) is
scaled by

.. math::
    g_i = \\left(1 - e^{-\\max(c_i - c_0, 0) / d_0}\\right)\\left(1 - e^{-a_i / l_0}\\right),

with :math:`c_i` its rest clearance from the body, :math:`c_0` the clearance of cloth lying
on the body, :math:`d_0` the scale over which the terms fade in with room, :math:`a_i` the
cloth's length along the mesh to where it lies on the body and :math:`l_0` the scale over
which they fade in with it (``SwinGarEstimator(clearance_scale=d_0, contact_clearance=c_0,
anchor_scale=l_0)``, :mod:`swingar_pyg.models.clearance_gate`). The gate holds no
parameters, so one set of weights is measured under each gate: what close-fitting cloth gains
against what the free-swinging families lose. The base data's val split holds a skirt and a
t-shirt; ``configs/data/gate_val.yaml`` adds close-fitting tops and a loose jumpsuit that
appear in no other split, so the gate is chosen without the test garments:

    python benchmarks/bench_gate.py --weights base --split val --data configs/data/base.yaml \\
        --extra-data "close-fitting=configs/data/gate_val.yaml" \\
        --gates none 6:10 6:30 6:60 6:100
"""

from __future__ import annotations

import argparse
from pathlib import Path

from bench_terms import split_sequences
from common import machine_info, write_results

from swingar_pyg.eval.model_card import labelled_configs, measure
from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.models.pretrained import read_weights
from swingar_pyg.world.body import AnnyBody


def parse_gate(text: str) -> dict:
    """``none`` or ``C0:D0[:L0]`` (millimetres; ``-`` for no D0) → the estimator's gate
    arguments."""
    if text == "none":
        return {"clearance_scale": None, "contact_clearance": 0.0, "anchor_scale": None}
    parts = text.split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        contact, scale, anchor = (parts + ["-"])[:3]
        gate = {"clearance_scale": None if scale == "-" else float(scale) / 1000,
                "contact_clearance": float(contact) / 1000,
                "anchor_scale": None if anchor == "-" else float(anchor) / 1000}
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'none' or C0:D0[:L0] in millimetres ('-' for none), got {text!r}"
        ) from None
    if gate["clearance_scale"] is None and gate["anchor_scale"] is None:
        raise argparse.ArgumentTypeError(f"{text!r} sets no scale: write 'none'")
    return gate


def gate_label(gate: dict) -> str:
    """The inverse of :func:`parse_gate`."""
    if gate["clearance_scale"] is None and gate.get("anchor_scale") is None:
        return "none"
    scales = [gate["clearance_scale"], gate.get("anchor_scale")]
    text = ":".join("-" if v is None else f"{1000 * v:g}"
                    for v in [gate["contact_clearance"]] + scales)
    return text.removesuffix(":-")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--weights", default="base", help="a shipped name or a .pt file")
    parser.add_argument("--data", default="configs/data/base.yaml")
    parser.add_argument("--split", default="test", choices=["val", "test"],
                        help="the split measured of every dataset: val to choose a gate, test "
                             "to confirm it (default: test)")
    parser.add_argument("--extra-data", "--extra-test", action="append", default=[],
                        metavar="LABEL=CONFIG",
                        help="another dataset config whose split is measured")
    parser.add_argument("--stride", type=int, default=1,
                        help="every k-th sequence of each split (default: all)")
    parser.add_argument("--gates", nargs="+", type=parse_gate,
                        default=[parse_gate(g) for g in ("none", "6:10", "6:30")],
                        help="'none' or C0:D0[:L0] in mm: the contact clearance, the clearance "
                             "scale and the anchor scale ('-' leaves a scale out)")
    parser.add_argument("--name", default="bench_gate")
    args = parser.parse_args()
    if args.stride < 1:
        parser.error(f"--stride must be >= 1, got {args.stride}")
    splits = {"data": args.data, **labelled_configs(args.extra_data, "--extra-data")}
    record = read_weights(args.weights)
    try:  # a bad gate fails here, before the test splits load
        estimators = {gate_label(gate): SwinGarEstimator.from_weights(
            {**record, "estimator": {**record["estimator"], **gate}}) for gate in args.gates}
    except ValueError as error:
        parser.error(str(error))

    body = AnnyBody()
    try:
        sequences = {label: split_sequences(config, body, args.stride, args.split)
                     for label, config in splits.items()}
    except ValueError as error:
        parser.error(str(error))
    figures = {}
    for text, estimator in estimators.items():
        figures[text] = {label: measure(estimator, record["data"], chosen)
                         for label, chosen in sequences.items()}
        for label, rows in figures[text].items():
            print(f"{text:>6} {label:>10}: " + ", ".join(
                f"{family} {row['estimator_mean_mm']:.1f} ({row['mean_ratio']:.2f} / "
                f"{row['p95_ratio']:.2f})" for family, row in rows.items()), flush=True)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gates = list(figures)
    panels = [(label, family) for label, rows in figures[gates[0]].items() for family in rows]
    figure, axis = plt.subplots(figsize=(1.2 * len(gates) + 3, 4))
    for label, family in panels:
        axis.plot(range(len(gates)), [figures[g][label][family]["mean_ratio"] for g in gates],
                  marker="o", label=family if label == "data" else f"{label}: {family}")
    axis.axhline(1.0, color="black", lw=0.8)
    axis.set_xticks(range(len(gates)), gates, rotation=30, ha="right")
    axis.set(yscale="log", ylabel="mean error / rigid skinning's",
             title=f"clearance gate on {Path(args.weights).name}, {args.split} splits "
                   "(c0:d0[:l0] in mm)")
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize=7, loc="upper right")
    write_results(args.name, {"machine": machine_info(), "weights": str(args.weights),
                              "split": args.split, "datasets": splits, "stride": args.stride,
                              "gates": {gate_label(g): g for g in args.gates},
                              "figures": figures}, figure)


if __name__ == "__main__":
    main()
