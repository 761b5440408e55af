"""``swingar report -c configs/report/<name>.yaml``: error against run time,
ablations and the stability suite, measured in one run (or resumed with
``--resume``: :mod:`~swingar_pyg.eval.measurements`) and written to one folder
(Markdown, CSV, PNG, JSON).

The config names a test split (through its dataset config, generated if missing;
``extra_tests`` adds other test splits, e.g. a garment type never trained on, evaluated on
the first model), the trained models (each a stack of training configs and seeds, a
missing checkpoint trained first when ``train_missing``; or a weights file, e.g. the
shipped ``base``), the precisions and collision
passes to evaluate them with, the simulator settings to place against them, the garment
sizes to stream, and the stability suite's size. See ``configs/report/quickstart.yaml``.

With ``archive: <folder>`` each finished run of a config stack is also exported there as
a weights file (``<run folder name>.pt``, with a JSON record of its configs, seed and step)
and measured from it; a run with an archived file is never trained again, so a report of
many runs can be spread over machines that keep only the committed archive.
"""

from __future__ import annotations

import glob
import hashlib
import json
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from importlib import metadata
from pathlib import Path

import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.collision import NeuralCollisions
from swingar_pyg.eval.child_process import run_in_child
from swingar_pyg.eval.error_vs_time import (
    MethodResult,
    equal_error_speedup,
    evaluate_estimator,
    evaluate_rigid,
    evaluate_second_simulator,
    evaluate_simulator,
    load_test_sequences,
)
from swingar_pyg.eval.measurements import MeasurementStore, code_fingerprint, file_identity
from swingar_pyg.eval.report_writer import write_report
from swingar_pyg.eval.stability import FULL, SMALL, run_stability
from swingar_pyg.eval.stream_speed import stream_speed
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.models.pretrained import weights_path, weights_sha256
from swingar_pyg.training import export_weights, load_body_sdf, load_estimator, load_pretrained
from swingar_pyg.training.cli import build_cli
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.dataset import DatasetConfig, make_dataset


@dataclass(frozen=True)
class ModelSpec:
    """A trained estimator: its training configs (layered) and seeds, or instead
    ``weights`` (a shipped name or a ``.pt`` file of ``swingar ship-weights``,
    measured as is), and the collision passes to evaluate it with (``none``,
    ``exact``, ``neural``)."""

    name: str
    configs: tuple[str, ...]
    seeds: tuple[int, ...] = (0,)
    collisions: tuple[str, ...] = ("none",)
    weights: str | None = None

    @classmethod
    def from_entry(cls, entry: dict) -> "ModelSpec":
        """A ``models:`` entry of a report config; a ``weights`` entry must name
        an existing file."""
        name = entry["name"]
        if "configs" in entry and "weights" in entry:
            raise ValueError(f"model {name!r} names both configs and weights; a model is "
                             "either trained from configs or measured from weights")
        if "weights" not in entry:
            return cls(name, tuple(entry["configs"]), tuple(entry.get("seeds", (0,))),
                       tuple(entry.get("collisions", ("none",))))
        weights = entry["weights"]
        if not isinstance(weights, str) or not weights:
            raise ValueError(f"model {name!r}: weights must be a shipped name or a .pt path, "
                             f"got {weights!r}")
        weights_path(weights)
        if "seeds" in entry:
            raise ValueError(f"model {name!r} is measured from weights: it has no seeds")
        return cls(name, (), (0,), tuple(entry.get("collisions", ("none",))), weights)

    def load(self, seed: int, train_missing: bool, archive: str | None = None
             ) -> tuple[SwinGarEstimator, dict, str, str]:
        """The estimator of ``seed`` in eval mode, its descriptor settings, where
        it came from (a checkpoint, trained first if missing, its archived weights
        when ``archive`` is given, or the model's weights) and that file's sha256."""
        if self.weights is not None or archive is not None:
            path = (weights_path(self.weights) if self.weights is not None
                    else archived_run(self.configs, seed, train_missing, archive))
            digest = weights_sha256(path)
            return *load_pretrained(path), f"weights {path} (sha256 {digest[:12]}...)", digest
        checkpoint = ensure_checkpoint(self.configs, seed, train_missing)
        return *load_estimator(checkpoint), checkpoint, weights_sha256(checkpoint)


