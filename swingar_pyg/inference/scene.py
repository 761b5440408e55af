"""Scene-driven inference (docs/design.md §9): leave out what a scene does not need.

A :class:`Scene` says what is there (garments fitted on a body, the body's shape
and motion) and what is wanted (skinning only, collision handling or not).
:func:`compile_scene` turns it into the stages it needs, and only those:

- **garment features** (graph, normals, descriptor) for each garment, unless a
  :class:`GarmentFeatureCache` already holds them;
- several garments become **one Batch** of disjoint graphs;
- **body poses** once for the motion;
- **rigid skinning** alone when the user only wants skinning (no network runs);
- otherwise the estimator, streamed: **motion code**, **skinning (E, P, LBS)**
  and **detail (M_d)**; a frame whose whole pose window equals the previous
  frame's (a body standing still) reuses the previous output instead, which is
  what the estimator would compute again;
- **collisions**: the bone-capsule broad phase each frame, then the SDF and the
  correction only on frames where some vertex can be inside the body (the neural
  SDF if a checkpoint is given, else the exact one); none when switched off.

The run reports, per stage, whether it ran (or why it was left out), how often,
its time, and the size of what it produced (MB of its output tensors).
"""

from __future__ import annotations

import hashlib
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import torch
from torch import Tensor
from torch_geometric.data import Batch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.collision import (
    BoneCapsules,
    NeuralCollisions,
    exact_signed_distance,
    resolve_collisions,
)
from swingar_pyg.geometry import mesh_edge_index
from swingar_pyg.geometry.skinning import linear_blend_skinning
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.inference.streaming import SwinGarStream
from swingar_pyg.models import BodySDF, GarmentWindow
from swingar_pyg.models.garment_window import garment_graph_features


@dataclass
class StageCost:
    """What one stage cost over a run."""

    name: str
    ran: bool = False
    calls: int = 0
    seconds: float = 0.0
    megabytes: float = 0.0
    note: str = ""
    moved: int = 0


class StageTimer:
    """Times named stages: ``with timer("stage") as record: ...; record(tensor)``
    counts a call, its wall time and the megabytes of the tensors recorded."""

    def __init__(self):
        self.stages: dict[str, StageCost] = {}

    def stage(self, name: str) -> StageCost:
        return self.stages.setdefault(name, StageCost(name))

    @contextmanager
    def __call__(self, name: str) -> Iterator:
        stage = self.stage(name)

        def record(*tensors: Tensor) -> None:
            stage.megabytes = max(stage.megabytes, sum(
                t.numel() * t.element_size() for t in tensors) / 2**20)

        start = time.perf_counter()
        yield record
        stage.seconds += time.perf_counter() - start
        stage.calls += 1
        stage.ran = True

    def skip(self, name: str, reason: str) -> None:
        """Says why ``name`` did not run (kept only if it did not)."""
        stage = self.stage(name)
        if not stage.ran:
            stage.note = reason


class GarmentFeatureCache:
    """Garment features (:func:`~swingar_pyg.models.garment_window.garment_graph_features`)
    by mesh content and settings, in memory and, with a ``directory``, on disk
    (one ``.pt`` file per key, written atomically)."""

    def __init__(self, directory: str | Path | None = None):
        self.directory = None if directory is None else Path(directory)
        self._memory: dict[str, dict] = {}
        self.hits = self.misses = 0

    @staticmethod
    def key(mesh, descriptor_size: int | None, sigma: float, seed: int) -> str:
        digest = hashlib.sha1()
        digest.update(np.ascontiguousarray(mesh.vertices).tobytes())
        digest.update(np.ascontiguousarray(mesh.faces).tobytes())
        digest.update(repr((descriptor_size, sigma, seed)).encode())
        return digest.hexdigest()

    def get(self, mesh, descriptor_size: int | None, sigma: float = DESCRIPTOR_SIGMA,
            seed: int = 0) -> dict | None:
        """The cached features, or ``None``."""
        key = self.key(mesh, descriptor_size, sigma, seed)
        if key not in self._memory and self.directory is not None:
            path = self.directory / f"{key}.pt"
            if path.is_file():
                self._memory[key] = torch.load(path, weights_only=True)
        found = self._memory.get(key)
        if found is None:
            self.misses += 1
        else:
            self.hits += 1
        return found

    def compute(self, mesh, descriptor_size: int | None, sigma: float = DESCRIPTOR_SIGMA,
                seed: int = 0) -> dict:
        """Computes the features and caches them."""
        key = self.key(mesh, descriptor_size, sigma, seed)
        features = garment_graph_features(mesh, descriptor_size, sigma, seed)
        self._memory[key] = features
        if self.directory is not None:
            with atomic_path(self.directory / f"{key}.pt") as tmp:
                torch.save(features, tmp)
        return features


