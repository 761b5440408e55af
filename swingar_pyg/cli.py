"""The ``swingar`` command line. Each subcommand imports what it needs when it runs."""

from __future__ import annotations

import argparse
import sys

from swingar_pyg import __version__


def _demo(args: argparse.Namespace) -> int:
    from swingar_pyg.demo import run_demo

    run_demo(args.garment or None, z=args.z, sigma=args.sigma, alpha=args.alpha,
             device=args.device)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="swingar",
        description="SwinGar for PyTorch Geometric: learn how garments of any topology "
                    "swing on a moving body.")
    parser.add_argument("--version", action="version", version=f"swingar_pyg {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = commands.add_parser(
        "demo", help="graph, descriptor and FCAConv on the shipped garments, with timings")
    demo.add_argument("--garment", action="append", metavar="NAME",
                      help="a shipped garment (repeatable; default: all)")
    demo.add_argument("--z", type=int, default=256, help="descriptor length (default: 256)")
    demo.add_argument("--sigma", type=float, default=0.1,
                      help="descriptor kernel width in metres (default: 0.1)")
    demo.add_argument("--alpha", type=float, default=2.0, help="FCAConv alpha (default: 2.0)")
    demo.add_argument("--device", default=None, help="torch device (default: cuda if available)")
    demo.set_defaults(run=_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        return args.run(args)
    except ValueError as error:
        parser.exit(2, f"swingar {args.command}: error: {error}\n")


if __name__ == "__main__":
    sys.exit(main())
