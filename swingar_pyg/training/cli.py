"""``swingar fit | validate | test | predict -c CONFIG``: Lightning's CLI over
any LightningModule and LightningDataModule a config names (``model:`` and
``data:`` with ``class_path`` and ``init_args``): the estimator's
(:class:`SwinGarModule`, :class:`~datamodules.SwinGarDataModule`) or the body
SDF's (:class:`BodySDFModule`, :class:`~datamodules.BodySDFDataModule`)."""

from __future__ import annotations

import sys
from unittest import mock

import lightning as L
from jsonargparse import Namespace
from lightning.pytorch.callbacks import ModelCheckpoint
from lightning.pytorch.cli import LightningArgumentParser, LightningCLI


class LastStepCheckpoint(ModelCheckpoint):
    """A :class:`ModelCheckpoint` whose ``last.ckpt`` always holds the latest
    validated step and, at the end, the final step.

    Lightning 2.6 rewrites ``last`` at a validation only when that validation also
    saved a top-k checkpoint (a new best), and at the end of training only if it never
    wrote one: a run killed after its validation error stopped falling resumed from its
    last best, and a finished run's ``last.ckpt`` could be steps short of ``max_steps``."""

    def _catch_up_last(self, trainer: L.Trainer) -> None:
        if self.save_last and not self._should_skip_saving_checkpoint(trainer):
            self._save_last_checkpoint(trainer, self._monitor_candidates(trainer))

    def on_validation_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        super().on_validation_end(trainer, pl_module)
        if not self._should_save_on_train_epoch_end(trainer):
            self._catch_up_last(trainer)

    def on_train_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._catch_up_last(trainer)
        super().on_train_end(trainer, pl_module)


class SwinGarCLI(LightningCLI):
    """Adds a ``checkpoint:`` section (a :class:`LastStepCheckpoint`) whose folder
    is ``<trainer.default_root_dir>/checkpoints``, and logs to CSV under
    ``<trainer.default_root_dir>/logs`` unless the config names a logger, so a
    config that changes the run's folder (an ablation) moves everything with it."""

    def add_arguments_to_parser(self, parser: LightningArgumentParser) -> None:
        parser.add_lightning_class_args(LastStepCheckpoint, "checkpoint")
        parser.link_arguments("trainer.default_root_dir", "checkpoint.dirpath",
                              compute_fn=lambda root: f"{root}/checkpoints")
        for name in ("descriptor_size", "history"):
            parser.link_arguments(f"data.init_args.{name}",
                                  f"model.init_args.estimator.init_args.{name}")

    def before_instantiate_classes(self) -> None:
        config = self.config[self.subcommand] if self.subcommand else self.config
        if config.trainer.logger in (None, True):
            config.trainer.logger = Namespace(
                class_path="lightning.pytorch.loggers.CSVLogger",
                init_args=Namespace(save_dir=config.trainer.default_root_dir, name="logs"))


def build_cli(argv: list[str], run: bool = True) -> LightningCLI:
    """Lightning's CLI; configs use ``class_path``/``init_args`` for the
    module, the datamodule, the networks, callbacks and loggers (a later config
    may set ``init_args`` alone, as the ablations do). With ``run=True`` the first argument is
    the subcommand."""
    # Lightning reads sys.argv unless given args, and warns when both are set
    # (always, under `swingar quickstart` or pytest); so the args become argv.
    with mock.patch.object(sys, "argv", [sys.argv[0], *argv]):
        return SwinGarCLI(L.LightningModule, L.LightningDataModule, subclass_mode_model=True,
                          subclass_mode_data=True, seed_everything_default=0,
                          save_config_kwargs={"overwrite": True}, run=run)
