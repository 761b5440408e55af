r"""Pose-history features for the motion encoder, in a heading-free frame.

Poses follow :mod:`swingar_pyg.world.body`: per-joint rotations ``R_j`` relative
to the rest pose in world-aligned axes, and the root position ``p``; +Z is up and
the rest body faces −Y. A window of poses ending at frame ``t`` is expressed in
the *canonical frame* of ``t``: origin at the root position ``p_t``, axes turned
by the root's heading (a rotation ``R_c`` about +Z). Turning or moving the whole
motion on the floor then leaves the features unchanged, while tilt (the
direction of gravity in the body frame) stays visible.

Per frame ``k`` the features are, with ``J`` joints (``6 J + 6`` numbers):

.. math::
    \bigl[\, \mathrm{6D}(\mathbf{R}_c^\top \mathbf{R}_{k,j})_{j=1..J},\;
    \mathbf{R}_c^\top (\mathbf{p}_k - \mathbf{p}_t),\;
    f\, \mathbf{R}_c^\top (\mathbf{p}_k - \mathbf{p}_{k-1}) \,\bigr]

where 6D takes the first two columns of a rotation and ``f`` is the frame rate
(the velocity is zero at a sequence's first frame). Frames before the sequence
start are zero with mask 0.
"""

from __future__ import annotations

import torch
from torch import Tensor


def pose_feature_size(num_joints: int) -> int:
    """Length of one frame's feature vector for a rig of ``num_joints`` joints."""
    return 6 * num_joints + 6


def heading_rotation(root_rotation: Tensor) -> Tensor:
    """The rotation about +Z that turns the rest forward (−Y) onto the root's
    forward direction projected on the floor; ``(..., 3, 3)`` → ``(..., 3, 3)``.

    When the root faces straight up or down (lying on the floor), its up axis
    projected on the floor serves as forward instead.
    """
    forward = -root_rotation[..., :2, 1]
    up = root_rotation[..., :2, 2]
    lying = forward.norm(dim=-1, keepdim=True) < 1e-4
    heading = torch.where(lying, up, forward)
    heading = heading / heading.norm(dim=-1, keepdim=True)
    sin, cos = heading[..., 0], -heading[..., 1]
    zero, one = torch.zeros_like(sin), torch.ones_like(sin)
    return torch.stack([torch.stack([cos, -sin, zero], -1),
                        torch.stack([sin, cos, zero], -1),
                        torch.stack([zero, zero, one], -1)], -2)


def pose_window(rotations: Tensor, translation: Tensor, fps: float, end: int,
                length: int) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Features of the ``length`` frames ending at frame ``end`` (inclusive).

    Args:
        rotations: ``(T, J, 3, 3)`` joint rotations of a sequence.
        translation: ``(T, 3)`` root positions.
        fps: frames per second.
        end: the window's last frame, ``0 <= end < T``.
        length: frames in the window (the pose history ``m``).

    Returns:
        ``features (length, 6J+6)``, ``mask (length,)`` (1 for real frames),
        ``frame_rotation (3, 3)`` = ``R_c`` and ``frame_origin (3,)`` = ``p_t``.
    """
    frames, joints = rotations.shape[:2]
    if not 0 <= end < frames:
        raise ValueError(f"window end {end} is outside the sequence of {frames} frames")
    if length < 1:
        raise ValueError(f"the pose history needs at least one frame, got {length}")
    start = max(end - length + 1, 0)
    rot = rotations[start:end + 1]
    pos = translation[start:end + 1]
    frames_before = torch.arange(start, end + 1, device=translation.device) - 1
    previous = translation[frames_before.clamp(min=0)]
    frame_rotation = heading_rotation(rotations[end, 0])
    frame_origin = translation[end]
    turn = frame_rotation.T
    local = (turn @ rot)[..., :, :2].transpose(-1, -2).reshape(len(rot), joints * 6)
    offset = (pos - frame_origin) @ turn.T
    velocity = fps * (pos - previous) @ turn.T
    features = rotations.new_zeros(length, pose_feature_size(joints))
    features[length - len(rot):] = torch.cat([local, offset, velocity], dim=-1)
    mask = rotations.new_zeros(length)
    mask[length - len(rot):] = 1.0
    return features, mask, frame_rotation, frame_origin
