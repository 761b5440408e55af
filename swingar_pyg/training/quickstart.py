"""The README's main job: data → training → test → a table of the estimator
against rigid skinning (error) and against the simulator (time per frame).

Both timings are taken in this run, one thread each: the estimator streams
every test sequence frame by frame, and the simulator re-simulates the first
test sequence of every test garment with the settings that made the data.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path


def _time_estimator(estimator, dataset, progress: bool) -> dict[str, float]:
    """Median ms per streamed frame per test garment, and the overall median."""
    per_garment: dict[str, list[float]] = {}
    sequences = enumerate(dataset.sequences)
    if progress:
        from tqdm import tqdm

        sequences = tqdm(sequences, total=len(dataset.sequences), desc="estimator (streaming)",
                         unit="sequence")
    for index, sequence in sequences:
        first = dataset.windows.index((index, 0))
        stream = estimator.stream(dataset[first], sequence.body_shape, sequence.fps)
        times = []
        for t in range(len(sequence.target)):
            start = time.perf_counter()
            stream.step(sequence.rotations[t], sequence.translation[t],
                        sequence.joint_transforms[t], sequence.joint_positions[t])
            times.append(time.perf_counter() - start)
        per_garment.setdefault(sequence.garment, []).extend(times[1:])
    return {name: 1e3 * float(np.median(v)) for name, v in per_garment.items()}


def _time_simulator(path: Path, sequence_ids: list[str], progress: bool) -> dict[str, float]:
    """Re-simulates sequences of a split file with the settings that made them;
    median ms per frame per garment."""
    import h5py

    from swingar_pyg.sim import XPBDSettings
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.motion import Motion
    from swingar_pyg.world.sequence import simulate_sequence
    from swingar_pyg.world.sequence_file import read_garment

    body = AnnyBody()
    out = {}
    for sequence_id in sequence_ids:
        with h5py.File(path, "r") as file:
            group = file[f"sequences/{sequence_id}"]
            name = str(group.attrs["garment"])
            fps = float(group.attrs["fps"])
            motion = Motion(str(group.attrs["motion"]), torch.as_tensor(group["rotations"][:]),
                            torch.as_tensor(group["translation"][:]), fps,
                            tuple(json.loads(group.attrs["joint_names"])))
            settings = json.loads(group.attrs["settings"])
            shape = torch.as_tensor(group["body_shape"][:])
        settings = XPBDSettings(**{**settings, "gravity": tuple(settings["gravity"])})
        result = simulate_sequence(body, shape, read_garment(path, name), motion, settings,
                                   progress=progress).result
        out[name] = 1e3 * float(np.median(result.seconds_per_frame))
    return out


def comparison_table(summary: dict, estimator_ms: dict[str, float],
                     simulator_ms: dict[str, float]) -> str:
    """Markdown: per test garment and overall, error (mm) of the estimator and
    of rigid skinning, and ms per frame of the estimator and of the simulator."""
    lines = ["| garment | estimator mean / p95 (mm) | rigid LBS mean / p95 (mm) | "
             "estimator ms/frame | simulator ms/frame | speed-up |",
             "|---|---|---|---|---|---|"]

    def row(label: str, key: str, names: list[str]) -> str:
        est, rig = summary["estimator"][key], summary["rigid"][key]
        e_ms = float(np.median([estimator_ms[n] for n in names if n in estimator_ms]))
        timed = [simulator_ms[n] for n in names if n in simulator_ms]
        s_ms = float(np.median(timed)) if timed else float("nan")
        return (f"| {label} | {est['mean_mm']:.1f} / {est['p95_mm']:.1f} | "
                f"{rig['mean_mm']:.1f} / {rig['p95_mm']:.1f} | {e_ms:.1f} | {s_ms:.0f} | "
                f"{s_ms / e_ms:.0f}× |")

    garments = sorted(k.split(":", 1)[1] for k in summary["estimator"]
                      if k.startswith("garment:"))
    for name in garments:
        lines.append(row(name, f"garment:{name}", [name]))
    lines.append(row("**all test**", "all", garments))
    motions = sorted(k for k in summary["estimator"] if k.startswith("motion:"))
    lines += ["", "| motion | estimator mean / p95 (mm) | rigid LBS mean / p95 (mm) |",
              "|---|---|---|"]
    for key in motions:
        est, rig = summary["estimator"][key], summary["rigid"][key]
        lines.append(f"| {key.split(':', 1)[1]} | {est['mean_mm']:.1f} / {est['p95_mm']:.1f} | "
                     f"{rig['mean_mm']:.1f} / {rig['p95_mm']:.1f} |")
    return "\n".join(lines)


def run_quickstart(config: str = "configs/quickstart.yaml", progress: bool = True) -> Path:
    """Trains ``config`` (resuming its last checkpoint if one exists), tests the
    best checkpoint on the held-out split, times estimator and simulator, and
    writes ``report.md`` and ``report.json`` to the run directory. Returns the
    report's path."""
    from swingar_pyg.training.cli import build_cli

    cli = build_cli(["-c", config], run=False)
    trainer, model, data = cli.trainer, cli.model, cli.datamodule
    root = Path(trainer.default_root_dir)
    last = Path(trainer.checkpoint_callback.dirpath or root) / "last.ckpt"
    trainer.fit(model, datamodule=data, ckpt_path=str(last) if last.exists() else None)
    checkpoints = trainer.checkpoint_callback
    best = checkpoints.best_model_path or checkpoints.last_model_path
    trainer.test(model, datamodule=data, ckpt_path=best)
    summary = model.last_summary
    dataset = data.datasets["test"]
    estimator = model.estimator.eval()
    estimator_ms = _time_estimator(estimator, dataset, progress)
    first_per_garment = {}
    for sequence in dataset.sequences:
        first_per_garment.setdefault(sequence.garment, sequence.id)
    simulator_ms = _time_simulator(data.split_path("test"), list(first_per_garment.values()),
                                   progress)
    table = comparison_table(summary, estimator_ms, simulator_ms)
    text = (f"# Quickstart: estimator vs rigid skinning and the simulator\n\n"
            f"Config `{config}`, checkpoint `{best}`. Errors: per-vertex distance to the "
            f"simulated garment at every test frame (unseen garments × unseen motions). "
            f"Times: median per frame, one thread, measured in this run (torch "
            f"{torch.__version__}, {torch.get_num_threads()} thread(s)).\n\n{table}\n")
    report = root / "report.md"
    with atomic_path(report) as tmp:
        tmp.write_text(text)
    with atomic_path(root / "report.json") as tmp:
        tmp.write_text(json.dumps({"config": config, "checkpoint": best, "errors": summary,
                                   "estimator_ms": estimator_ms,
                                   "simulator_ms": simulator_ms}, indent=2))
    print("\n" + table + f"\n\nwrote {report}")
    return report
