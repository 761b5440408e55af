"""``swingar ship-weights``: a trained checkpoint becomes weights inside the
package (``swingar_pyg/weights/<name>.pt``) with a model card beside them
(``<name>.json``, and ``<name>.md`` for people). Shipped weights can be
exported again with another clearance gate; their card's provenance carries over.

The card records what the network was trained on (the data config, its
sequences, the simulator revision), how (the training arguments, the step),
and what it measured on the test split and on extra test splits: per garment
family, the streamed estimator's mean and p95 vertex error against rigid
skinning's. It also records the figures of a **check slice**, a one-sequence
dataset recipe small enough to simulate in a unit test, so a test can
re-measure the shipped weights and compare (``tests/test_shipped_model.py``).
"""

from __future__ import annotations

import json
import os
import tempfile
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path

import torch
import yaml
from torch import Tensor

from swingar_pyg.eval.error_vs_time import (
    StoredSequences,
    TestSequence,
    evaluate_estimator,
    evaluate_rigid,
    load_test_sequences,
)
from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.models.pretrained import WEIGHTS_DIR, read_weights, weights_path, weights_sha256
from swingar_pyg.sim import SIMULATOR_REVISION
from swingar_pyg.training import (
    error_stats,
    export_weights,
    garment_family,
    load_pretrained,
    write_exported_weights,
)
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.dataset import DatasetConfig, make_dataset
from swingar_pyg.world.sequence_file import simulator_revisions

# An unseen skirt (not in the base data) on an unseen motion, 2 s: about a minute to
# simulate and measure on one core.
CHECK_SLICE = {
    "name": "check-slice", "seconds": 2.0, "fps": 30,
    "solver": {"substeps": 100, "iterations": 1, "max_substeps": 400, "backend": "warp",
               "bend_every": 10},
    "body_shapes": [[0.5, 0.5, 0.5, 0.5, 0.5, 0.5]],
    "splits": {"test": {"garments": [{"length": 0.55, "flare": 0.45, "vertices": 700,
                                      "jitter": 0.3, "seed": 901}],
                        "motions": [{"kind": "kick", "amplitude": 0.7}]}},
}


def family_figures(estimator: dict[str, Tensor], rigid: dict[str, Tensor],
                   families: dict[str, str]) -> dict:
    """Per garment family and over all: the estimator's and rigid skinning's mean
    and p95 error (mm), and their ratios (estimator / rigid; below 1 is better).
    ``estimator`` and ``rigid`` map each sequence id to its errors ``(T, N)`` (mm),
    ``families`` to its garment family."""
    grouped: dict[str, list[str]] = defaultdict(list)
    for sequence_id, family in families.items():
        grouped[family].append(sequence_id)

    def row(ids: list[str]) -> dict:
        mine, base = (error_stats(torch.cat([errors[i].reshape(-1) for i in ids]))
                      for errors in (estimator, rigid))
        return {"sequences": len(ids),
                "estimator_mean_mm": mine["mean_mm"], "estimator_p95_mm": mine["p95_mm"],
                "rigid_mean_mm": base["mean_mm"], "rigid_p95_mm": base["p95_mm"],
                "mean_ratio": mine["mean_mm"] / base["mean_mm"],
                "p95_ratio": mine["p95_mm"] / base["p95_mm"]}

    return {"all": row(list(families)),
            **{family: row(ids) for family, ids in sorted(grouped.items())}}


def measure(estimator: SwinGarEstimator, data_settings: dict,
            sequences: Iterable[TestSequence], progress: bool = True) -> dict:
    """:func:`family_figures` of the estimator streamed in fp32 and of rigid skinning
    over ``sequences``, taken one at a time (a :class:`StoredSequences` keeps one in
    memory)."""
    streamed, rigid, families = {}, {}, {}
    if progress:
        from tqdm import tqdm

        sequences = tqdm(sequences, desc="estimator and rigid skinning", unit="sequence")
    for s in sequences:
        streamed.update(evaluate_estimator("estimator", estimator, [s], data_settings["sigma"],
                                           data_settings["seed"]).errors)
        rigid.update(evaluate_rigid([s]).errors)
        families[s.id] = garment_family(s.garment.name)
    return family_figures(streamed, rigid, families)


def check_slice_figures(estimator: SwinGarEstimator, data_settings: dict, body=None,
                        recipe: dict | None = None, progress: bool = False) -> dict:
    """Simulates the check slice (:data:`CHECK_SLICE`) in a temporary folder and
    measures the estimator on it (:func:`measure`)."""
    body = body or AnnyBody()
    with tempfile.TemporaryDirectory(prefix="swingar-check-") as folder:
        config_path = Path(folder) / "check.yaml"
        config_path.write_text(yaml.safe_dump({**(recipe or CHECK_SLICE),
                                               "output": str(Path(folder) / "data")}))
        config = DatasetConfig.from_yaml(config_path)
        make_dataset(config, progress=progress)
        sequences = load_test_sequences(Path(config.output) / "test.h5", body)
        return measure(estimator, data_settings, sequences, progress)