@dataclass
class Scene:
    """Garments on a body in motion, and what is wanted of them.

    Attributes:
        garments: :class:`~swingar_pyg.world.garment.Garment` s fitted on the
            body's rest pose with ``body_shape``.
        body: the :class:`~swingar_pyg.world.body.BodyModel`.
        body_shape: ``(S,)`` its shape parameters.
        motion: the :class:`~swingar_pyg.world.motion.Motion`.
        skinning_only: rigid skinning with the transferred weights, no network.
        collisions: move vertices out of the body after inference.
        body_sdf: a trained :class:`~swingar_pyg.models.BodySDF` for the
            collision pass (default: the exact mesh SDF, slower).
    """

    garments: list
    body: object
    body_shape: Tensor
    motion: object
    skinning_only: bool = False
    collisions: bool = True
    body_sdf: BodySDF | None = None

    def __post_init__(self):
        if not self.garments:
            raise ValueError("a scene needs at least one garment")
        if tuple(self.motion.joint_names) != tuple(self.body.joint_names):
            raise ValueError("the motion was made for another rig than the body's")


@dataclass
class SceneResult:
    """The garments over the motion (``vertices[g]`` ``(T, N_g, 3)``, in the
    order of the scene; ``before_collisions`` the same before the collision
    pass), and what each stage cost."""

    names: list[str]
    vertices: list[Tensor]
    before_collisions: list[Tensor]
    stages: list[StageCost]
    frames: int

    def stage(self, name: str) -> StageCost:
        for stage in self.stages:
            if stage.name == name:
                return stage
        raise KeyError(name)

    def table(self) -> str:
        return stage_table(self.stages)


def stage_table(stages: list[StageCost]) -> str:
    """Stages as a text table: ran, calls, ms in all and per call, MB, note."""
    lines = [f"{'stage':<29} {'ran':>4} {'calls':>6} {'ms':>9} {'ms/call':>8} {'MB':>7}  note"]
    for s in stages:
        per_call = 1e3 * s.seconds / s.calls if s.calls else 0.0
        lines.append(f"{s.name:<29} {'yes' if s.ran else 'no':>4} {s.calls:>6} "
                     f"{1e3 * s.seconds:>9.1f} {per_call:>8.2f} {s.megabytes:>7.2f}  {s.note}")
    return "\n".join(lines)


STAGES = ("garment features", "batch", "body poses", "rigid skinning", "motion code",
          "skinning (E, P, LBS)", "detail (M_d)", "static frames reused",
          "collisions: broad phase", "collisions: SDF + correction")


@dataclass(frozen=True)
class Stage:
    """One stage of a scene's plan: whether it will run, and why it runs or why
    it is left out."""

    name: str
    runs: bool
    why: str

    @property
    def note(self) -> str:
        """``why`` as a run reports it: ``"left out: …"`` for a stage left out."""
        return self.why if self.runs else f"left out: {self.why}"


