"""BVH motion capture: reading (any skeleton, any channel order), forward kinematics
and resampling. Units and axes stay the file's here; :mod:`swingar_pyg.world.retarget`
converts them once, when a clip is put on a body.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

_AXES = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POSITIONS = ("Xposition", "Yposition", "Zposition")


@dataclass(frozen=True)
class BVHClip:
    """A parsed BVH clip, in the file's units and axes.

    Attributes:
        joint_names: ``J`` names in file order (End Sites excluded).
        parents: ``(J,)`` parent index, -1 for the root.
        offsets: ``(J, 3)`` joint offsets from their parents.
        local_rotations: ``(T, J, 3, 3)`` joint rotations relative to their parents.
        root_positions: ``(T, 3)`` root position channels (or the root offset).
        frame_time: seconds per frame.
    """

    joint_names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    local_rotations: np.ndarray
    root_positions: np.ndarray
    frame_time: float

    @property
    def num_frames(self) -> int:
        return self.local_rotations.shape[0]

    def world(self) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: world rotations ``(T, J, 3, 3)`` and positions ``(T, J, 3)``."""
        frames, joints = self.local_rotations.shape[:2]
        rotations = np.empty_like(self.local_rotations)
        positions = np.empty((frames, joints, 3))
        for j, parent in enumerate(self.parents):
            if parent < 0:
                rotations[:, j] = self.local_rotations[:, j]
                positions[:, j] = self.root_positions
            else:
                rotations[:, j] = rotations[:, parent] @ self.local_rotations[:, j]
                positions[:, j] = positions[:, parent] + rotations[:, parent] @ self.offsets[j]
        return rotations, positions

    def resample(self, fps: float) -> "BVHClip":
        """The clip at ``fps``: rotations by slerp, root positions linearly."""
        if fps <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        source = np.arange(self.num_frames) * self.frame_time
        # Frame times are rounded in files (CMU: .0083333 for 1/120 s): a sample within
        # half a source frame of the end still belongs to the clip.
        target = np.arange(0.0, source[-1] + 0.5 * self.frame_time, 1.0 / fps)
        target = np.minimum(target, source[-1])
        joints = len(self.joint_names)
        rotations = np.empty((len(target), joints, 3, 3))
        for j in range(joints):
            slerp = Slerp(source, Rotation.from_matrix(self.local_rotations[:, j]))
            rotations[:, j] = slerp(target).as_matrix()
        positions = np.stack([np.interp(target, source, self.root_positions[:, k])
                              for k in range(3)], axis=1)
        return BVHClip(self.joint_names, self.parents, self.offsets, rotations, positions,
                       1.0 / fps)


def read_bvh(path: str | Path) -> BVHClip:
    """Parses a BVH file.

    Raises:
        ValueError: naming the line, for a malformed hierarchy, an unknown channel,
            a frame with the wrong number of values, or non-numeric data.
    """
    path = Path(path)
    tokens = [(number, line.split()) for number, line in
              enumerate(path.read_text().splitlines(), start=1) if line.strip()]
    names, parents, offsets, channels = [], [], [], []
    stack: list[int] = []
    position = 0

    def fail(message: str) -> ValueError:
        line = tokens[min(position, len(tokens) - 1)][0] if tokens else 0
        return ValueError(f"{path.name}, line {line}: {message}")

    if not tokens or tokens[0][1][0] != "HIERARCHY":
        raise fail("a BVH file starts with HIERARCHY")
    position = 1
    pending: int | None = None  # the joint whose block is being read (None: an End Site)
    in_end_site = False
    try:
        while position < len(tokens) and tokens[position][1][0] != "MOTION":
            words = tokens[position][1]
            keyword = words[0]
            if keyword in ("ROOT", "JOINT"):
                if (keyword == "ROOT") != (not stack and not names):
                    raise fail(f"{keyword} {words[1:]} is out of place")
                names.append(" ".join(words[1:]))
                parents.append(stack[-1] if stack else -1)
                offsets.append(np.zeros(3))
                channels.append([])
                pending = len(names) - 1
            elif keyword == "End":
                in_end_site = True
            elif keyword == "{":
                if in_end_site:
                    stack.append(-1)
                elif pending is None:
                    raise fail("'{' without a joint")
                else:
                    stack.append(pending)
                    pending = None
            elif keyword == "}":
                if not stack:
                    raise fail("unbalanced '}'")
                if stack.pop() == -1:
                    in_end_site = False
            elif keyword == "OFFSET":
                if not in_end_site:
                    offsets[stack[-1]] = np.array([float(v) for v in words[1:4]])
            elif keyword == "CHANNELS":
                count = int(words[1])
                names_ = words[2:2 + count]
                if len(names_) != count:
                    raise fail(f"CHANNELS says {count} but lists {len(names_)}")
                for channel in names_:
                    if channel not in _AXES and channel not in _POSITIONS:
                        raise fail(f"unknown channel {channel!r}")
                channels[stack[-1]] = names_
            else:
                raise fail(f"unexpected {keyword!r} in the hierarchy")
            position += 1
        if stack:
            raise fail("the hierarchy ends with unclosed joints")
        if position >= len(tokens):
            raise fail("no MOTION section")
        frames = int(tokens[position + 1][1][-1])
        frame_time = float(tokens[position + 2][1][-1])
        position += 3
        rows = [tokens[position + k][1] for k in range(frames) if position + k < len(tokens)]
    except (IndexError, ValueError) as error:
        if isinstance(error, ValueError) and str(error).startswith(path.name):
            raise
        raise fail(f"malformed ({error})") from None
    if not names:
        raise fail("no joints")
    if len(rows) != frames:
        raise ValueError(f"{path.name}: the header promises {frames} frames, the file has "
                         f"{len(rows)}")
    width = sum(len(c) for c in channels)
    for k, row in enumerate(rows):
        if len(row) != width:
            raise ValueError(f"{path.name}: frame {k} has {len(row)} values, the channels "
                             f"need {width}")
    try:
        data = np.array([[float(v) for v in row] for row in rows]).reshape(frames, width)
    except ValueError:
        raise ValueError(f"{path.name}: the MOTION section holds a non-numeric value") from None
    if not np.isfinite(data).all():
        raise ValueError(f"{path.name}: the MOTION section holds non-finite values")

    joints = len(names)
    rotations = np.tile(np.eye(3), (frames, joints, 1, 1))
    root_positions = np.tile(offsets[0], (frames, 1))
    column = 0
    for j, joint_channels in enumerate(channels):
        order = "".join(_AXES[c] for c in joint_channels if c in _AXES)
        angles = [data[:, column + k] for k, c in enumerate(joint_channels) if c in _AXES]
        for k, channel in enumerate(joint_channels):
            if channel in _POSITIONS and j == 0:
                root_positions[:, _POSITIONS.index(channel)] = data[:, column + k]
        if order:  # uppercase: intrinsic rotations, applied in the listed order
            rotations[:, j] = Rotation.from_euler(order, np.stack(angles, axis=1),
                                                  degrees=True).as_matrix()
        column += len(joint_channels)
    return BVHClip(tuple(names), np.array(parents), np.array(offsets), rotations,
                   root_positions, frame_time)