def check_weights_name(name: str) -> str:
    """A weights name is a file stem: no folders, no suffix."""
    if not name or Path(name).name != name or name.endswith((".pt", ".json", ".md")):
        raise ValueError(f"a weights name is a bare file stem like 'mine', got {name!r}")
    return name


def labelled_configs(items: list[str], option: str) -> dict[str, str]:
    """``{label: dataset config}`` of command-line ``LABEL=CONFIG`` items given to ``option``."""
    configs = {}
    for item in items:
        label, sep, config = item.partition("=")
        if not sep or not label or not config:
            raise ValueError(f"{option} takes LABEL=CONFIG, got {item!r}")
        configs[label] = config
    return configs


def made_split(config_path: str | Path, split: str = "test") -> tuple[DatasetConfig, Path]:
    """A dataset config and the file of one of its splits; raises ``ValueError`` if
    the config, the split or its file is missing (this never starts a simulation)."""
    if not Path(config_path).is_file():
        raise ValueError(f"no dataset config at {config_path}")
    config = DatasetConfig.from_yaml(config_path)
    if split not in config.blocks:
        raise ValueError(f"{config_path} has no {split!r} split (it has "
                         f"{', '.join(config.blocks) or 'none'})")
    path = Path(config.output) / f"{split}.h5"
    if not path.exists():
        raise ValueError(f"no {split} split at {path}; make it first with `swingar make-dataset "
                         f"-c {config_path}` (it simulates every split of the config)")
    return config, path


def reexport_weights(weights: str | Path, out: str | Path, settings: dict | None = None) -> dict:
    """Writes shipped ``weights`` (a name or a ``.pt`` file with its card
    ``<name>.json`` beside it) again with their
    :data:`~swingar_pyg.training.checkpoints.EXPORT_SETTINGS` replaced by
    ``settings``: the gate of a trained network set anew without its checkpoint.
    Returns what :func:`~swingar_pyg.training.export_weights` returns, with the
    training provenance (checkpoint, command) taken from the card, which must name
    these weights by sha256, and the weights it was exported from."""
    path = weights_path(weights)
    record = read_weights(path)
    card_path = path.with_suffix(".json")
    if not card_path.is_file():
        raise ValueError(f"no model card {card_path} beside {path}: its training provenance "
                         "is unknown; export its checkpoint with --ckpt instead")
    card = json.loads(card_path.read_text())
    if card.get("sha256") != weights_sha256(path):
        raise ValueError(f"{card_path} describes other weights than {path} (sha256 differs)")
    if not isinstance(card.get("training"), dict):
        raise ValueError(f"{card_path} holds no training provenance; is it a model card?")
    arguments = write_exported_weights(out, record["estimator"], settings, record["state_dict"],
                                       record["data"])
    training = card["training"]
    return {"estimator": arguments, "data": record["data"], "training": training["module"],
            "datamodule": training["datamodule"], "step": training["step"],
            "checkpoint": training["checkpoint"], "command": training["command"],
            "set_at_export": {**card.get("set_at_export", {}), **(settings or {})},
            "exported_from": {"weights": path.name, "sha256": card["sha256"]}}