class ScenePipeline:
    """The stages a scene needs (see the module docstring); :meth:`run` runs them."""

    def __init__(self, scene: Scene, estimator=None, cache: GarmentFeatureCache | None = None,
                 sigma: float = DESCRIPTOR_SIGMA, seed: int = 0, collision_margin: float = 0.03):
        if estimator is None and not scene.skinning_only:
            raise ValueError("a scene that is not skinning_only needs an estimator")
        self.scene, self.estimator = scene, estimator
        self.cache = cache or GarmentFeatureCache()
        self.sigma, self.seed, self.margin = sigma, seed, collision_margin

    def plan(self) -> list[Stage]:
        """Every stage in order, whether it will run and why, before running."""
        s = self.scene

        def stage(name: str, left_out: str, runs: str = "runs") -> Stage:
            """``left_out``: why the stage is left out, empty if it runs."""
            return Stage(name, not left_out, left_out or runs)

        skinning_only = "skinning only" if s.skinning_only else ""
        switched_off = "" if s.collisions else "switched off"
        no_detail = skinning_only or ("the estimator has none"
                                      if self.estimator.detail is None else "")
        sdf = "neural SDF" if s.body_sdf is not None else "exact SDF"
        return [
            stage("garment features", skinning_only, "per garment, unless cached"),
            stage("batch", "one garment" if len(s.garments) == 1 else "",
                  f"{len(s.garments)} garments in one Batch"),
            stage("body poses", ""),
            stage("rigid skinning", "" if s.skinning_only else "the estimator skins"),
            stage("motion code", skinning_only),
            stage("skinning (E, P, LBS)", skinning_only),
            stage("detail (M_d)", no_detail, "runs, but not on static frames"),
            stage("static frames reused", skinning_only,
                  "frames whose pose window did not change"),
            stage("collisions: broad phase", switched_off),
            stage("collisions: SDF + correction", switched_off,
                  f"{sdf}, on frames the broad phase flags"),
        ]

    def _graphs(self, timer: StageTimer):
        graphs, cached = [], 0
        joints = len(self.scene.body.joint_names)
        settings = (self.estimator.descriptor_size, self.sigma, self.seed)
        for garment in self.scene.garments:
            features = self.cache.get(garment.mesh, *settings)
            if features is None:
                with timer("garment features") as record:
                    features = self.cache.compute(garment.mesh, *settings)
                    record(*[v for v in features.values() if isinstance(v, Tensor)])
            else:
                cached += 1
            graphs.append(GarmentWindow.from_garment(garment, joints, features))
        timer.stage("garment features").note = (
            f"{len(graphs) - cached} computed, {cached} from the cache" if cached < len(graphs)
            else f"left out: all {cached} from the cache")
        if len(graphs) == 1:
            timer.skip("batch", "one garment")
            return graphs[0]
        with timer("batch") as record:
            batch = Batch.from_data_list(graphs)
            record(batch.rest, batch.edge_index)
        return batch

    def run(self, progress: bool = False) -> SceneResult:
        s = self.scene
        timer = StageTimer()
        frames = s.motion.num_frames
        with timer("body poses") as record:
            posed = s.body.pose(s.body_shape, s.motion.rotations, s.motion.translation)
            record(posed.joint_transforms, posed.joint_positions, posed.vertices)
        offsets = np.cumsum([0] + [g.mesh.num_vertices for g in s.garments])
        if s.skinning_only:
            vertices = self._skin_rigidly(posed, timer)
            edge_index = torch.cat([mesh_edge_index(g.mesh) + int(o)
                                    for g, o in zip(s.garments, offsets)], dim=1)
        else:
            graph = self._graphs(timer)
            vertices = self._stream(graph, posed, timer, progress)
            edge_index = graph.edge_index
        for planned in self.plan():
            if not planned.runs:
                timer.skip(planned.name, planned.note)
        before = vertices
        if s.collisions:
            vertices = self._collide(vertices, edge_index, posed, timer)

        def split(x: Tensor) -> list[Tensor]:
            return [x[:, a:b] for a, b in zip(offsets[:-1], offsets[1:])]

        stages = [timer.stages.get(name, StageCost(name)) for name in STAGES]
        return SceneResult([g.name for g in s.garments], split(vertices), split(before), stages,
                           frames)

    def _skin_rigidly(self, posed, timer: StageTimer) -> Tensor:
        out = []
        with timer("rigid skinning") as record:
            for garment in self.scene.garments:
                out.append(linear_blend_skinning(
                    torch.as_tensor(garment.mesh.vertices, dtype=torch.float32),
                    torch.as_tensor(garment.skin_indices).long(),
                    torch.as_tensor(garment.skin_weights, dtype=torch.float32),
                    posed.joint_transforms))
            vertices = torch.cat(out, dim=1)
            record(vertices)
        return vertices

    def _stream(self, graph, posed, timer: StageTimer, progress: bool) -> Tensor:
        s = self.scene
        stream = SwinGarStream(self.estimator, graph, s.body_shape, s.motion.fps, timer=timer)
        # A frame whose window (m + 1 poses) and cached skinned frames (3) all equal the
        # previous frame's gives the previous output again: reuse it.
        still = self.estimator.history + 3
        rotations, translation = s.motion.rotations, s.motion.translation
        same = torch.zeros(len(rotations), dtype=torch.bool)
        same[1:] = ((rotations[1:] == rotations[:-1]).flatten(1).all(1) &
                    (translation[1:] == translation[:-1]).all(1))
        run_length = torch.zeros(len(rotations), dtype=torch.long)
        for t in range(1, len(rotations)):
            run_length[t] = run_length[t - 1] + 1 if same[t] else 0
        frames = range(len(rotations))
        if progress:
            from tqdm import tqdm

            frames = tqdm(frames, desc="scene", unit="frame")
        out, reused = [], 0
        for t in frames:
            if t >= still and run_length[t] >= still:
                out.append(out[-1])
                reused += 1
                continue
            out.append(stream.step(rotations[t], translation[t], posed.joint_transforms[t],
                                   posed.joint_positions[t]))
        if reused:
            stage = timer.stage("static frames reused")
            stage.ran, stage.calls = True, reused
            stage.note = "pose window unchanged: previous output"
        else:
            timer.skip("static frames reused", "no static window")
        return torch.stack(out)

    def _collide(self, vertices: Tensor, edge_index: Tensor, posed,
                 timer: StageTimer) -> Tensor:
        s = self.scene
        capsules = BoneCapsules.from_body(s.body, s.body_shape)
        neural = None
        if s.body_sdf is not None:
            neural = NeuralCollisions.for_body(s.body_sdf, s.body, s.body_shape,
                                               margin=self.margin)
        out, moved = vertices.clone(), 0
        for t in range(len(vertices)):
            with timer("collisions: broad phase"):
                near = capsules.near(vertices[t], posed.joint_positions[t], self.margin)
            if not near.any():
                continue
            with timer("collisions: SDF + correction") as record:
                if neural is not None:
                    result = neural.correct(vertices[t], edge_index, posed.joint_transforms[t],
                                            posed.joint_positions[t], near=near)
                else:
                    field = exact_signed_distance(posed.vertices[t], s.body.faces)
                    result = resolve_collisions(vertices[t].double(), edge_index, field,
                                                near=near)
                out[t] = result.vertices.to(out)
                moved += int(result.moved.sum())
                record(result.vertices)
        sdf = timer.stage("collisions: SDF + correction")
        sdf.moved = moved
        if sdf.ran:
            sdf.note = (f"{'neural' if neural else 'exact'} SDF; moved {moved} vertex-frames")
        else:
            timer.skip("collisions: SDF + correction", "the broad phase found no vertex near "
                       "the body")
        return out


def compile_scene(scene: Scene, estimator=None, cache: GarmentFeatureCache | None = None,
                  **options) -> ScenePipeline:
    """The pipeline ``scene`` needs (see the module docstring)."""
    return ScenePipeline(scene, estimator, cache, **options)


__all__ = ["GarmentFeatureCache", "Scene", "ScenePipeline", "SceneResult", "StageCost",
           "StageTimer", "compile_scene", "stage_table"]
