"""Streaming inference: one new body pose in, the garment at that frame out.

The stream caches what does not change (the garment encoding :math:`M_g`, the
shape code, the attention graph), the last ``m + 1`` poses and, per recent
frame, the skinned garment :math:`\\mathbf{M}_c`, the joint positions and the
body code. A new frame therefore runs the motion encoder over its pose window,
:math:`E`, :math:`P` and skinning once, and :math:`M_d` over the three cached
graphs; its output equals the estimator's on the same window (frame 0 is
repeated before the second frame, as in training).
"""

from __future__ import annotations

from collections import deque
from contextlib import nullcontext
from typing import Callable, ContextManager

import torch
from torch import Tensor

from swingar_pyg.models.estimator import TARGET_FRAMES, SwinGarEstimator, batch_vector
from swingar_pyg.models.pose_features import pose_window


class SwinGarStream:
    """Rolling-cache inference for one garment, or a Batch of garments worn on
    the same body.

    Args:
        estimator: a trained :class:`SwinGarEstimator` (put in eval mode here).
        garment: :class:`~swingar_pyg.models.GarmentWindow` (or Batch) with the
            garment fields: ``rest``, ``normal``, ``fit``, ``prior_weights``,
            ``edge_index`` and, if the estimator uses one, ``descriptor``.
        body_shape: ``(S,)`` shape parameters of the body.
        fps: frame rate of the poses that will be streamed.
        timer: called with a stage name (``"motion code"``, ``"skinning (E, P,
            LBS)"``, ``"detail (M_d)"``), returns a context manager around that
            stage of each step that yields a function taking the stage's output
            tensors (:class:`~swingar_pyg.inference.scene.StageTimer`).
    """

    def __init__(self, estimator: SwinGarEstimator, garment, body_shape: Tensor, fps: float,
                 timer: Callable[[str], ContextManager] | None = None):
        if not fps > 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.estimator = estimator.eval()
        self.garment = garment
        self.fps = float(fps)
        self._timer = timer or (lambda name: nullcontext(lambda *tensors: None))
        self.batch = batch_vector(garment)
        self.graphs = int(self.batch.max()) + 1 if garment.num_nodes else 1
        self.body_shape = body_shape.reshape(1, -1).to(garment.rest)
        history = estimator.history
        with torch.no_grad():
            self.edge_index, self.features, self.shape_code = estimator.encode_garment(garment)
        self._rotations: deque[Tensor] = deque(maxlen=history + 1)
        self._translations: deque[Tensor] = deque(maxlen=history + 1)
        self._recent: deque[tuple[Tensor, Tensor, Tensor]] = deque(maxlen=TARGET_FRAMES)

    @torch.no_grad()
    def step(self, rotations: Tensor, translation: Tensor, joint_transforms: Tensor,
             joint_positions: Tensor) -> Tensor:
        """The garment ``(N, 3)`` at the next frame.

        Args:
            rotations: ``(J, 3, 3)`` joint rotations of the frame.
            translation: ``(3,)`` root position.
            joint_transforms: ``(J, 4, 4)`` the body's skinning transforms.
            joint_positions: ``(J, 3)`` the body's joint positions.
        """
        model = self.estimator
        with self._timer("motion code") as record:
            self._rotations.append(rotations.to(self.garment.rest))
            self._translations.append(translation.to(self.garment.rest))
            features, mask, frame_rotation, frame_origin = pose_window(
                torch.stack(tuple(self._rotations)), torch.stack(tuple(self._translations)),
                self.fps, len(self._rotations) - 1, model.history)
            windows = features[None, None].expand(self.graphs, 1, -1, -1)
            masks = mask[None, None].expand(self.graphs, 1, -1)
            motion = model.motion_codes(windows, masks)[:, 0]
            record(motion)
        with self._timer("skinning (E, P, LBS)") as record:
            transforms = joint_transforms.to(features)[None].expand(self.graphs, -1, -1, -1)
            skinned = model.skin(self.garment, self.edge_index, self.features, self.shape_code,
                                 motion, transforms)
            record(skinned)
        if model.detail is None:
            return skinned
        with self._timer("detail (M_d)") as record:
            code = model.body_codes(self.body_shape.expand(self.graphs, -1), windows)[:, 0]
            self._recent.append((skinned, joint_positions.to(features), code))
            frames = list(self._recent)
            frames = [frames[0]] * (TARGET_FRAMES - len(frames)) + frames
            stacked_skinned = torch.stack([f[0] for f in frames])
            joints = torch.stack([f[1] for f in frames])[None].expand(self.graphs, -1, -1, -1)
            codes = torch.stack([f[2] for f in frames], dim=1)
            refined = model.refine(self.edge_index, self.batch, stacked_skinned, joints, codes,
                                   frame_rotation[None].expand(self.graphs, -1, -1),
                                   frame_origin[None].expand(self.graphs, -1))
            record(refined)
        return refined[-1]
