"""Training points of the neural body SDF: points near posed bodies with their
exact signed distance and outward normal
(:func:`~swingar_pyg.geometry.body_signed_distance`, positive inside).

A split is a set of frames, each one body (shape, pose) with a fixed number of
points: samples on the posed surface moved along its normal by a random offset
(a mixture of scales, most within a few centimetres), and, for frames taken from
a garment dataset, the simulated and the rigidly skinned garment's vertices of
that frame (where the network is used). Layout of ``<split>.h5``::

    points (F,P,3) sdf (F,P) normal (F,P,3) joint_transforms (F,J,4,4)
    joint_positions (F,J,3) body_shape (F,S)
    motion (F,) [names]     attrs: settings (JSON), split
"""

from __future__ import annotations

import json
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.geometry import body_signed_distance
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.dataset import DatasetConfig, make_dataset
from swingar_pyg.world.motion import EXTREME_MOTIONS, PROCEDURAL_MOTIONS
from swingar_pyg.world.motion_library import make_motion

FIELDS = ("points", "sdf", "normal", "joint_transforms", "joint_positions", "body_shape")


@dataclass(frozen=True)
class SDFSampleSettings:
    """What a split of SDF samples is made of; a change regenerates it.

    Args:
        shapes: body shapes always in the training split (e.g. a garment
            dataset's), besides ``random_shapes`` drawn uniformly in ``[0, 1]``.
        random_shapes: random training shapes.
        val_shapes: random shapes of the validation split (never trained on).
        motions: motion sources of the training split (procedural families,
            shipped clips or .bvh paths; procedural ones at random amplitude).
        val_motions: motion sources of the validation split.
        frames_per_motion: frames taken from each motion for each shape.
        seconds: length of each motion.
        points_per_frame: points of every frame.
        offsets: standard deviations (m) of the offsets along the normal, and
            ``offset_weights`` how often each is drawn.
        amplitudes: range of the procedural motions' amplitude.
        garment_datasets: garment dataset configs (``configs/data/<name>.yaml``)
            whose training sequences add points at garment vertices: the
            simulated and the rigidly skinned garment of some frames (made
            first if missing, with :func:`~swingar_pyg.world.dataset.make_dataset`).
        garment_frames: frames taken from each of those sequences.
        seed: of every random choice.
    """

    shapes: tuple[tuple[float, ...], ...] = ()
    random_shapes: int = 40
    val_shapes: int = 4
    motions: tuple[str, ...] = ("sway", "twist", "walk", "kick", "jump")
    val_motions: tuple[str, ...] = ("spin_stop", "cmu_02_01_walk_delfem2")
    frames_per_motion: int = 2
    seconds: float = 3.0
    points_per_frame: int = 2048
    offsets: tuple[float, ...] = (0.003, 0.01, 0.03, 0.08)
    offset_weights: tuple[float, ...] = (0.3, 0.3, 0.3, 0.1)
    amplitudes: tuple[float, float] = (0.6, 1.3)
    garment_datasets: tuple[str, ...] = ()
    garment_frames: int = 4
    seed: int = 0

    def __post_init__(self):
        if len(self.offsets) != len(self.offset_weights) or not self.offsets:
            raise ValueError("give one weight per offset scale")
        if min(self.offset_weights) < 0 or sum(self.offset_weights) <= 0:
            raise ValueError(f"offset weights must be >= 0 with a positive sum, got "
                             f"{self.offset_weights}")
        if self.points_per_frame < 2 or self.frames_per_motion < 1:
            raise ValueError("points_per_frame must be >= 2 and frames_per_motion >= 1")
        if not self.shapes and self.random_shapes < 1:
            raise ValueError("the training split needs at least one body shape")

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)


@dataclass
class _Job:
    """The frames of one body shape: one job per worker."""

    shape: tuple[float, ...]
    motions: tuple[str, ...]
    seed: int
    garment_frames: list[tuple[str, str, list[int]]] = field(default_factory=list)