@dataclass(frozen=True)
class ReportConfig:
    name: str
    output: str
    dataset: str
    models: tuple[ModelSpec, ...]
    precisions: tuple[str, ...] = ("fp32",)
    body_sdf: tuple[str, ...] | None = None
    train_missing: bool = True
    # (substeps, iterations) or (substeps, iterations, max_substeps)
    simulator_settings: tuple[tuple[int, ...], ...] = ((5, 2), (10, 2), (20, 2), (50, 2))
    simulator_sequences: int = 4
    second_simulator: tuple[int, int] | None = None
    streaming_vertices: tuple[int, ...] = (1000, 5000, 20000)
    streaming_frames: int = 60
    streaming_compile: bool = False
    stability: str = "full"
    extra_tests: dict = field(default_factory=dict)
    test_sequences: int | None = None
    seeds_override: tuple[int, ...] | None = None
    archive: str | None = None

    @classmethod
    def from_yaml(cls, path: str | Path) -> "ReportConfig":
        import yaml

        raw = yaml.safe_load(Path(path).read_text())
        try:
            models = tuple(ModelSpec.from_entry(m) for m in raw["models"])
            simulator = raw.get("simulator", {})
            streaming = raw.get("streaming", {})
            config = cls(
                name=str(raw["name"]), output=str(raw["output"]), dataset=str(raw["dataset"]),
                models=models, precisions=tuple(raw.get("precisions", ("fp32",))),
                body_sdf=_stack(raw.get("body_sdf")),
                train_missing=bool(raw.get("train_missing", True)),
                simulator_settings=tuple(tuple(s) for s in simulator.get(
                    "settings", cls.simulator_settings)),
                simulator_sequences=int(simulator.get("sequences", cls.simulator_sequences)),
                second_simulator=(tuple(simulator["second"]) if simulator.get("second")
                                  else None),
                streaming_vertices=tuple(streaming.get("vertices", cls.streaming_vertices)),
                streaming_frames=int(streaming.get("frames", cls.streaming_frames)),
                streaming_compile=bool(streaming.get("compile", cls.streaming_compile)),
                stability=str(raw.get("stability", "full")),
                extra_tests=dict(raw.get("extra_tests", {})),
                test_sequences=raw.get("test_sequences"), archive=raw.get("archive"))
        except KeyError as missing:
            raise ValueError(f"{path}: the report config needs {missing}") from None
        except (TypeError, ValueError) as error:
            raise ValueError(f"{path}: {error}") from None
        for model in config.models:
            unknown = set(model.collisions) - {"none", "exact", "neural"}
            if unknown:
                raise ValueError(f"{path}: model {model.name!r} asks for collision passes "
                                 f"{sorted(unknown)}; use none, exact or neural")
            if "neural" in model.collisions and config.body_sdf is None:
                raise ValueError(f"{path}: model {model.name!r} asks for the neural collision "
                                 "pass but the report names no body_sdf config")
        for setting in config.simulator_settings:
            if len(setting) not in (2, 3):
                raise ValueError(f"{path}: a simulator setting is [substeps, iterations] or "
                                 f"[substeps, iterations, max_substeps], got {list(setting)}")
        unknown = set(config.precisions) - {"fp32", "bf16", "fp32-compiled"}
        if unknown:
            raise ValueError(f"{path}: precisions {sorted(unknown)} are unknown; use fp32, bf16 "
                             "or fp32-compiled")
        if config.stability not in ("full", "small", "off"):
            raise ValueError(f"{path}: stability must be full, small or off")
        return config

    def with_seeds(self, seeds: tuple[int, ...]) -> "ReportConfig":
        """The same report over ``seeds`` for every model trained from configs
        (``swingar report --seeds 0`` trains and measures one seed of each
        ablation); a model measured from weights has none."""
        if not seeds or any(seed < 0 for seed in seeds):
            raise ValueError(f"seeds must be non-negative integers, got {list(seeds)}")
        if all(m.weights for m in self.models):
            raise ValueError(f"report {self.name!r} measures weights only: it has no seeds "
                             "to replace")
        return replace(self, models=tuple(m if m.weights else replace(m, seeds=tuple(seeds))
                                          for m in self.models),
                       seeds_override=tuple(seeds))


