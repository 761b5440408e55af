"""Self-contained checkpoints for LightningModules that take a network."""

from __future__ import annotations

import inspect

import lightning as L
from lightning.pytorch.core.mixins.hparams_mixin import _given_hyperparameters


def save_hyperparameters_with_network(module: L.LightningModule, network: str) -> None:
    """Saves the init arguments of the ``__init__`` that calls this. Made by
    LightningCLI, they are the config (the network as ``class_path`` +
    ``init_args``), so ``load_from_checkpoint(path)`` rebuilds the network
    alone; made in Python, the ``network`` argument is a module, is left out,
    and must be passed when loading."""
    made_by_cli = _given_hyperparameters.get() is not None
    caller = inspect.currentframe().f_back
    module.save_hyperparameters(ignore=[] if made_by_cli else [network], frame=caller)
    config = module.hparams.get(network) if made_by_cli else None
    if isinstance(config, dict):
        # The CLI's config leaves out values linked into the network from elsewhere (the
        # estimator's descriptor_size and history come from the data): take them from it.
        instance = caller.f_locals[network]
        init_args = config.setdefault("init_args", {})
        for name in inspect.signature(type(instance).__init__).parameters:
            if name not in init_args and name != "self" and hasattr(instance, name):
                init_args[name] = getattr(instance, name)