def ship_weights(checkpoint: str | Path | None, name: str, dataset: str | Path,
                 extra_tests: dict[str, str] | None = None, command: str | None = None,
                 out_dir: str | Path = WEIGHTS_DIR, check_slice: dict = CHECK_SLICE,
                 progress: bool = True, settings: dict | None = None,
                 weights: str | Path | None = None) -> Path:
    """Exports ``checkpoint`` as ``<out_dir>/<name>.pt`` (with the estimator
    ``settings`` of :func:`~swingar_pyg.training.export_weights`), or instead shipped
    ``weights`` (re-exported by :func:`reexport_weights`), measures it on the test
    split of ``dataset`` (the config it was trained on), on each of ``extra_tests``
    (``{label: dataset config}``) and on ``check_slice`` (a dataset recipe with one
    test split), and writes the card ``<name>.json`` and ``<name>.md``. Returns
    the card's path.

    Every config and test split is read before anything is written, and the three
    files are moved into place only once all is measured: a failure leaves the
    folder as it was."""
    check_weights_name(name)
    if (checkpoint is None) == (weights is None):
        raise ValueError("ship a checkpoint or weights, exactly one of the two")
    out_dir = Path(out_dir)
    body = AnnyBody()
    config, test_path = made_split(dataset)
    extra_paths = {label: made_split(path)[1]
                   for label, path in (extra_tests or {}).items()}
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out_dir, prefix=f".{name}-") as staging:
        staged = Path(staging)
        if weights is None:
            provenance = {**export_weights(checkpoint, staged / f"{name}.pt", settings),
                          "checkpoint": str(checkpoint), "command": None,
                          "exported_from": None}
        else:
            provenance = reexport_weights(weights, staged / f"{name}.pt", settings)
        trained_on = provenance["datamodule"].get("config")
        if trained_on is not None and Path(trained_on).resolve() != Path(dataset).resolve():
            raise ValueError(f"{checkpoint or weights} was trained on {trained_on}, not "
                             f"{dataset}: measure it on the test split of its own data")
        estimator, data_settings = load_pretrained(staged / f"{name}.pt")
        figures = {"test": measure(estimator, data_settings, StoredSequences(test_path, body),
                                   progress)}
        for label, path in extra_paths.items():
            figures[label] = measure(estimator, data_settings, StoredSequences(path, body),
                                     progress)
        check = check_slice_figures(estimator, data_settings, body, check_slice, progress)
        card = {
            "name": name, "weights": f"{name}.pt",
            "sha256": weights_sha256(staged / f"{name}.pt"),
            "parameters": sum(p.numel() for p in estimator.parameters()),
            "estimator": provenance["estimator"],
            "set_at_export": provenance["set_at_export"],
            "descriptor": provenance["data"],
            "data": {"config": str(dataset), "name": config.name,
                     "simulator_revisions": sorted(simulator_revisions(test_path)),
                     "solver": {k: getattr(config.solver, k) for k in
                                ("substeps", "iterations", "max_substeps", "backend",
                                 "bend_every")},
                     "garments": {split: len(g) for split, g in config.garments.items()},
                     "motions": {split: [m.kind for m in ms]
                                 for split, ms in config.motions.items()},
                     "body_shapes": len(config.body_shapes)},
            "training": {"command": command or provenance["command"],
                         "checkpoint": provenance["checkpoint"],
                         "step": provenance["step"], "module": provenance["training"],
                         "datamodule": provenance["datamodule"]},
            **({"exported_from": provenance["exported_from"]}
               if provenance["exported_from"] else {}),
            "figures": figures,
            "check_slice": {"recipe": check_slice, "simulator_revision": SIMULATOR_REVISION,
                            "figures": check},
            "torch": torch.__version__,
        }
        (staged / f"{name}.json").write_text(json.dumps(card, indent=2, default=str) + "\n")
        (staged / f"{name}.md").write_text(card_markdown(card))
        for suffix in (".pt", ".json", ".md"):
            os.replace(staged / f"{name}{suffix}", out_dir / f"{name}{suffix}")
    return out_dir / f"{name}.json"


def _figure_table(figures: dict) -> list[str]:
    lines = ["| family | sequences | estimator mean / p95 (mm) | rigid mean / p95 (mm) "
             "| ratio mean / p95 |", "| --- | --- | --- | --- | --- |"]
    for family, row in figures.items():
        lines.append(f"| {family} | {row['sequences']} | {row['estimator_mean_mm']:.1f} / "
                     f"{row['estimator_p95_mm']:.1f} | {row['rigid_mean_mm']:.1f} / "
                     f"{row['rigid_p95_mm']:.1f} | {row['mean_ratio']:.2f} / "
                     f"{row['p95_ratio']:.2f} |")
    return lines


def card_markdown(card: dict) -> str:
    """The card for people: the JSON's figures as tables, and how to reproduce them."""
    data, training = card["data"], card["training"]
    lines = [
        f"# Model card: `{card['name']}`", "",
        f"`SwinGarEstimator.from_pretrained(\"{card['name']}\")`, or `swingar predict` without "
        f"`--ckpt`. Weights `{card['weights']}` (sha256 `{card['sha256'][:16]}…`), "
        f"{card['parameters']:,} parameters; generated by `swingar ship-weights` from "
        f"`{card['name']}.json`, which holds every figure below.", "",
        "## Network", "",
        "```json", json.dumps(card["estimator"], indent=1), "```", "",
        *([f"Set on the trained network at export: `{json.dumps(card['set_at_export'])}`.", ""]
          if card.get("set_at_export") else []),
        *([f"Exported again from `{card['exported_from']['weights']}` (sha256 "
           f"`{card['exported_from']['sha256'][:16]}…`), the same network.", ""]
          if card.get("exported_from") else []),
        f"Descriptor: sigma {card['descriptor']['sigma']}, seed {card['descriptor']['seed']}.", "",
        "## Training data", "",
        f"`{data['config']}` (test split made by simulator revision(s) "
        f"{data['simulator_revisions']}, solver "
        f"{data['solver']}): garments per split {data['garments']}, "
        f"{data['body_shapes']} body shapes, motions per split:", "",
        *[f"- {split}: {', '.join(dict.fromkeys(kinds))}"
          for split, kinds in data["motions"].items()], "",
        "## Training", "",
        f"`{training['command']}`: checkpoint `{training['checkpoint']}`, step "
        f"{training['step']}, module arguments `{json.dumps(training['module'])}`.", "",
        "## Figures", "",
        "Per-vertex error at every frame, the estimator streamed one frame at a time in "
        "fp32 without the collision pass, against rigid skinning with the weights "
        "transferred from the body. Ratios below 1 beat skinning.", ""]
    for label, figures in card["figures"].items():
        lines += [f"### {label}", "", *_figure_table(figures), ""]
    lines += ["### Check slice", "",
              "One unseen sequence re-simulated and re-measured by `tests/test_shipped_model.py`:",
              "", *_figure_table(card["check_slice"]["figures"]), ""]
    return "\n".join(lines)
