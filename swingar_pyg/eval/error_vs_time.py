"""Error against run time on a test split: every method on the same sequences,
timed on the same machine in the same run.

A method's error is the per-vertex distance (mm) to the simulated garment at
every frame of every test sequence; its time is the median wall time per
frame. Methods: the estimator streamed one frame at a time (any precision,
with or without the collision pass), rigid skinning with the transferred
weights, and the simulator itself at other settings than the ones that made the
data (coarser ones trade error for time; a finer one measures how far the
ground truth itself is from convergence).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch
from torch import Tensor

from swingar_pyg.collision import exact_signed_distance, resolve_collisions
from swingar_pyg.geometry import mesh_edge_index
from swingar_pyg.geometry.signed_distance import BodySurface
from swingar_pyg.geometry.skinning import linear_blend_skinning
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.inference import SwinGarStream
from swingar_pyg.inference.prediction import garment_graph
from swingar_pyg.sim import VBDSettings, XPBDSettings
from swingar_pyg.training.vertex_errors import error_stats
from swingar_pyg.world.motion import Motion
from swingar_pyg.world.sequence import simulate_sequence
from swingar_pyg.world.sequence_file import read_garment, read_sequence, sequence_ids


@dataclass
class TestSequence:
    """A stored sequence with what every method needs to re-run it."""

    id: str
    garment: object
    motion: object
    body_shape: Tensor
    truth: Tensor
    rigid: Tensor
    settings: dict
    posed: object


class StoredSequences:
    """The sequences of a split file (all or ``ids``), each read and its body posed
    only when iteration reaches it: one sequence in memory at a time, for measures
    that keep only errors (a base test split posed at once holds gigabytes)."""

    def __init__(self, path, body, ids: list[str] | None = None):
        self.path, self.body = path, body
        self.ids = sequence_ids(path) if ids is None else list(ids)

    def __len__(self) -> int:
        return len(self.ids)

    def __iter__(self):
        for sequence_id in self.ids:
            yield from load_test_sequences(self.path, self.body, ids=[sequence_id])


def load_test_sequences(path, body, limit: int | None = None,
                        ids: list[str] | None = None) -> list[TestSequence]:
    """The sequences of a split file (all, the first ``limit`` or ``ids``),
    with the body posed for each."""
    if ids is None:
        ids = sequence_ids(path)[:limit]
    out = []
    for sequence_id in ids:
        stored = read_sequence(path, sequence_id)
        if stored["joint_names"] != tuple(body.joint_names):
            raise ValueError(f"{path}:{sequence_id} was made for another rig than this body's")
        shape = torch.as_tensor(stored["body_shape"])
        motion = Motion(stored["motion"], torch.as_tensor(stored["rotations"]),
                        torch.as_tensor(stored["translation"]), stored["fps"],
                        stored["joint_names"])
        out.append(TestSequence(sequence_id, read_garment(path, stored["garment"]), motion, shape,
                                torch.as_tensor(stored["garment_vertices"]),
                                torch.as_tensor(stored["rigid_vertices"]), stored["settings"],
                                body.pose(shape, motion.rotations, motion.translation)))
    return out


@dataclass
class MethodResult:
    """One point of the curve: errors ``(T, N)`` in mm per sequence, seconds per
    frame, and whatever else the method measured."""

    name: str
    kind: str
    errors: dict[str, Tensor]
    seconds: list[float]
    extra: dict = field(default_factory=dict)

    @property
    def ms_per_frame(self) -> float:
        return 1e3 * float(np.median(self.seconds))

    def stats(self, sequences: list[TestSequence] | None = None) -> dict[str, float]:
        """Mean, RMSE and p95 (mm) over all errors (of ``sequences`` if given)."""
        keep = None if sequences is None else {s.id for s in sequences}
        chosen = [e.reshape(-1) for k, e in self.errors.items() if keep is None or k in keep]
        return error_stats(torch.cat(chosen))

    def row(self) -> dict:
        return {"method": self.name, "kind": self.kind, "ms_per_frame": self.ms_per_frame,
                **self.stats(), **self.extra}


def _distance_mm(a: Tensor, b: Tensor) -> Tensor:
    return 1e3 * (a.double() - b.double()).norm(dim=-1).float()


def evaluate_rigid(sequences: list[TestSequence]) -> MethodResult:
    """Rigid skinning with the weights transferred from the body (the baseline)."""
    errors, seconds = {}, []
    for s in sequences:
        rest = torch.as_tensor(s.garment.mesh.vertices, dtype=torch.float32)
        indices = torch.as_tensor(s.garment.skin_indices).long()
        weights = torch.as_tensor(s.garment.skin_weights, dtype=torch.float32)
        frames = []
        for t in range(len(s.truth)):
            start = time.perf_counter()
            frames.append(linear_blend_skinning(rest, indices, weights,
                                                s.posed.joint_transforms[t:t + 1])[0])
            seconds.append(time.perf_counter() - start)
        errors[s.id] = _distance_mm(torch.stack(frames), s.truth)
    return MethodResult("rigid skinning", "rigid", errors, seconds)


def _warm_up(estimator, graph, sequence: TestSequence, device: torch.device) -> None:
    """Streams a sequence's first frames once with ``compile=True``: compiled code
    is cached (one compilation serves every garment size), so the timed stream
    starts compiled."""
    stream = SwinGarStream(estimator, graph, sequence.body_shape.to(device), sequence.motion.fps,
                           compile=True)
    for t in range(min(3, len(sequence.truth))):
        stream.step(sequence.motion.rotations[t].to(device),
                    sequence.motion.translation[t].to(device),
                    sequence.posed.joint_transforms[t].to(device),
                    sequence.posed.joint_positions[t].to(device))


def evaluate_estimator(name: str, estimator, sequences: list[TestSequence],
                       sigma: float = DESCRIPTOR_SIGMA, seed: int = 0, precision: str = "fp32",
                       collisions=None, body=None) -> MethodResult:
    """The estimator streamed over each sequence, one frame at a time.

    Args:
        precision: ``"fp32"``, ``"bf16"`` (CPU/GPU autocast) or ``"fp32-compiled"``
            (:class:`SwinGarStream` with ``compile=True``; each garment's first frames
            run once untimed, which compiles, and ``compile_seconds`` records them).
        collisions: ``None``, ``"exact"`` (exact SDF) or a
            :class:`~swingar_pyg.collision.NeuralCollisions` factory
            ``shape -> handler``; its time is included, and the share of
            vertices inside the body after it (exact SDF) is recorded.
    """
    if precision not in ("fp32", "bf16", "fp32-compiled"):
        raise ValueError(f"precision must be fp32, bf16 or fp32-compiled, got {precision!r}")
    compile = precision == "fp32-compiled"
    estimator = estimator.eval()
    errors, seconds, inside, total, compile_seconds = {}, [], 0, 0, 0.0
    device = next(estimator.parameters()).device
    for s in sequences:
        graph = garment_graph(s.garment, len(s.motion.joint_names), estimator.descriptor_size,
                              sigma=sigma, seed=seed).to(device)
        edges = mesh_edge_index(s.garment.mesh)
        handler = collisions(s.body_shape) if callable(collisions) else None
        if compile:
            start = time.perf_counter()
            _warm_up(estimator, graph, s, device)
            compile_seconds += time.perf_counter() - start
        stream = SwinGarStream(estimator, graph, s.body_shape.to(device), s.motion.fps,
                               compile=compile)
        frames = []
        for t in range(len(s.truth)):
            start = time.perf_counter()
            with torch.autocast(device.type, dtype=torch.bfloat16, enabled=precision == "bf16"):
                vertices = stream.step(s.motion.rotations[t].to(device),
                                       s.motion.translation[t].to(device),
                                       s.posed.joint_transforms[t].to(device),
                                       s.posed.joint_positions[t].to(device)).float()
            if handler is not None:
                vertices = handler.correct(vertices, edges.to(device),
                                           s.posed.joint_transforms[t].to(device),
                                           s.posed.joint_positions[t].to(device)).vertices
            elif collisions == "exact":
                exact = exact_signed_distance(s.posed.vertices[t], body.faces)
                vertices = resolve_collisions(vertices.double(), edges, exact).vertices.float()
            seconds.append(time.perf_counter() - start)
            frames.append(vertices.cpu())
        predicted = torch.stack(frames)
        errors[s.id] = _distance_mm(predicted, s.truth)
        if collisions is not None:
            for t in range(len(predicted)):
                surface = BodySurface(s.posed.vertices[t].double().numpy(), body.faces.numpy())
                inside += int((surface.signed_distance(predicted[t].double().numpy())[0] > 0).sum())
                total += predicted.shape[1]
    extra = {"precision": precision}
    if compile:
        extra["compile_seconds"] = compile_seconds
    if collisions is not None:
        extra["inside_percent"] = 100.0 * inside / max(total, 1)
    return MethodResult(name, "estimator", errors, seconds, extra)


def _resimulate(sequences: list[TestSequence], settings_for: Callable[[dict], object],
                body) -> tuple[dict, list, float]:
    """Each sequence simulated again with ``settings_for(stored settings)``: errors
    against its stored ground truth, seconds per frame, largest strain."""
    errors, seconds, strain = {}, [], 0.0
    for s in sequences:
        stored = {**s.settings, "gravity": tuple(s.settings["gravity"])}
        result = simulate_sequence(body, s.body_shape, s.garment, s.motion,
                                   settings_for(stored)).result
        errors[s.id] = _distance_mm(result.positions, s.truth)
        seconds.extend(result.seconds_per_frame.tolist())
        strain = max(strain, float(result.max_stretch.max()))
    return errors, seconds, strain


def evaluate_simulator(sequences: list[TestSequence], substeps: int, iterations: int,
                       body, max_substeps: int | None = None) -> MethodResult:
    """The simulator re-run on each sequence with other substeps and iterations
    (all else as stored), against the stored ground truth: at fixed substeps, or
    with ``max_substeps`` error-controlled (``XPBDSettings.max_substeps``)."""
    errors, seconds, strain = _resimulate(
        sequences, lambda stored: XPBDSettings(**{**stored, "substeps": substeps,
                                                  "iterations": iterations,
                                                  "max_substeps": max_substeps}), body)
    reference = sequences[0].settings
    same = (substeps, iterations, max_substeps) == (
        reference["substeps"], reference["iterations"], reference.get("max_substeps"))
    return MethodResult(f"simulator {setting_name(substeps, iterations, max_substeps)}",
                        "simulator", errors, seconds,
                        {"substeps": substeps, "iterations": iterations,
                         "max_substeps": max_substeps, "max_strain": strain,
                         "is_ground_truth_setting": same})


def setting_name(substeps: int, iterations: int, max_substeps: int | None = None) -> str:
    """``"100x1"``, or ``"100x1:400"`` when frames above the bar are re-run with up to
    400 substeps."""
    return f"{substeps}x{iterations}" + (f":{max_substeps}" if max_substeps else "")


def evaluate_second_simulator(sequences: list[TestSequence], substeps: int, iterations: int,
                              body) -> MethodResult:
    """newton's VBD solver on the same scenes (frame rate, gravity, density, damping,
    friction, thickness and settling as stored): its distance from the XPBD ground
    truth is the floor two credible simulators set (see ``swingar_pyg.sim.vbd``)."""
    shared = ("fps", "gravity", "density", "damping", "friction", "thickness", "settle_frames")
    errors, seconds, strain = _resimulate(
        sequences, lambda stored: VBDSettings(substeps=substeps, iterations=iterations,
                                              **{k: stored[k] for k in shared}), body)
    return MethodResult(f"VBD simulator {substeps}x{iterations} (newton)",
                        "second simulator", errors, seconds,
                        {"substeps": substeps, "iterations": iterations, "max_strain": strain})


def simulator_front(simulator: list[MethodResult]) -> list[tuple[float, float]]:
    """The simulator's Pareto front: ``(mean error mm, ms per frame)`` of the
    settings no other setting beats on both, from the most accurate to the fastest.
    A setting that is both slower and less accurate than another (a finer solve
    drifting from data made at a coarser one) is not a way to reach its error."""
    points: list[tuple[float, float]] = []
    for error_mm, ms in sorted((r.stats()["mean_mm"], r.ms_per_frame) for r in simulator
                               if r.stats()["mean_mm"] > 0):
        if not points or ms < points[-1][1]:
            points.append((error_mm, ms))
    return points


def equal_error_speedup(estimator: MethodResult, simulator: list[MethodResult]) -> dict:
    """How much faster the estimator is than the simulator at the estimator's
    mean error, interpolating the simulator's (log time, log error) Pareto front
    (:func:`simulator_front`). ``None`` where the error lies outside the front's
    range."""
    points = simulator_front(simulator)
    error = estimator.stats()["mean_mm"]
    if len(points) < 2 or not points[0][0] <= error <= points[-1][0]:
        return {"simulator_ms_at_equal_error": None, "speedup": None,
                "note": f"{error:.1f} mm lies outside the simulator's "
                        f"{points[0][0]:.1f}-{points[-1][0]:.1f} mm" if points else "no curve"}
    errors, times = np.log([p[0] for p in points]), np.log([p[1] for p in points])
    # error falls as time grows: interpolate log time over increasing log error
    simulator_ms = float(np.exp(np.interp(np.log(error), errors, times)))
    return {"simulator_ms_at_equal_error": simulator_ms,
            "speedup": simulator_ms / estimator.ms_per_frame}