def _stack(configs) -> tuple[str, ...] | None:
    if configs is None:
        return None
    return (configs,) if isinstance(configs, str) else tuple(configs)


# ------------------------------------------------------------------ checkpoints

def _parsed(configs: tuple[str, ...]) -> list[dict]:
    """Each YAML file of a config stack, parsed (an empty file as ``{}``)."""
    import yaml

    return [yaml.safe_load(Path(path).read_text()) or {} for path in configs]


def _last_set(parsed: list[dict], *keys: str):
    """The value at ``keys`` (e.g. ``"trainer", "max_steps"``) of the last
    config in a parsed stack that sets it, as the CLI layers them; ``None`` if
    none does."""
    value = None
    for config in parsed:
        node = config
        for key in keys[:-1]:
            node = node.get(key) or {}
        value = node.get(keys[-1], value)
    return value


def _run_folder(configs: tuple[str, ...], seed: int) -> tuple[Path, list[str]]:
    """The run folder of a training config stack at ``seed``, and the CLI
    arguments that train it there."""
    root = _last_set(_parsed(configs), "trainer", "default_root_dir")
    if root is None:
        raise ValueError(f"{' + '.join(configs)} names no trainer.default_root_dir")
    folder = Path(root) if seed == 0 else Path(f"{root}-seed{seed}")
    arguments = [a for path in configs for a in ("-c", path)]
    arguments += ["--seed_everything", str(seed), "--trainer.default_root_dir", str(folder)]
    return folder, arguments


def _best_checkpoint(folder: Path) -> str | None:
    found = sorted(glob.glob(str(folder / "checkpoints" / "best-*.ckpt")),
                   key=lambda p: Path(p).stat().st_mtime)
    return found[-1] if found else None


def ensure_checkpoint(configs: tuple[str, ...], seed: int, train_missing: bool) -> str:
    """The best checkpoint of a config stack and seed; a run that is missing or
    was cut off before its ``max_steps`` is trained first (resuming
    ``last.ckpt``) when ``train_missing``."""
    folder, arguments = _run_folder(configs, seed)
    last = folder / "checkpoints" / "last.ckpt"
    best = _best_checkpoint(folder)
    if best is not None and last.exists() and _finished(last, configs):
        return best
    if not train_missing:
        raise ValueError(f"no finished run under {folder}; train it with `swingar fit "
                         f"{' '.join(arguments)}` or set train_missing")
    # In a process of its own: a finished fit leaves its datamodule (the split in memory,
    # ~8 GB for the base data) referenced, so runs trained one after another in one
    # process would add up.
    exitcode = run_in_child(_fit, (arguments, str(last) if last.exists() else None))
    if exitcode != 0:
        raise RuntimeError(f"training under {folder} failed (exit code {exitcode}; "
                           f"its error is printed above): swingar fit {' '.join(arguments)}")
    if not (last.exists() and _finished(last, configs)):  # Lightning exits 0 on SIGTERM
        raise RuntimeError(f"training under {folder} stopped before its max_steps; run the "
                           "report again to resume it")
    best = _best_checkpoint(folder)
    if best is None:
        raise ValueError(f"training under {folder} wrote no best checkpoint")
    return best


def _fit(arguments: list[str], resume: str | None) -> None:
    cli = build_cli(arguments, run=False)
    cli.trainer.fit(cli.model, datamodule=cli.datamodule, ckpt_path=resume)


