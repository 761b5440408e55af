r"""The broad phase of collision handling: which garment vertices could be
inside the body at all, from the body's bones alone (no SDF evaluation).

Each joint :math:`j` gets a capsule around its bone segments
(:mod:`~swingar_pyg.geometry.bones`) whose radius :math:`r_j` holds the rest
body surface that the joint carries (vertices whose largest skinning weight is
:math:`j`'s). A point whose clearance

.. math::
    c(\mathbf{x}) = \min_j \bigl(d_j(\mathbf{x}) - r_j\bigr)

exceeds a margin is outside every capsule, hence outside the body; the margin
absorbs what skinning moves beyond the capsules (blended vertices at the
joints: at most 1.2 cm on the anny body, in the split and cross-arm poses
of :data:`~swingar_pyg.world.motion.EXTREME_MOTIONS` at 1.5 times their amplitude).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from swingar_pyg.geometry.bones import bone_segments, distance_to_bones
from swingar_pyg.world.body import rest_pose


@dataclass(frozen=True)
class BoneCapsules:
    """Capsules ``radius`` ``(J,)`` around each joint's bone segments
    (``owner``, ``tip``)."""

    radius: Tensor
    owner: Tensor
    tip: Tensor

    @classmethod
    def fit(cls, rest_vertices: Tensor, skin_indices: Tensor, skin_weights: Tensor,
            rest_joint_positions: Tensor, parents: tuple[int, ...]) -> "BoneCapsules":
        """Capsules of a body in its rest pose: ``(V, 3)`` vertices, ``(V, K)``
        skinning, ``(J, 3)`` joint heads and the rig's parents."""
        owner, tip = bone_segments(parents)
        dominant = skin_indices.gather(1, skin_weights.argmax(dim=1, keepdim=True)).squeeze(1)
        joints = rest_joint_positions.expand(len(rest_vertices), -1, -1)
        distance = distance_to_bones(rest_vertices, joints, owner, tip)
        own = distance.gather(1, dominant.long().unsqueeze(1)).squeeze(1)
        radius = torch.zeros(len(parents), dtype=own.dtype).scatter_reduce(
            0, dominant.long(), own, reduce="amax")
        return cls(radius, owner, tip)

    @classmethod
    def from_body(cls, body, shape: Tensor) -> "BoneCapsules":
        """The capsules of a :class:`~swingar_pyg.world.body.BodyModel` with ``shape``."""
        rest = rest_pose(body, shape)
        indices, weights = body.skinning()
        return cls.fit(rest.vertices[0], indices, weights, rest.joint_positions[0], body.parents)

    def clearance(self, points: Tensor, joint_positions: Tensor) -> Tensor:
        """:math:`c(\\mathbf{x})` ``(M,)`` for points ``(M, 3)`` and the posed joint
        heads ``(J, 3)`` (or one row per point, ``(M, J, 3)``)."""
        if joint_positions.dim() == 2:
            joint_positions = joint_positions.expand(len(points), -1, -1)
        distance = distance_to_bones(points, joint_positions.to(points), self.owner.to(
            points.device), self.tip.to(points.device))
        return (distance - self.radius.to(points)).amin(dim=1)

    def near(self, points: Tensor, joint_positions: Tensor, margin: float = 0.03) -> Tensor:
        """``(M,)`` bool: points that may be inside the body (clearance < margin)."""
        return self.clearance(points, joint_positions) < margin
