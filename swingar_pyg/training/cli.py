"""``swingar fit | validate | test | predict -c CONFIG``: Lightning's CLI over
:class:`SwinGarModule` and :class:`~datamodules.SwinGarDataModule`."""

from __future__ import annotations

import sys
from unittest import mock

from lightning.pytorch.cli import LightningCLI

from datamodules import SwinGarDataModule
from swingar_pyg.training.module import SwinGarModule

LIGHTNING_COMMANDS = ("fit", "validate", "test", "predict")


def build_cli(argv: list[str], run: bool = True) -> LightningCLI:
    """Lightning's CLI; configs use ``class_path``/``init_args`` for the
    estimator, callbacks and loggers. With ``run=True`` the first argument is
    the subcommand."""
    # Lightning reads sys.argv unless given args, and warns when both are set
    # (always, under `swingar quickstart` or pytest); so the args become argv.
    with mock.patch.object(sys, "argv", [sys.argv[0], *argv]):
        return LightningCLI(SwinGarModule, SwinGarDataModule, seed_everything_default=0,
                            save_config_kwargs={"overwrite": True}, run=run)
