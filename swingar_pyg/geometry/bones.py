r"""A rig's bones as line segments, and distances from points to them.

Joint :math:`j` moves the segments from its head :math:`\mathbf{p}_j` to the
head of each of its children; a joint without children (a head, a toe, a
fingertip) owns the point :math:`\mathbf{p}_j` alone. A point's distance to
joint :math:`j` is its distance to the closest of these. Because a joint's
segments move rigidly with its skinning transform, the distance is the same in
the posed body and, for the point carried back by that transform, in the rest
pose.
"""

from __future__ import annotations

import torch
from torch import Tensor


def bone_segments(parents: tuple[int, ...] | list[int]) -> tuple[Tensor, Tensor]:
    """``(owner, tip)`` joint indices of every bone segment of a rig whose joint
    ``k`` has parent ``parents[k]`` (``-1`` for the root): one segment per
    parent–child pair, owned by the parent, and a point segment per leaf joint.

    Raises:
        ValueError: if a parent index is out of range or not smaller than its
            child's (joints must be in topological order).
    """
    owner, tip = [], []
    for child, parent in enumerate(parents):
        if parent >= child or parent < -1:
            raise ValueError(f"joint {child} has parent {parent}; parents must come before "
                             "their children (and the root's parent is -1)")
        if parent >= 0:
            owner.append(parent)
            tip.append(child)
    has_child = set(owner)
    for joint in range(len(parents)):
        if joint not in has_child:
            owner.append(joint)
            tip.append(joint)
    return torch.tensor(owner), torch.tensor(tip)


def distance_to_bones(points: Tensor, joint_positions: Tensor, owner: Tensor,
                      tip: Tensor) -> Tensor:
    r"""Distance of each point to each joint's bone segments.

    Args:
        points: ``(M, 3)``.
        joint_positions: ``(M, J, 3)`` the joint heads of the body each point is
            measured against (one row per point, so points on different bodies
            mix freely).
        owner, tip: the segments of :func:`bone_segments`.

    Returns:
        ``(M, J)``: :math:`\min_{s \text{ of } j} \lVert \mathbf{x} - \mathrm{seg}_s \rVert`.
    """
    start, end = joint_positions[:, owner], joint_positions[:, tip]  # (M, B, 3)
    along = end - start
    offset = points[:, None] - start
    length2 = along.square().sum(-1)
    # A point segment (length 0) has t = 0: its distance is to the head itself.
    t = torch.where(length2 > 0, (offset * along).sum(-1) / length2.clamp_min(1e-30),
                    torch.zeros_like(length2)).clamp(0.0, 1.0)
    distance = (offset - t.unsqueeze(-1) * along).norm(dim=-1)
    per_joint = distance.new_full((len(points), joint_positions.shape[1]), torch.inf)
    return per_joint.scatter_reduce(1, owner.to(points.device).expand(len(points), -1),
                                    distance, reduce="amin")