def near_surface_points(vertices: np.ndarray, faces: np.ndarray, count: int,
                        rng: np.random.Generator, offsets: tuple[float, ...],
                        offset_weights: tuple[float, ...]) -> np.ndarray:
    """``count`` points spread uniformly over the surface's area and moved along
    its normal by a zero-mean Gaussian whose scale is drawn from ``offsets``."""
    import trimesh

    surface = trimesh.Trimesh(vertices, faces, process=False)
    points, face = trimesh.sample.sample_surface(surface, count, seed=int(rng.integers(2**31)))
    probability = np.asarray(offset_weights, dtype=np.float64)
    scale = rng.choice(np.asarray(offsets), size=count, p=probability / probability.sum())
    return points + surface.face_normals[face] * (rng.standard_normal(count) * scale)[:, None]


def _frames(body, shape, rotations, translation, chosen, count, settings, rng, extra=None):
    """Samples and exact targets of ``chosen`` frames of a pose sequence."""
    posed = body.pose(torch.as_tensor(shape, dtype=torch.float32), rotations[chosen],
                      translation[chosen])
    faces = body.faces.numpy()
    out = {name: [] for name in FIELDS}
    for k in range(len(chosen)):
        vertices = posed.vertices[k].double().numpy()
        points = near_surface_points(vertices, faces, count - (0 if extra is None else
                                                               len(extra[k])),
                                     rng, settings.offsets, settings.offset_weights)
        if extra is not None:
            points = np.concatenate([extra[k], points])
        sdf, normal = body_signed_distance(points, vertices, faces)
        out["points"].append(points)
        out["sdf"].append(sdf)
        out["normal"].append(normal)
        out["joint_transforms"].append(posed.joint_transforms[k].numpy())
        out["joint_positions"].append(posed.joint_positions[k].numpy())
        out["body_shape"].append(np.asarray(shape))
    return out


def sample_motion_frames(body, shape: tuple[float, ...], motions: tuple[str, ...],
                         settings: SDFSampleSettings,
                         rng: np.random.Generator) -> tuple[dict, list[str]]:
    """Samples of ``settings.frames_per_motion`` random frames of each motion
    source on ``body`` with ``shape``: arrays of :data:`FIELDS` and the motion
    name of each frame."""
    pieces, names = [], []
    for source in motions:
        amplitude = float(rng.uniform(*settings.amplitudes)) \
            if source in PROCEDURAL_MOTIONS + EXTREME_MOTIONS else 1.0
        motion = make_motion(source, body, torch.tensor(shape), seconds=settings.seconds,
                             amplitude=amplitude)
        # Past the ease-in from the rest pose: frames of the motion itself.
        start = min(round(0.5 * motion.fps), motion.num_frames - 1)
        chosen = rng.choice(np.arange(start, motion.num_frames),
                            min(settings.frames_per_motion, motion.num_frames - start),
                            replace=False)
        pieces.append(_frames(body, shape, motion.rotations, motion.translation, chosen,
                              settings.points_per_frame, settings, rng))
        names += [motion.name] * len(chosen)
    return _join(pieces), names


def _join(pieces: list[dict]) -> dict:
    return {name: np.stack([x for piece in pieces for x in piece[name]]) for name in FIELDS}


def _run_job(job: _Job, settings: SDFSampleSettings) -> tuple[dict, list[str]]:
    import h5py
    torch.set_num_threads(1)
    body = AnnyBody()
    rng = np.random.default_rng(job.seed)
    pieces, names = [], []
    if job.motions:
        sampled, names = sample_motion_frames(body, job.shape, job.motions, settings, rng)
        pieces.append({name: list(sampled[name]) for name in FIELDS})
    for path, sequence_id, frames in job.garment_frames:
        with h5py.File(path, "r") as file:
            group = file[f"sequences/{sequence_id}"]
            rotations = torch.as_tensor(group["rotations"][:])
            translation = torch.as_tensor(group["translation"][:])
            motion = str(group.attrs["motion"])
            garment = [np.concatenate([group["garment_vertices"][t], group["rigid_vertices"][t]])
                       for t in frames]
        half = settings.points_per_frame // 2
        extra = [v[rng.choice(len(v), min(half, len(v)), replace=False)].astype(np.float64)
                 for v in garment]
        pieces.append(_frames(body, job.shape, rotations, translation, np.asarray(frames),
                              settings.points_per_frame, settings, rng, extra))
        names += [f"{motion}@{Path(path).stem}:{sequence_id}"] * len(frames)
    return _join(pieces), names