def archived_run(configs: tuple[str, ...], seed: int, train_missing: bool,
                 archive: str | Path) -> Path:
    """The weights file of a config stack and seed in ``archive``: exported from
    its finished run (trained first by :func:`ensure_checkpoint` when missing)
    unless the archive holds it already, with ``<name>.json`` beside it naming
    the configs, seed, checkpoint, step and its monitored validation figure.

    An archived run is refused when its configs, or the dataset config they
    name, have changed since (their parsed YAML: comments aside), when it is
    another config stack's run of the same folder name, or when its weights
    file is not the one its record names."""
    folder, _ = _run_folder(configs, seed)
    path = Path(archive) / f"{folder.name}.pt"
    record = path.with_suffix(".json")
    digest = _configs_sha256(configs)
    if path.is_file() and record.is_file():
        archived = json.loads(record.read_text())
        if archived.get("configs") != list(configs):
            raise ValueError(f"{path} holds the run of {' + '.join(archived.get('configs', []))}"
                             f", not of {' + '.join(configs)}: give this report an archive "
                             "of its own")
        if archived.get("configs_sha256") != digest:
            raise ValueError(f"{path} was trained from other settings than "
                             f"{' + '.join(configs)} and their dataset config now hold; "
                             f"delete {path} and {record} to train it again")
        if archived.get("weights_sha256") != weights_sha256(path):
            raise ValueError(f"{path} is not the weights file {record} names (its sha256 "
                             "differs); restore it or delete both to export it again")
        return path
    checkpoint = ensure_checkpoint(configs, seed, train_missing)
    exported = export_weights(checkpoint, path)
    with atomic_path(record) as tmp:  # written last: a record means a whole weights file
        Path(tmp).write_text(json.dumps(
            {"configs": list(configs), "seed": seed, "configs_sha256": digest,
             "checkpoint": Path(checkpoint).name, "step": exported["step"],
             "monitored": _best_score(checkpoint),
             "weights_sha256": weights_sha256(path)}, indent=1) + "\n")
    return path


def _best_score(checkpoint: str | Path) -> dict | None:
    """The monitored validation figure of a best checkpoint (e.g.
    ``{"val/estimator_mean_mm": 31.8}``), ``None`` if it was saved unmonitored."""
    saved = torch.load(checkpoint, map_location="cpu", weights_only=False)
    for key, state in saved.get("callbacks", {}).items():
        score = state.get("best_model_score") if isinstance(state, dict) else None
        if score is not None and "'monitor': '" in key:
            return {key.split("'monitor': '", 1)[1].split("'", 1)[0]: float(score)}
    return None


def _configs_sha256(configs: tuple[str, ...]) -> str:
    """sha256 of a config stack's parsed YAML and of the dataset config it
    trains on (``data.init_args.config``, the last one named)."""
    parsed = _parsed(configs)
    dataset = _last_set(parsed, "data", "init_args", "config")
    if dataset is not None:
        parsed += _parsed((dataset,))
    return hashlib.sha256(json.dumps(parsed, sort_keys=True).encode()).hexdigest()


def _finished(last: Path, configs: tuple[str, ...]) -> bool:
    """Whether the run of ``last.ckpt`` reached the configs' ``max_steps``."""
    steps = _last_set(_parsed(configs), "trainer", "max_steps")
    saved = torch.load(last, map_location="cpu", weights_only=False)
    return steps is None or steps < 0 or saved.get("global_step", 0) >= steps


# ------------------------------------------------------------------ the run

