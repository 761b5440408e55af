"""Body models behind one small interface, and the default: anny (Apache-2.0, CC0 data).

Pose convention (shared with SMPL): ``rotations[:, j]`` rotates joint ``j`` relative
to its rest orientation, in axes that are world-aligned at rest; ``rotations[:, 0]``
is the root's world rotation and ``translation`` the root's world position. Metres,
+Z up, the body faces -Y. Identity rotations and zero translation give the rest
pose (an A-pose for anny).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import torch
from torch import Tensor

from swingar_pyg.verbosity import init_warp


@dataclass(frozen=True)
class PosedBody:
    """A body in a sequence of poses.

    Attributes:
        vertices: ``(T, V, 3)`` posed surface.
        joint_transforms: ``(T, J, 4, 4)`` skinning transforms: a rest-pose point
            ``x`` bound to joint ``j`` moves to ``joint_transforms[t, j] @ [x, 1]``.
        joint_positions: ``(T, J, 3)`` joint (bone head) positions.
    """

    vertices: Tensor
    joint_transforms: Tensor
    joint_positions: Tensor


def check_pose(rotations: Tensor, translation: Tensor, joints: int) -> None:
    """Raises ``ValueError`` unless ``rotations`` is ``(T, joints, 3, 3)`` and
    ``translation`` ``(T, 3)``, both finite."""
    if rotations.dim() != 4 or rotations.shape[1:] != (joints, 3, 3):
        raise ValueError(f"rotations must have shape (T, {joints}, 3, 3), "
                         f"got {tuple(rotations.shape)}")
    if translation.shape != (rotations.shape[0], 3):
        raise ValueError(f"translation must have shape ({rotations.shape[0]}, 3), "
                         f"got {tuple(translation.shape)}")
    if not (torch.isfinite(rotations).all() and torch.isfinite(translation).all()):
        raise ValueError("rotations and translation must be finite")


def rest_pose(body: "BodyModel", shape: Tensor) -> PosedBody:
    """``body`` with ``shape`` in its rest pose (identity rotations, root at the
    origin): one frame."""
    joints = len(body.joint_names)
    return body.pose(shape, torch.eye(3).expand(1, joints, 3, 3), torch.zeros(1, 3))


class BodyModel(Protocol):
    """What the rest of the package needs from a body model."""

    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    num_shape_parameters: int

    @property
    def faces(self) -> Tensor:
        """``(F, 3)`` long triangle faces of the body surface."""

    def default_shape(self) -> Tensor:
        """``(S,)`` the average body's shape parameters."""

    def rest_vertices(self, shape: Tensor) -> Tensor:
        """``(V, 3)`` the body in its rest pose."""

    def pose(self, shape: Tensor, rotations: Tensor, translation: Tensor) -> PosedBody:
        """Poses ``shape`` (``(S,)``) by ``rotations`` ``(T, J, 3, 3)`` and
        ``translation`` ``(T, 3)`` (see the module docstring)."""

    def skinning(self) -> tuple[Tensor, Tensor]:
        """``(indices, weights)``, each ``(V, K)``: the joints each vertex follows."""


@lru_cache(maxsize=None)
def _anny_model(rig: str) -> torch.nn.Module:
    # The first build in a machine writes ~0.8 GB under ~/.cache/anny and takes
    # about a minute; later builds read that cache in under a second. Warp (anny's
    # skinning) is initialised first, without its start-up banner unless asked.
    init_warp()
    import anny

    return anny.Anny(rig=rig).to(torch.float32).eval()


class AnnyBody:
    """The anny body with its CMU-named ``cmu_mb`` rig (31 joints, 13,718 vertices).

    Shape parameters are anny's phenotype values in ``[0, 1]``: gender, age, muscle,
    weight, height, proportions (0.5 each is the average body). The model is built
    once per process and shared.
    """

    def __init__(self, rig: str = "cmu_mb", frames_per_chunk: int = 64):
        self._model = _anny_model(rig)
        self.joint_names = tuple(self._model.bone_labels)
        self.parents = tuple(int(p) for p in self._model.bone_parents)
        self.shape_names = tuple(self._model.phenotype_labels)
        self.num_shape_parameters = len(self.shape_names)
        self.frames_per_chunk = frames_per_chunk

    @property
    def faces(self) -> Tensor:
        return self._model.get_triangular_faces().long()

    def default_shape(self) -> Tensor:
        return torch.full((self.num_shape_parameters,), 0.5)

    def _check_shape(self, shape: Tensor) -> Tensor:
        shape = torch.as_tensor(shape, dtype=torch.float32)
        if shape.shape != (self.num_shape_parameters,):
            raise ValueError(f"shape must have {self.num_shape_parameters} values "
                             f"({', '.join(self.shape_names)}), got {tuple(shape.shape)}")
        if not torch.isfinite(shape).all() or (shape < 0).any() or (shape > 1).any():
            raise ValueError(f"anny shape parameters must lie in [0, 1], got {shape.tolist()}")
        return shape

    def rest_vertices(self, shape: Tensor) -> Tensor:
        return rest_pose(self, shape).vertices[0]

    def pose(self, shape: Tensor, rotations: Tensor, translation: Tensor) -> PosedBody:
        shape = self._check_shape(shape)
        joints = len(self.joint_names)
        check_pose(rotations, translation, joints)
        # anny skins from its own rest mesh, whose root is not at the origin; our
        # rest pose is the identity pose, so skinning transforms are re-based onto it.
        identity = torch.eye(4).repeat(1, joints, 1, 1)
        _, from_identity = self._forward(shape, identity)
        to_rest = torch.linalg.inv(from_identity)
        pieces = []
        for start in range(0, rotations.shape[0], self.frames_per_chunk):
            rot = rotations[start:start + self.frames_per_chunk].float()
            frames = rot.shape[0]
            parameters = torch.eye(4).repeat(frames, joints, 1, 1)
            parameters[:, :, :3, :3] = rot
            parameters[:, 0, :3, 3] = translation[start:start + frames].float()
            out, transforms = self._forward(shape, parameters)
            pieces.append((out["vertices"], transforms @ to_rest,
                           out["bone_poses"][..., :3, 3]))
        vertices, transforms, positions = (torch.cat(parts) for parts in zip(*pieces))
        return PosedBody(vertices, transforms, positions)

    def _forward(self, shape: Tensor, parameters: Tensor) -> tuple[dict, Tensor]:
        with torch.no_grad():
            out = self._model(parameters, phenotype_kwargs=shape.expand(len(parameters), -1))
            transforms, _ = self._model.get_bone_transforms(parameters, out["rest_bone_poses"])
        return out, transforms

    def skinning(self) -> tuple[Tensor, Tensor]:
        return (self._model.vertex_bone_indices.long(),
                self._model.vertex_bone_weights.float())
