"""The estimator cases: a long stream (drift of its recurrent state), bfloat16
autocast, extreme poses and a garment 20x the usual size, each streamed frame by
frame through the garment graph."""

from __future__ import annotations

import time

import torch
from torch import Tensor

from swingar_pyg.eval.stability.records import Case
from swingar_pyg.geometry.skinning import linear_blend_skinning
from swingar_pyg.inference import SwinGarStream
from swingar_pyg.inference.prediction import animate, garment_graph
from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt

BF16_MM = 5 * 2.0**-8 * 1e3  # five bfloat16 roundoffs of a coordinate 1 m from the origin
# The motion's phase is float32: 10,000 frames in, 2*pi*333 s = 2,092 rad carries a
# roundoff of 2.4e-4 rad, which moves a 12-degree sway of a 1 m body by up to ~0.05 mm.
# Drift beyond twice that is the estimator's recurrent state, not the clock.
DRIFT_MM = 0.1


def _stream(context, rotations, translation, autocast: torch.dtype | None = None) -> Tensor:
    posed = context.body.pose(context.shape, rotations, translation)
    with torch.autocast("cpu", dtype=autocast, enabled=autocast is not None):
        vertices, _ = animate(context.estimator, context.graph, context.shape, rotations,
                              translation, posed.joint_transforms, posed.joint_positions, 30.0,
                              progress=False)
    return vertices.float()


def _estimator_drift(context):
    # A periodic motion streamed for many periods: once the pose window is full,
    # the garment at a frame and at the same phase many periods later must agree.
    frames = context.sizes.stream_frames
    clip = context.motion("sway", frames / 30.0)
    vertices = _stream(context, clip.rotations, clip.translation)
    period = 30  # sway at speed 1: one period per second
    first = context.estimator.history + 2 * period
    last = first + ((frames - 1 - first) // period) * period
    drift = float((vertices[last] - vertices[first]).norm(dim=-1).max())
    return 1e3 * drift, [vertices], f"frames {first} and {last}"


def _estimator_bf16(context):
    clip = context.motion("kick", 2.0)
    full = _stream(context, clip.rotations, clip.translation)
    half = _stream(context, clip.rotations, clip.translation, autocast=torch.bfloat16)
    return 1e3 * float((half - full).norm(dim=-1).max()), [half]


def _estimator_extreme(kind: str):
    def run(context):
        clip = context.motion(kind, 2.0)
        vertices = _stream(context, clip.rotations, clip.translation)
        posed = context.body.pose(context.shape, clip.rotations, clip.translation)
        skirt = context.skirt
        rigid = linear_blend_skinning(context.graph.rest, torch.as_tensor(skirt.skin_indices),
                                      torch.as_tensor(skirt.skin_weights, dtype=torch.float32),
                                      posed.joint_transforms)
        return 1e3 * float((vertices - rigid).norm(dim=-1).mean()), [vertices]
    return run


def _estimator_large(context):
    vertices = 20 * context.sizes.skirt_vertices
    skirt = fit_procedural_skirt(SkirtSpec(length=0.8, vertices=vertices, jitter=0.3),
                                 context.body, context.shape)
    graph = garment_graph(skirt, len(context.body.joint_names), context.estimator.descriptor_size)
    clip = context.motion("walk", 0.3)
    posed = context.body.pose(context.shape, clip.rotations, clip.translation)
    stream = SwinGarStream(context.estimator, graph, context.shape, 30.0)
    start = time.perf_counter()
    out = [stream.step(clip.rotations[t], clip.translation[t], posed.joint_transforms[t],
                       posed.joint_positions[t]) for t in range(len(clip.rotations))]
    ms = 1e3 * (time.perf_counter() - start) / len(out)
    return ms, out, f"{skirt.mesh.num_vertices} vertices"


ESTIMATOR_CASES: tuple[Case, ...] = (
    Case("estimator", "long stream (drift)", "max mm between equal phases", _estimator_drift,
         bound=DRIFT_MM),
    Case("estimator", "bfloat16 autocast", "max mm vs float32", _estimator_bf16, bound=BF16_MM),
    Case("estimator", "legs split", "mean mm from rigid skinning", _estimator_extreme("leg_split")),
    Case("estimator", "arms crossed", "mean mm from rigid skinning",
         _estimator_extreme("arm_cross")),
    Case("estimator", "20x the vertices", "ms per streamed frame", _estimator_large),
)
