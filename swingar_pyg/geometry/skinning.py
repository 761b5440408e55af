"""Linear blend skinning and rotations, batched and differentiable."""

from __future__ import annotations

import torch
from torch import Tensor


def linear_blend_skinning(rest: Tensor, joint_indices: Tensor, joint_weights: Tensor,
                          transforms: Tensor) -> Tensor:
    r"""Skins rest points by per-joint rigid transforms.

    .. math::
        \mathbf{x}_i(t) = \sum_{k} w_{ik}\, \mathbf{G}_{j_{ik}}(t)
        \begin{bmatrix} \mathbf{x}_i \\ 1 \end{bmatrix}

    Args:
        rest: ``(N, 3)`` rest positions.
        joint_indices: ``(N, K)`` joints each point follows.
        joint_weights: ``(N, K)`` their weights (rows sum to 1).
        transforms: ``(T, J, 4, 4)`` skinning transforms.

    Returns:
        ``(T, N, 3)`` skinned positions.
    """
    rotation = transforms[:, joint_indices, :3, :3]  # (T, N, K, 3, 3)
    translation = transforms[:, joint_indices, :3, 3]  # (T, N, K, 3)
    moved = (rotation @ rest[None, :, None, :, None]).squeeze(-1) + translation
    return (joint_weights[None, ..., None] * moved).sum(dim=2)


def axis_angle_to_matrix(axis_angle: Tensor) -> Tensor:
    r"""Rotation matrices ``(..., 3, 3)`` from axis-angle vectors ``(..., 3)``
    (Rodrigues' formula; exact at zero angle)."""
    angle = axis_angle.norm(dim=-1, keepdim=True)
    axis = axis_angle / angle.clamp_min(1e-12)
    x, y, z = axis.unbind(-1)
    zero = torch.zeros_like(x)
    cross = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).view(*x.shape, 3, 3)
    sin, cos = torch.sin(angle)[..., None], torch.cos(angle)[..., None]
    eye = torch.eye(3, dtype=axis_angle.dtype, device=axis_angle.device)
    return eye + sin * cross + (1 - cos) * (cross @ cross)
