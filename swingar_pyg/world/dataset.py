"""Ground-truth datasets: garments x motions x body shapes, simulated, in HDF5 per split.

Generation is a list of jobs (one sequence each) in a fixed order. Each job writes
its own part file atomically, so a killed run resumes where it stopped and never
keeps half a sequence; each part records its recipe (garment, motion, body shape,
frame rate, length, solver settings, simulator revision), and a part whose recipe
is not the config's (the config or the simulator changed since) is simulated
again (a solver setting added since a part was made counts as its default, which
keeps the simulation as it was). ``--shard i/n`` takes every n-th job for spreading
over machines; worker processes (one torch thread each) share a machine. When every
part of a split is current, the parts are merged into ``<output>/<split>.h5``.
Splits are by garment and by motion: the config lists each split's own garments
and motions, and :func:`plan_jobs` refuses a garment or motion in two splits.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.sim.recording import STRETCH_BAR, sequence_stretch_by_place
from swingar_pyg.sim.xpbd import SIMULATOR_REVISION, XPBDSettings
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.catalogue import ShippedGarmentSpec, fit_garment, garment_spec
from swingar_pyg.world.motion_library import make_motion
from swingar_pyg.world.sequence import simulate_sequence
from swingar_pyg.world.sequence_file import merge_sequence_files, write_sequences

SPLITS = ("train", "val", "test")


@dataclass(frozen=True)
class MotionSpec:
    """A motion source (procedural family, shipped clip or .bvh path; see
    :func:`~swingar_pyg.world.motion_library.make_motion`) with its augmentation."""

    kind: str
    speed: float = 1.0
    amplitude: float = 1.0
    mirror: bool = False
    arms_out: float = 0.0  # degrees, captured clips only (world.motion.arms_out)


@dataclass(frozen=True)
class DatasetConfig:
    """What to generate (see ``configs/data/*.yaml``). A split is ``{garments, motions}``
    (every garment on every motion) or a list of such blocks, when some garments should
    meet only some motions; a block appended later keeps the jobs of the ones before it."""

    name: str
    output: str
    seconds: float
    fps: float
    body_shapes: tuple[tuple[float, ...], ...]
    # per split, blocks of (garments, motions): each block's every garment on each motion
    blocks: dict[str, tuple[tuple[tuple, tuple[MotionSpec, ...]], ...]]
    solver: XPBDSettings

    @property
    def garments(self) -> dict[str, tuple]:
        """Per split, its garments (each once, in order)."""
        return {split: tuple(dict.fromkeys(g for garments, _ in blocks for g in garments))
                for split, blocks in self.blocks.items()}

    @property
    def motions(self) -> dict[str, tuple[MotionSpec, ...]]:
        """Per split, its motions (each once, in order)."""
        return {split: tuple(dict.fromkeys(m for _, motions in blocks for m in motions))
                for split, blocks in self.blocks.items()}

    @classmethod
    def from_yaml(cls, path: str | Path) -> "DatasetConfig":
        import yaml

        raw = yaml.safe_load(Path(path).read_text())
        try:
            splits = raw["splits"]
            unknown = set(splits) - set(SPLITS)
            if unknown:
                raise ValueError(f"unknown splits {sorted(unknown)}; use {', '.join(SPLITS)}")
            return cls(
                name=str(raw["name"]), output=str(raw["output"]),
                seconds=float(raw["seconds"]), fps=float(raw.get("fps", 30.0)),
                body_shapes=tuple(tuple(float(v) for v in s) for s in raw["body_shapes"]),
                blocks={split: tuple(
                    (tuple(garment_spec(g) for g in block["garments"]),
                     tuple(MotionSpec(**m) for m in block["motions"]))
                    for block in (spec if isinstance(spec, list) else [spec]))
                    for split, spec in splits.items()},
                solver=XPBDSettings(fps=float(raw.get("fps", 30.0)), **raw.get("solver", {})),
            )
        except KeyError as missing:
            raise ValueError(f"{path}: the config needs {missing}") from None
        except TypeError as error:
            raise ValueError(f"{path}: {error}") from None


@dataclass(frozen=True)
class Job:
    split: str
    index: int
    garment: object
    motion: MotionSpec
    shape_index: int
    shape: tuple[float, ...]

    @property
    def id(self) -> str:
        return f"{self.split}-{self.index:05d}"


def plan_jobs(config: DatasetConfig) -> list[Job]:
    """Every (garment, motion, body shape) of every split, in a fixed order."""
    for kind, items in (("garment", config.garments), ("motion", config.motions)):
        seen: dict[Any, str] = {}
        for split, specs in items.items():
            for spec in specs:
                key = spec.kind if kind == "motion" else spec
                if key in seen and seen[key] != split:
                    raise ValueError(f"{kind} {key} is in both the {seen[key]} and the "
                                     f"{split} split; splits must not share {kind}s")
                seen[key] = split
    jobs = []
    for split in SPLITS:
        # block by block, so that a block appended to a split leaves the others' ids
        combos = [(g, m, k) for garments, motions in config.blocks.get(split, ())
                  for g in garments for m in motions for k in range(len(config.body_shapes))]
        jobs += [Job(split, i, g, m, k, config.body_shapes[k])
                 for i, (g, m, k) in enumerate(combos)]
    return jobs


def _part_path(output: Path, job: Job) -> Path:
    return output / "parts" / job.split / f"{job.id}.h5"


def job_recipe(job: Job, config: DatasetConfig) -> str:
    """Everything a job's sequence is made from, as JSON: the garment spec, the motion,
    the body shape, frame rate, length, solver settings and simulator revision."""
    garment = [type(job.garment).__name__, dataclasses.asdict(job.garment)]
    return json.dumps({"garment": garment, "motion": dataclasses.asdict(job.motion),
                       "shape": list(job.shape), "fps": config.fps, "seconds": config.seconds,
                       "solver": dataclasses.asdict(config.solver),
                       "simulator_revision": SIMULATOR_REVISION}, sort_keys=True)


def _is_current(part: Path, recipe: str) -> bool:
    """Whether ``part`` exists and was made from ``recipe``. A solver or motion setting
    the part's recipe lacks counts as its default: settings are added with defaults that
    keep the simulation as it was."""
    import h5py

    if not part.exists():
        return False
    with h5py.File(part, "r") as file:
        stored = file.attrs.get("recipe")
    if stored is None:
        return False
    # the config's own recipe, from job_recipe, already names every setting
    return _recipe_with_defaults(stored) == json.loads(recipe)


def _recipe_with_defaults(recipe: str) -> dict:
    """``recipe`` parsed, its solver settings and motion completed by the defaults of
    :class:`XPBDSettings` and :class:`MotionSpec`."""
    defaults = json.loads(json.dumps(dataclasses.asdict(XPBDSettings())))
    parsed = json.loads(recipe)
    parsed["solver"] = {**defaults, **parsed["solver"]}
    motion = dataclasses.asdict(MotionSpec(kind=parsed["motion"]["kind"]))
    parsed["motion"] = {**motion, **parsed["motion"]}
    return parsed


def _run_job(job: Job, fps: float, seconds: float, solver: XPBDSettings, part: str,
             recipe: str) -> dict:
    torch.set_num_threads(1)
    body = AnnyBody()
    shape = torch.tensor(job.shape)
    garment = fit_garment(job.garment, body, shape)
    garment = dataclasses.replace(garment, name=f"{garment.name}@shape{job.shape_index}")
    motion = make_motion(job.motion.kind, body, shape, seconds=seconds, fps=fps,
                         speed=job.motion.speed, amplitude=job.motion.amplitude,
                         mirror=job.motion.mirror, arms_out_degrees=job.motion.arms_out)
    sequence = simulate_sequence(body, shape, garment, motion, solver)
    sequence = sequence.with_exact_penetration(body.faces)
    write_sequences(part, [sequence], ids=[job.id], attrs={"recipe": recipe})
    result = sequence.result
    places = sequence_stretch_by_place(garment.mesh, garment.pinned, result.positions,
                                       sequence.body_vertices)
    return {"id": job.id, "vertices": garment.mesh.num_vertices, "frames": motion.num_frames,
            "ms_per_frame": 1e3 * float(np.median(result.seconds_per_frame)),
            "mean_substeps": float(np.mean(result.substeps_per_frame)),
            "max_stretch": float(result.max_stretch.max()), "max_stretch_by_place": places,
            "max_penetration": float(np.nanmax(result.penetration)),
            "max_penetration_exact": float(sequence.penetration_exact.max())}


def garment_family(spec) -> str:
    """A garment spec's family: ``skirt``, ``dress``, ``tshirt``, ``jumpsuit`` or the
    shipped piece's name."""
    if isinstance(spec, ShippedGarmentSpec):
        return spec.name
    return type(spec).__name__.removesuffix("Spec").lower()


def _simulation_figures(reports: list[dict]) -> dict:
    """The simulator's figures over the sequences of ``reports`` (``_run_job``'s)."""
    largest = np.array([r["max_stretch"] for r in reports])
    return {
        "sequences": len(reports),
        "ms_per_frame_median": float(np.median([r["ms_per_frame"] for r in reports])),
        # above the solver's substeps where it re-ran frames over the bar (max_substeps)
        "substeps_mean": float(np.mean([r["mean_substeps"] for r in reports])),
        "max_stretch": float(largest.max()),
        # One sequence's largest strain is chaotic (benchmarks/bench_strain.py): how the
        # sequences spread says more than the worst of them.
        "max_stretch_median_sequence": float(np.median(largest)),
        "share_over_stretch_bar": float((largest > STRETCH_BAR).mean()),
        # where the sequences over the bar have their largest stretch (stretch_by_place)
        "over_stretch_bar_by_place": dict(Counter(
            max(r["max_stretch_by_place"], key=r["max_stretch_by_place"].get)
            for r in reports if r["max_stretch"] > STRETCH_BAR)),
        "max_penetration": float(max(r["max_penetration"] for r in reports)),
        "max_penetration_exact": float(max(r["max_penetration_exact"] for r in reports))}


def make_dataset(config: DatasetConfig, output: str | Path | None = None,
                 shard: tuple[int, int] = (0, 1), workers: int = 1,
                 progress: bool = True) -> dict:
    """Generates this shard's missing parts, then merges every complete split.

    Returns a summary: per split, the sequences and the simulator's figures.
    """
    index, count = shard
    if not 0 <= index < count:
        raise ValueError(f"shard must be i/n with 0 <= i < n, got {index}/{count}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    output = Path(output or config.output)
    jobs = plan_jobs(config)
    mine = [job for k, job in enumerate(jobs) if k % count == index]
    recipes = {job.id: job_recipe(job, config) for job in jobs}
    todo = [job for job in mine if not _is_current(_part_path(output, job), recipes[job.id])]
    stale = sum(_part_path(output, job).exists() for job in todo)
    if stale:
        warnings.warn(f"{stale} part file(s) under {output / 'parts'} were made from another "
                      "config or simulator revision; simulating them again", stacklevel=2)
    start = time.perf_counter()
    reports = []
    if todo:
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), desc=f"{config.name} shard {index}/{count}",
                       unit="sequence")
        arguments = [(job, config.fps, config.seconds, config.solver,
                      str(_part_path(output, job)), recipes[job.id]) for job in todo]
        for job in todo:
            _part_path(output, job).parent.mkdir(parents=True, exist_ok=True)
        if workers == 1:
            for args in arguments:
                reports.append(_run_job(*args))
                if bar:
                    bar.update()
        else:
            with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
                futures = [pool.submit(_run_job, *args) for args in arguments]
                for future in as_completed(futures):
                    reports.append(future.result())
                    if bar:
                        bar.update()
        if bar:
            bar.close()

    summary: dict = {"name": config.name, "output": str(output), "shard": f"{index}/{count}",
                     "generated": len(reports), "skipped_existing": len(mine) - len(todo),
                     "replaced_stale": stale,
                     "seconds": time.perf_counter() - start, "splits": {}}
    for split in SPLITS:
        split_jobs = [job for job in jobs if job.split == split]
        if not split_jobs:
            continue
        parts = [_part_path(output, job) for job in split_jobs]
        # re-read: parts of other shards may have landed while this one ran
        complete = all(_is_current(part, recipes[job.id])
                       for part, job in zip(parts, split_jobs))
        if complete:
            merge_sequence_files(parts, output / f"{split}.h5")
        summary["splits"][split] = {"sequences": len(parts), "complete": complete,
                                    "garments": len(config.garments.get(split, ())),
                                    "motions": [m.kind for m in config.motions.get(split, ())]}
    if reports:
        by_id = {job.id: job for job in jobs}
        summary["simulation"] = _simulation_figures(reports)
        for key, group in (("by_garment_family", lambda job: garment_family(job.garment)),
                           ("by_motion", lambda job: job.motion.kind)):
            groups: dict[str, list[dict]] = {}
            for report in reports:
                groups.setdefault(group(by_id[report["id"]]), []).append(report)
            summary["simulation"][key] = {name: _simulation_figures(members)
                                          for name, members in sorted(groups.items())}
    with atomic_path(output / f"summary-shard{index}of{count}.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary
