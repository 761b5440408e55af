r"""Pose-history features for the motion encoder, free of heading and floor position.

Poses follow :mod:`swingar_pyg.world.body` (SMPL's convention): joint rotations
``R_j`` relative to the parent at rest, the root's ``R_0`` in world axes, and the
root position ``p``; +Z is up and the rest body faces −Y. The *heading* of a
frame is the root's turn about +Z, ``R_h`` with angle ``ψ``
(:func:`heading_rotation`); only the root carries it. Per frame ``k`` of a
window ending at frame ``t`` the features are (``6 J + 7`` numbers):

.. math::
    \bigl[\, \mathrm{6D}(\mathbf{R}_{h,k}^\top \mathbf{R}_{k,0}),\;
    \mathrm{6D}(\mathbf{R}_{k,j})_{j=1..J-1},\;
    \mathbf{R}_{h,t}^\top (\mathbf{p}_k - \mathbf{p}_t),\;
    f\, \mathbf{R}_{h,t}^\top (\mathbf{p}_k - \mathbf{p}_{k-1}),\;
    f\, \mathrm{wrap}(\psi_k - \psi_{k-1}) \,\bigr]

that is the pose without its heading, the trajectory and velocity in the
*canonical frame* of ``t`` (origin ``p_t``, axes turned by ``R_{h,t}``), and the
rate of turn; 6D takes the first two columns of a rotation and ``f`` is the
frame rate (rates are zero at a sequence's first frame). Turning or moving the
whole motion on the floor leaves the features unchanged, tilt stays visible,
and a body spinning in place looks like a body turning at that rate, however
far it has turned. Frames before the sequence start are zero with mask 0.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from swingar_pyg.geometry.skinning import axis_angle_to_matrix


def pose_feature_size(num_joints: int) -> int:
    """Length of one frame's feature vector for a rig of ``num_joints`` joints."""
    return 6 * num_joints + 7


def heading_angle(root_rotation: Tensor) -> Tensor:
    """The heading ``ψ`` of root rotations ``(..., 3, 3)``: the angle about +Z that
    turns the rest forward (−Y) onto the root's forward direction projected on
    the floor. When the root faces straight up or down (lying on the floor), its
    up axis projected on the floor serves as forward instead."""
    forward = -root_rotation[..., :2, 1]
    up = root_rotation[..., :2, 2]
    lying = forward.norm(dim=-1, keepdim=True) < 1e-4
    heading = torch.where(lying, up, forward)
    return torch.atan2(heading[..., 0], -heading[..., 1])


def heading_rotation(root_rotation: Tensor) -> Tensor:
    """The rotation about +Z by :func:`heading_angle`; ``(..., 3, 3)``."""
    angle = heading_angle(root_rotation)
    zero = torch.zeros_like(angle)
    return axis_angle_to_matrix(torch.stack([zero, zero, angle], dim=-1))


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
        ``features (length, 6J+7)``, ``mask (length,)`` (1 for real frames),
        ``frame_rotation (3, 3)`` = ``R_c`` and ``frame_origin (3,)`` = ``p_t``.
    """
    frames, joints = rotations.shape[:2]
    if not 0 <= end < frames:
        raise ValueError(f"window end {end} is outside the sequence of {frames} frames")
    if length < 1:
        raise ValueError(f"the pose history needs at least one frame, got {length}")
    start = max(end - length + 1, 0)
    frames_before = (torch.arange(start, end + 1, device=translation.device) - 1).clamp(min=0)
    rot = rotations[start:end + 1]
    pos = translation[start:end + 1]
    angle = heading_angle(rotations[start:end + 1, 0])
    turn_rate = torch.remainder(angle - heading_angle(rotations[frames_before, 0]) + math.pi,
                                2 * math.pi) - math.pi
    frame_rotation = heading_rotation(rotations[end, 0])
    frame_origin = translation[end]
    turn = frame_rotation.T
    unturned = rot.clone()
    unturned[:, 0] = heading_rotation(rot[:, 0]).transpose(-1, -2) @ rot[:, 0]
    local = unturned[..., :, :2].transpose(-1, -2).reshape(len(rot), joints * 6)
    offset = (pos - frame_origin) @ turn.T
    velocity = fps * (pos - translation[frames_before]) @ turn.T
    features = rotations.new_zeros(length, pose_feature_size(joints))
    features[length - len(rot):] = torch.cat(
        [local, offset, velocity, fps * turn_rate[:, None]], dim=-1)
    mask = rotations.new_zeros(length)
    mask[length - len(rot):] = 1.0
    return features, mask, frame_rotation, frame_origin
