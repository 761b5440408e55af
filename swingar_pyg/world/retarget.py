r"""Retargeting motion capture onto a body rig by joint names (docs/design.md §6).

The clip's axes are converted once (BVH: +Y up, facing +Z; here: +Z up, facing
-Y). Frame 0 of a CMU clip is a T-pose while anny rests in an A-pose, so each
body joint :math:`j` first turns its rest bone direction onto the clip's frame-0
direction (:math:`Q_j`, shortest arc), then follows the clip's world rotation
relative to frame 0:

.. math::
    A_j(t) = R_b(t)\, R_b(0)^{\top} Q_j, \qquad
    \text{local}_j(t) = A_{\text{parent}(j)}(t)^{\top} A_j(t),

with :math:`R_b` the world rotation of the mapped clip joint :math:`b`. Joints mapped
to the clip's girdle bones (a joint on one side whose parent is on the midline: the
pelvis' hip bones, the clavicles) keep their parent's :math:`Q`: those directions
differ between skeletons by build, not by pose, and turning anny's hip bones onto
CMU's would pull its hip joints 6 cm towards each other (29 % of the hip width) and
tear the skin between them. Body joints that the map leaves out move rigidly with
their parent. The root's path is scaled by the ratio of hip heights.
"""

from __future__ import annotations

import numpy as np
import torch

from swingar_pyg.world.body import BodyModel, rest_pose
from swingar_pyg.world.bvh import BVHClip
from swingar_pyg.world.motion import Motion, joint_side

# BVH (+Y up, facing +Z) to this project's frame (+Z up, facing -Y).
BVH_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

# The shipped CMU clips (cgspeed conversion) onto anny's cmu_mb rig: same names
# but for the index finger.
CMU_TO_ANNY = {"LeftHandIndex1": "LeftHandFinger1", "RightHandIndex1": "RightHandFinger1"}


def _shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation of least angle taking direction ``a`` to direction ``b``."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis, cos = np.cross(a, b), float(np.dot(a, b))
    if cos < -1 + 1e-9:  # opposite: any perpendicular axis
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + cross + cross @ cross / (1 + cos)


def _girdle(clip: BVHClip, joint: int) -> bool:
    """Whether the clip's ``joint`` is a girdle bone (a hip bone of the pelvis, a
    clavicle): a joint on one side whose parent is on the midline. Decided on the
    clip's skeleton, so that it holds whatever the body calls the joint mapped to it
    (SMPL's ``left_collar`` is CMU's ``LeftShoulder``; SMPL's ``left_hip`` is CMU's
    ``LeftUpLeg``, a thigh)."""
    parent = int(clip.parents[joint])
    return (parent >= 0 and joint_side(clip.joint_names[joint]) != ""
            and joint_side(clip.joint_names[parent]) == "")


def retarget(clip: BVHClip, body: BodyModel, shape: torch.Tensor, fps: float = 30.0,
             joint_map: dict[str, str] | None = None, name: str = "bvh") -> Motion:
    """Puts ``clip`` on ``body`` (of ``shape``) as a :class:`Motion` at ``fps``.

    Args:
        joint_map: clip joint name -> body joint name, for names that differ (the
            default, :data:`CMU_TO_ANNY`, fits the shipped CMU clips and anny).

    Raises:
        ValueError: if the clip's root does not map to the body's root, or no
            joint maps at all.
    """
    joint_map = CMU_TO_ANNY if joint_map is None else joint_map
    clip = clip.resample(fps)
    body_names = list(body.joint_names)
    to_body = {c: joint_map.get(c, c) for c in clip.joint_names}
    mapped = {to_body[c]: k for k, c in enumerate(clip.joint_names) if to_body[c] in body_names}
    if not mapped:
        raise ValueError(f"no clip joint maps onto the body's joints (clip: "
                         f"{', '.join(clip.joint_names[:5])}, ...); give a joint_map")
    if body_names[0] not in mapped or mapped[body_names[0]] != 0:
        raise ValueError(f"the clip's root {clip.joint_names[0]!r} must map to the body's root "
                         f"{body_names[0]!r}")

    world_rotations, world_positions = clip.world()
    world_rotations = BVH_TO_Z_UP @ world_rotations @ BVH_TO_Z_UP.T
    world_positions = world_positions @ BVH_TO_Z_UP.T
    frames = clip.num_frames
    parents = list(body.parents)
    joints = len(body_names)
    rest_heads = rest_pose(body, shape).joint_positions[0].double().numpy()
    children = {j: [c for c in range(joints) if parents[c] == j] for j in range(joints)}

    align = np.tile(np.eye(3), (joints, 1, 1))
    for j in range(1, joints):
        align[j] = align[parents[j]]
        if body_names[j] not in mapped or _girdle(clip, mapped[body_names[j]]):
            continue
        for c in children[j]:
            if body_names[c] not in mapped or "Thumb" in body_names[c] or \
                    joint_side(body_names[c]) not in ("", joint_side(body_names[j])):
                continue
            rest_direction = rest_heads[c] - rest_heads[j]
            clip_direction = (world_positions[0, mapped[body_names[c]]] -
                              world_positions[0, mapped[body_names[j]]])
            if min(np.linalg.norm(rest_direction), np.linalg.norm(clip_direction)) > 1e-6:
                align[j] = _shortest_arc(rest_direction, clip_direction)
                break

    absolute = np.empty((frames, joints, 3, 3))
    for j in range(joints):
        if body_names[j] in mapped:
            b = mapped[body_names[j]]
            absolute[:, j] = world_rotations[:, b] @ world_rotations[0, b].T @ align[j]
        else:  # rigid with its parent (its alignment is the parent's)
            absolute[:, j] = absolute[:, parents[j]]
    local = absolute.copy()
    for j in range(1, joints):
        local[:, j] = np.swapaxes(absolute[:, parents[j]], -1, -2) @ absolute[:, j]

    feet = [mapped[n] for n in ("LeftFoot", "RightFoot") if n in mapped]
    body_feet = [body_names.index(n) for n in ("LeftFoot", "RightFoot") if n in body_names]
    scale = 1.0
    if feet and body_feet:
        clip_hips = world_positions[0, 0, 2] - world_positions[0, feet, 2].mean()
        body_hips = rest_heads[0, 2] - rest_heads[body_feet, 2].mean()
        scale = body_hips / clip_hips
    translation = scale * (world_positions[:, 0] - world_positions[0, 0])
    return Motion(name, torch.tensor(local, dtype=torch.float32),
                  torch.tensor(translation, dtype=torch.float32), fps, tuple(body_names))
