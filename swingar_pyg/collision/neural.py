"""Collision handling with the neural body SDF: broad phase on the bones, then
the neighbour-aware correction on the vertices that could be inside."""

from __future__ import annotations

from dataclasses import dataclass

from torch import Tensor

from swingar_pyg.collision.broad_phase import BoneCapsules
from swingar_pyg.collision.correction import Correction, resolve_collisions
from swingar_pyg.models.body_sdf import BodySDF
from swingar_pyg.world.body import BodyModel


@dataclass
class NeuralCollisions:
    """Moves garment vertices out of a body of one shape, frame by frame.

    Attributes:
        body_sdf: a trained :class:`~swingar_pyg.models.BodySDF`.
        capsules: the body's :class:`BoneCapsules` (the broad phase).
        body_shape: ``(S,)`` the body's shape parameters.
        margin: vertices farther than this beyond every capsule skip the network.
        offset: the correction's safety band (see
            :func:`~swingar_pyg.collision.resolve_collisions`): the network's
            typical error near the surface.
        iterations: correction steps at most.
    """

    body_sdf: BodySDF
    capsules: BoneCapsules
    body_shape: Tensor
    margin: float = 0.03
    offset: float = 0.004
    iterations: int = 3

    @classmethod
    def for_body(cls, body_sdf: BodySDF, body: BodyModel, body_shape: Tensor,
                 **options) -> NeuralCollisions:
        """For ``body`` with ``body_shape``: a trained ``body_sdf`` (e.g.
        :func:`~swingar_pyg.training.load_body_sdf` of a ``swingar fit -c
        configs/body_sdf.yaml`` checkpoint) and the body's capsules.

        Raises:
            ValueError: if ``body_sdf`` was trained on another rig than ``body``'s.
        """
        if tuple(body_sdf.parents) != tuple(body.parents):
            raise ValueError("the body SDF was trained on another rig than this body's")
        return cls(body_sdf.eval(), BoneCapsules.from_body(body, body_shape), body_shape,
                   **options)

    def correct(self, vertices: Tensor, edge_index: Tensor, joint_transforms: Tensor,
                joint_positions: Tensor, near: Tensor | None = None) -> Correction:
        """One frame: garment ``(N, 3)`` (a Batch of garments is fine), mesh
        edges, and the body's ``(J, 4, 4)`` transforms and ``(J, 3)`` joints;
        ``near``: the broad phase's result, if already known."""
        if near is None:
            near = self.capsules.near(vertices, joint_positions, self.margin)
        field = self.body_sdf.bind(joint_transforms.to(vertices), joint_positions.to(vertices),
                                   self.body_shape.to(vertices))
        return resolve_collisions(vertices, edge_index, field, iterations=self.iterations,
                                  near=near, offset=self.offset)