def _shape_rows(count: int, rng: np.random.Generator) -> list[tuple[float, ...]]:
    return [tuple(float(v) for v in rng.uniform(0.0, 1.0, 6)) for _ in range(count)]


def plan_jobs(settings: SDFSampleSettings, split: str) -> list[_Job]:
    """The jobs (one per body shape) of the ``train`` or ``val`` split."""
    rng = np.random.default_rng([settings.seed, 0 if split == "train" else 1])
    if split == "train":
        shapes = [tuple(map(float, s)) for s in settings.shapes]
        shapes += _shape_rows(settings.random_shapes, rng)
        motions = settings.motions
    elif split == "val":
        shapes, motions = _shape_rows(settings.val_shapes, rng), settings.val_motions
    else:
        raise ValueError(f"SDF sample splits are train and val, not {split!r}")
    jobs = [_Job(shape, motions, int(rng.integers(2**31))) for shape in shapes]
    if split == "train":
        _assign_garment_frames(jobs, settings, rng)
    return jobs


def _shape_key(shape: tuple[float, ...]) -> tuple[float, ...]:
    return tuple(round(v, 6) for v in shape)


def _assign_garment_frames(jobs: list[_Job], settings: SDFSampleSettings,
                           rng: np.random.Generator) -> None:
    import h5py

    # Shapes stored in float32 match the config's by value, not bit for bit.
    by_shape = {_shape_key(job.shape): job for job in jobs}
    for config_path in settings.garment_datasets:
        config = DatasetConfig.from_yaml(config_path)
        path = Path(config.output) / "train.h5"
        if not path.is_file():
            make_dataset(config, workers=2)
        with h5py.File(path, "r") as file:
            for sequence_id, group in sorted(file.get("sequences", {}).items()):
                shape = tuple(float(v) for v in group["body_shape"][:])
                job = by_shape.get(_shape_key(shape))
                if job is None:
                    job = _Job(shape, (), int(rng.integers(2**31)))
                    by_shape[_shape_key(shape)] = job
                    jobs.append(job)
                frames = group["garment_vertices"].shape[0]
                chosen = sorted(rng.choice(frames, min(settings.garment_frames, frames),
                                           replace=False).tolist())
                job.garment_frames.append((str(path), sequence_id, chosen))


def generate_split(settings: SDFSampleSettings, split: str, path: str | Path,
                   workers: int = 1, progress: bool = True) -> Path:
    """Makes the ``split`` file of SDF samples at ``path`` (atomically)."""
    import h5py

    jobs = plan_jobs(settings, split)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), desc=f"body SDF samples ({split})", unit="shape")
    results = []
    if workers == 1:
        for job in jobs:
            results.append(_run_job(job, settings))
            if bar:
                bar.update()
    else:
        with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
            for result in pool.map(_run_job, jobs, [settings] * len(jobs)):
                results.append(result)
                if bar:
                    bar.update()
    if bar:
        bar.close()
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as file:
            for name in FIELDS:
                data = np.concatenate([r[0][name] for r in results]).astype(np.float32)
                chunks = (1, *data.shape[1:]) if name in ("points", "sdf", "normal") else None
                file.create_dataset(name, data=data, chunks=chunks)
            file["motion"] = np.array([n for r in results for n in r[1]], dtype="S")
            file.attrs["settings"] = settings.to_json()
            file.attrs["split"] = split
    return Path(path)


def split_settings(path: str | Path) -> str | None:
    """The settings JSON a split file was made with (``None`` if absent)."""
    import h5py

    if not Path(path).is_file():
        return None
    with h5py.File(path, "r") as file:
        return file.attrs.get("settings")


def read_split(path: str | Path) -> dict:
    """A split file as arrays (see the module docstring) plus ``motion`` names."""
    import h5py

    with h5py.File(path, "r") as file:
        out = {name: file[name][:] for name in FIELDS}
        out["motion"] = [m.decode() for m in file["motion"][:]]
    return out