def _machine() -> dict:
    versions = {}
    for package in ("torch", "torch-geometric", "lightning", "numpy", "scipy", "trimesh",
                    "anny", "swingar-pyg"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = None
    return {"platform": platform.platform(), "processor": platform.processor() or
            platform.machine(), "torch_threads": torch.get_num_threads(),
            "python": platform.python_version(), "versions": versions,
            "date": time.strftime("%Y-%m-%d %H:%M:%S %Z")}


def _test_split(dataset: str) -> Path:
    config = DatasetConfig.from_yaml(dataset)
    path = Path(config.output) / "test.h5"
    if not path.exists():
        make_dataset(config, workers=2)
    return path


def train_runs(config: ReportConfig, log=print) -> list[str]:
    """Trains every run the config's models need, resuming those cut off, and
    measures nothing; returns their best checkpoints (their weights files when
    the config has an ``archive``). A report's training runs for hours; without
    the test split held beside it, several seeds can train side by side, and
    :func:`run_report` then reuses the finished runs."""
    trained = []
    for model in config.models:
        if model.weights is not None:
            continue
        for seed in model.seeds:
            log(f"training: {model.name}, seed {seed}")
            if config.archive is None:
                trained.append(ensure_checkpoint(model.configs, seed, train_missing=True))
            else:
                trained.append(str(archived_run(model.configs, seed, True, config.archive)))
    return trained


def run_report(config: ReportConfig, progress: bool = True, log=print,
               resume: bool = False) -> Path:
    """Measures everything the config asks for and writes the report folder;
    returns the path of ``report.md``.

    Each estimator measurement is also stored in ``<output>/measured/``
    (:class:`~swingar_pyg.eval.measurements.MeasurementStore`); with ``resume`` a
    measurement stored there by an earlier run of the report, of the same estimator
    on the same sequences with the same settings, is read back instead of measured
    again, and the report says which and when."""
    out = Path(config.output)
    started = time.perf_counter()
    body = AnnyBody()
    test_path = _test_split(config.dataset)
    sequences = load_test_sequences(test_path, body, config.test_sequences)
    log(f"test split {test_path}: {len(sequences)} sequences")
    store = MeasurementStore(out / "measured")
    machine = _machine()
    run_identity = {"test_split": file_identity(test_path), "sequences": [s.id for s in sequences],
                    "code": code_fingerprint(), "machine": {k: v for k, v in machine.items()
                                                            if k != "date"}}
    body_sdf, body_sdf_sha256 = None, None
    if config.body_sdf is not None and any("neural" in m.collisions for m in config.models):
        body_sdf_checkpoint = ensure_checkpoint(config.body_sdf, 0, config.train_missing)
        body_sdf = load_body_sdf(body_sdf_checkpoint)
        body_sdf_sha256 = weights_sha256(body_sdf_checkpoint)
    handlers: dict = {}

    def neural(shape):
        key = tuple(shape.tolist())
        if key not in handlers:
            handlers[key] = NeuralCollisions.for_body(body_sdf, body, shape)
        return handlers[key]

    results, checkpoints, per_model, first_seeds, resumed = [], {}, {}, {}, {}
    identities = []
    for model in config.models:
        for seed in model.seeds:
            estimator, data, source, digest = model.load(seed, config.train_missing,
                                                         config.archive)
            checkpoints[f"{model.name} (seed {seed})"] = source
            if seed == model.seeds[0]:
                first_seeds[model.name] = estimator, data
            sigma, descriptor_seed = data.get("sigma", DESCRIPTOR_SIGMA), data.get("seed", 0)
            # every precision without collision handling, the collision passes at the first
            variants = [(p, "none") for p in config.precisions if "none" in model.collisions]
            variants += [(config.precisions[0], c) for c in model.collisions if c != "none"]
            for precision, pass_ in variants:
                label = _label(model.name, precision, pass_)
                identities.append({
                    **run_identity, "label": label, "seed": seed,
                    "model_sha256": digest, "precision": precision,
                    "collisions": pass_, "sigma": sigma, "descriptor_seed": descriptor_seed,
                    "body_sdf_sha256": body_sdf_sha256 if pass_ == "neural" else None})
                collisions = {"none": None, "exact": "exact", "neural": neural}[pass_]
                log(f"estimator: {label}, seed {seed}")
                result = _stored_or_measured(
                    store, identities[-1], resume,
                    lambda: evaluate_estimator(label, estimator, sequences, sigma,
                                               descriptor_seed, precision, collisions, body),
                    {"model": model.name, "seed": seed, "collisions": pass_})
                if "measured_at" in result.extra:
                    resumed[f"{label} (seed {seed})"] = result.extra["measured_at"]
                    log(f"  read back: measured {result.extra['measured_at']}")
                if seed == model.seeds[0]:
                    results.append(result)
                per_model.setdefault(label, []).append(result)
    first_estimator = first_seeds[config.models[0].name][0] if config.models else None
    rigid = evaluate_rigid(sequences)
    log("simulator at other settings")
    chosen = _spread(sequences, config.simulator_sequences)
    simulator = [evaluate_simulator(chosen, substeps, iterations, body, *cap)
                 for substeps, iterations, *cap in config.simulator_settings]
    speedups = {r.name: equal_error_speedup(_restricted(r, chosen), simulator)
                for r in results}
    second = None
    if config.second_simulator:
        log("second simulator")
        second = evaluate_second_simulator(chosen, *config.second_simulator, body)
    streaming = []
    for compile in (False, True) if config.streaming_compile else (False,):
        if first_estimator is not None:
            log("streaming speed" + (", compiled" if compile else ""))
            streaming += stream_speed(first_estimator, body, config.streaming_vertices,
                                      config.streaming_frames, compile=compile)
    extra = {}
    for name, dataset in config.extra_tests.items():
        log(f"extra test: {name}")
        extra_sequences = load_test_sequences(_test_split(dataset), body)
        rows_ = []
        for model in config.models:
            estimator, data = first_seeds[model.name]
            rows_.append(evaluate_estimator(model.name, estimator, extra_sequences,
                                            data.get("sigma", DESCRIPTOR_SIGMA),
                                            data.get("seed", 0)).row())
        extra[name] = {"estimators": rows_, "rigid": evaluate_rigid(extra_sequences).row()}
    stability = []
    if config.stability != "off":
        log("stability suite")
        stability = run_stability(FULL if config.stability == "full" else SMALL,
                                  first_estimator, body_sdf, progress=progress)
    report = write_report(out, config, machine=machine, test_path=test_path,
                          sequences=sequences, results=results, per_model=per_model,
                          rigid=rigid, simulator=simulator, second=second, simulated=chosen,
                          speedups=speedups, streaming=streaming, extra=extra,
                          stability=stability, checkpoints=checkpoints, body_sdf=body_sdf,
                          resumed=resumed, seconds=time.perf_counter() - started)
    store.prune(identities)
    return report


def _stored_or_measured(store: MeasurementStore, identity: dict, resume: bool,
                        measure: Callable[[], MethodResult], extra: dict) -> MethodResult:
    """The measurement of ``identity``: read back from ``store`` when ``resume``
    finds it there (``extra["measured_at"]`` says when it was measured), else
    ``measure()`` now, with ``extra`` added, and stored."""
    stored = store.load(identity) if resume else None
    if stored is not None:
        result, measured_at = stored
        result.extra["measured_at"] = measured_at
        return result
    result = measure()
    result.extra.update(extra)
    store.save(identity, result)
    return result


def _label(name: str, precision: str, collisions: str) -> str:
    parts = [name]
    if precision != "fp32":
        parts.append(precision)
    if collisions != "none":
        parts.append(f"+ {collisions} collisions")
    return " ".join(parts)


def _spread(sequences: list, count: int) -> list:
    """``count`` sequences spread over the garments and motions of the split."""
    by_pair: dict = {}
    for s in sequences:
        by_pair.setdefault((s.garment.name.split("@")[0], s.motion.name), s)
    chosen = list(by_pair.values())
    return chosen[:count] if count < len(chosen) else chosen


def _restricted(result, sequences):
    """``result`` on ``sequences`` only (the ones the simulator re-ran)."""
    keep = {s.id for s in sequences}
    return MethodResult(result.name, result.kind, {k: v for k, v in result.errors.items()
                                                   if k in keep}, result.seconds, result.extra)
