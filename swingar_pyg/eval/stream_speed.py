"""Streaming speed: frames per second of :class:`~swingar_pyg.inference.SwinGarStream`
per garment size, whole and per stage, on a walking body.

The scene is a procedural knee-length skirt of a given vertex count on the
default body. Each frame's wall time is measured after ``warmup`` frames (which
include :func:`torch.compile`'s first calls, timed apart); figures are medians
over frames, so a stray slow frame does not move them. ``benchmarks/bench_stream.py``
and ``swingar report`` use this one measurement.
"""

from __future__ import annotations

import time
from collections import defaultdict
from contextlib import contextmanager
from typing import Iterator, Sequence

import numpy as np

from swingar_pyg.inference import SwinGarStream, garment_graph
from swingar_pyg.world.motion_library import make_motion
from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt


class _StageSamples:
    """A stream timer that keeps every call's wall time per stage."""

    def __init__(self):
        self.seconds: dict[str, list[float]] = defaultdict(list)

    @contextmanager
    def __call__(self, name: str) -> Iterator:
        start = time.perf_counter()
        yield lambda *tensors: None
        self.seconds[name].append(time.perf_counter() - start)


def stream_speed(estimator, body, vertices: Sequence[int], frames: int = 60, warmup: int = 3,
                 compile: bool = False) -> list[dict]:
    """One flat row per garment size: ``vertices`` (as built), ``compiled``,
    ``ms_per_frame``, ``fps``, ``ms <stage>`` (median per stage) and
    ``first_frames_s`` (wall time of the warm-up frames, compilation included).

    Args:
        estimator: a :class:`~swingar_pyg.models.SwinGarEstimator` (weights do not
            change the speed).
        body: the body model (:class:`~swingar_pyg.world.body.AnnyBody`).
        vertices: the skirt sizes to build (the mesher lands within a few vertices).
        frames: frames measured after the warm-up.
        warmup: frames run before measuring.
        compile: stream with ``compile=True``.
    """
    if frames < 1 or warmup < 0:
        raise ValueError(f"need frames >= 1 and warmup >= 0, got {frames} and {warmup}")
    shape = body.default_shape()
    total = frames + warmup
    motion = make_motion("walk", body, shape, seconds=total / 30.0)
    posed = body.pose(shape, motion.rotations, motion.translation)
    rows = []
    for count in vertices:
        skirt = fit_procedural_skirt(SkirtSpec(length=0.8, vertices=count), body, shape)
        graph = garment_graph(skirt, len(body.joint_names), estimator.descriptor_size)
        timer = _StageSamples()
        # passed only when set, so this measurement also runs on older revisions
        options = {"compile": True} if compile else {}
        stream = SwinGarStream(estimator, graph, shape, motion.fps, timer=timer, **options)
        seconds = []
        for t in range(min(total, motion.num_frames)):
            start = time.perf_counter()
            stream.step(motion.rotations[t], motion.translation[t], posed.joint_transforms[t],
                        posed.joint_positions[t])
            seconds.append(time.perf_counter() - start)
        ms = 1e3 * float(np.median(seconds[warmup:]))
        rows.append({
            "vertices": skirt.mesh.num_vertices, "compiled": compile, "ms_per_frame": ms,
            "fps": 1e3 / ms,
            **{f"ms {name}": 1e3 * float(np.median(samples[warmup:]))
               for name, samples in timer.seconds.items()},
            "first_frames_s": float(sum(seconds[:warmup]))})
    return rows
