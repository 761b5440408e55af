"""How large the suite's inputs are, and the inputs its cases share.

:data:`SMALL` runs in well under a minute (the tests), :data:`FULL` at the sizes
of real use (the report). :class:`StabilityContext` holds the body, the skirt,
the estimator, its garment graph and the body SDF's collision handling, each
built on first use, so a run that skips a component never builds its inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import torch
from torch import Tensor

from swingar_pyg.collision import NeuralCollisions
from swingar_pyg.inference.prediction import garment_graph
from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.training import load_body_sdf
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.motion_library import make_motion
from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt


@dataclass(frozen=True)
class StabilitySizes:
    """How large each case is."""

    graph_side: int
    descriptor_side: int
    skirt_vertices: int
    sim_seconds: float
    substeps: int
    stream_frames: int


SMALL = StabilitySizes(graph_side=24, descriptor_side=16, skirt_vertices=200, sim_seconds=0.3,
                       substeps=10, stream_frames=300)
FULL = StabilitySizes(graph_side=100, descriptor_side=70, skirt_vertices=1500, sim_seconds=2.0,
                      substeps=50, stream_frames=10_000)


class StabilityContext:
    """What the cases share, built on first use."""

    def __init__(self, sizes: StabilitySizes, estimator, body_sdf_checkpoint: str | None):
        self.sizes = sizes
        self.given_estimator = estimator
        self.body_sdf_checkpoint = body_sdf_checkpoint

    @cached_property
    def body(self):
        return AnnyBody()

    @cached_property
    def shape(self) -> Tensor:
        return self.body.default_shape()

    @cached_property
    def skirt(self):
        return fit_procedural_skirt(SkirtSpec(length=0.6, flare=0.35,
                                              vertices=self.sizes.skirt_vertices),
                                    self.body, self.shape)

    @cached_property
    def estimator(self):
        if self.given_estimator is not None:
            return self.given_estimator.eval()
        torch.manual_seed(0)
        model = SwinGarEstimator(channels=16, detail_channels=8, descriptor_size=32, history=16)
        # Untrained heads start at zero (rigid skinning); random ones exercise every path.
        for parameter in model.parameters():
            torch.nn.init.normal_(parameter, std=0.1)
        return model.eval()

    @cached_property
    def graph(self):
        return garment_graph(self.skirt, len(self.body.joint_names),
                             self.estimator.descriptor_size)

    def motion(self, kind: str, seconds: float, **options):
        return make_motion(kind, self.body, self.shape, seconds=seconds, **options)

    @cached_property
    def neural(self):
        if self.body_sdf_checkpoint is None:
            return None
        return NeuralCollisions.for_body(load_body_sdf(self.body_sdf_checkpoint), self.body,
                                         self.shape)
