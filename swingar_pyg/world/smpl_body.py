"""SMPL behind the :class:`~swingar_pyg.world.body.BodyModel` interface, for users
who own SMPL model files (``smplx`` reads them; extra ``smpl``). Nothing of SMPL
ships with this package.

SMPL is in metres, +Y up, facing +Z, with its root (the pelvis) wherever the
shape puts it; this package is in metres, +Z up, facing -Y, root at the origin
in the rest pose. The adapter converts at its edge, once: a point maps as
``(x, y, z) -> (x, -z, y)`` and rotations are conjugated by that map. SMPL's
local joint rotations are relative to the parent in axes that are world-aligned
at rest, which is this package's pose convention (:mod:`~swingar_pyg.world.body`);
its rest pose is a T-pose. Posed vertices include SMPL's pose blend shapes, so
they differ from rigid skinning of the rest mesh by those offsets.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import Tensor

from swingar_pyg.world.body import PosedBody, check_pose, rest_pose

SMPL_JOINTS = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
               "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
               "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
               "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand",
               "right_hand")

# The shipped CMU clips onto SMPL, for :func:`~swingar_pyg.world.retarget.retarget`.
CMU_TO_SMPL = {
    "Hips": "pelvis", "LowerBack": "spine1", "Spine": "spine2", "Spine1": "spine3",
    "Neck": "neck", "Head": "head",
    "LeftUpLeg": "left_hip", "LeftLeg": "left_knee", "LeftFoot": "left_ankle",
    "LeftToeBase": "left_foot", "RightUpLeg": "right_hip", "RightLeg": "right_knee",
    "RightFoot": "right_ankle", "RightToeBase": "right_foot",
    "LeftShoulder": "left_collar", "LeftArm": "left_shoulder", "LeftForeArm": "left_elbow",
    "LeftHand": "left_wrist", "RightShoulder": "right_collar", "RightArm": "right_shoulder",
    "RightForeArm": "right_elbow", "RightHand": "right_wrist",
}

# SMPL's frame (+Y up, facing +Z) to this package's (+Z up, facing -Y).
SMPL_TO_Z_UP = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


class SMPLBody:
    """An SMPL body (via ``smplx``) as a :class:`~swingar_pyg.world.body.BodyModel`.

    Args:
        model_path: an SMPL model file (``.pkl``) or a folder holding
            ``SMPL_<GENDER>.pkl``.
        gender: ``"neutral"``, ``"male"`` or ``"female"``.
        num_betas: shape coefficients used (SMPL's :math:`\\beta`, any real values).
        skinning_joints: joints kept per vertex in :meth:`skinning`.
    """

    def __init__(self, model_path: str | Path, gender: str = "neutral", num_betas: int = 10,
                 skinning_joints: int = 4):
        try:
            import smplx
        except ImportError as error:
            raise ImportError("SMPLBody needs smplx: pip install 'swingar-pyg[smpl]'") from error
        if not Path(model_path).exists():
            raise ValueError(f"no SMPL model at {model_path}")
        self._model = smplx.SMPL(str(model_path), gender=gender, num_betas=num_betas,
                                 batch_size=1).eval()
        if self._model.J_regressor.shape[0] != len(SMPL_JOINTS):
            raise ValueError(f"{model_path} has {self._model.J_regressor.shape[0]} joints; an "
                             f"SMPL model has {len(SMPL_JOINTS)}")
        self.joint_names = SMPL_JOINTS
        self.parents = (-1,) + tuple(int(p) for p in self._model.parents[1:].tolist())
        self.num_shape_parameters = self._model.num_betas
        self.skinning_joints = skinning_joints

    @property
    def faces(self) -> Tensor:
        return self._model.faces_tensor.long()

    def default_shape(self) -> Tensor:
        return torch.zeros(self.num_shape_parameters)

    def _check_shape(self, shape: Tensor) -> Tensor:
        shape = torch.as_tensor(shape, dtype=torch.float32)
        if shape.shape != (self.num_shape_parameters,) or not torch.isfinite(shape).all():
            raise ValueError(f"shape must be {self.num_shape_parameters} finite SMPL betas, got "
                             f"{tuple(shape.shape)}")
        return shape

    def rest_vertices(self, shape: Tensor) -> Tensor:
        return rest_pose(self, shape).vertices[0]

    def pose(self, shape: Tensor, rotations: Tensor, translation: Tensor) -> PosedBody:
        from smplx.lbs import batch_rigid_transform, blend_shapes, lbs, vertices2joints

        shape = self._check_shape(shape)
        joints = len(self.joint_names)
        check_pose(rotations, translation, joints)
        m = self._model
        frames = rotations.shape[0]
        to_z_up = SMPL_TO_Z_UP
        local = to_z_up.T @ rotations.float() @ to_z_up  # into SMPL's axes
        betas = shape[None].expand(frames, -1)
        with torch.no_grad():
            vertices, _ = lbs(betas, local, m.v_template, m.shapedirs, m.posedirs,
                              m.J_regressor, m.parents, m.lbs_weights, pose2rot=False)
            rest_joints = vertices2joints(m.J_regressor, m.v_template[None] +
                                          blend_shapes(betas[:1], m.shapedirs))[0]
            posed_joints, relative = batch_rigid_transform(
                local, rest_joints[None].expand(frames, -1, -1), m.parents)
        root = rest_joints[0]
        # In SMPL's axes, rest points are shaped vertices minus the root; posed ones
        # are moved back by the root and on by the translation (given in our axes).
        shift = to_z_up.T @ translation.float().T  # (3, T)
        offset = (shift.T - root)[:, None]  # (T, 1, 3)
        into = torch.eye(4).repeat(frames, joints, 1, 1)
        into[..., :3, 3] = offset
        out_of_rest = torch.eye(4)
        out_of_rest[:3, 3] = root
        smpl_transforms = into @ relative @ out_of_rest
        frame_change = torch.eye(4)
        frame_change[:3, :3] = to_z_up
        transforms = frame_change @ smpl_transforms @ frame_change.T
        return PosedBody((vertices + offset) @ to_z_up.T, transforms,
                         (posed_joints + offset) @ to_z_up.T)

    def skinning(self) -> tuple[Tensor, Tensor]:
        weights = self._model.lbs_weights
        kept, indices = weights.topk(self.skinning_joints, dim=1)
        return indices.long(), kept / kept.sum(dim=1, keepdim=True)
