"""Streaming inference: one new body pose in, the garment at that frame out.

The stream caches what does not change (the garment encoding :math:`M_g`, the
shape code, the attention graph), the last ``m + 1`` poses and the input terms
of :math:`M_d` for the last three frames (each frame's input to :math:`M_d` is
in its own canonical frame, so it is the same in every window). A new frame runs
the motion encoder over its pose window, :math:`E`, :math:`P` and skinning once,
the input maps of :math:`M_d` on that frame, and the recurrence over the three
cached terms: three FCA maps where re-running the window would take six (the
first step starts from the zero state, whose state maps vanish). Its output
equals the estimator's on the same window (frame 0 is repeated before the second
frame, as in training).
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
        compile: run the per-frame garment work through :func:`torch.compile`
            with dynamic shapes, so one compilation (tens of seconds, once per
            process) serves every garment size; each frame then costs about half.
            It pays on long or live streams.
    """

    def __init__(self, estimator: SwinGarEstimator, garment, body_shape: Tensor, fps: float,
                 timer: Callable[[str], ContextManager] | None = None, compile: bool = False):
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
            edge_index, self.features, self.shape_code = estimator.encode_garment(garment)
        self.gate = estimator.clearance_gate(garment.fit, garment.edge_index, garment.rest)
        # EdgeIndex does not trace; compiled code gets the plain tensor.
        self.edge_index = edge_index.as_tensor() if compile else edge_index
        self._rotations: deque[Tensor] = deque(maxlen=history + 1)
        self._translations: deque[Tensor] = deque(maxlen=history + 1)
        self._input_terms: deque[Tensor] = deque(maxlen=TARGET_FRAMES)
        stages = (self._skin, self._detail_input_terms, self._refine)
        if compile:
            stages = tuple(torch.compile(stage, dynamic=True) for stage in stages)
        self._skin_stage, self._input_terms_stage, self._refine_stage = stages

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
            skinned = self._skin_stage(motion, joint_transforms.to(features))
            record(skinned)
        if model.detail is None:
            return skinned
        with self._timer("detail (M_d)") as record:
            body_code = model.body_codes(self.body_shape.expand(self.graphs, -1),
                                         windows)[:, 0]
            self._input_terms.append(self._input_terms_stage(
                skinned, joint_positions.to(features), frame_rotation, frame_origin))
            terms = list(self._input_terms)
            # distinct copies: compiled code would recompile for aliased inputs
            terms = [terms[0].clone() for _ in range(TARGET_FRAMES - len(terms))] + terms
            refined = self._refine_stage(*terms, skinned, body_code, frame_rotation)
            record(refined)
        return refined

    def _skin(self, motion: Tensor, joint_transforms: Tensor) -> Tensor:
        transforms = joint_transforms[None].expand(self.graphs, -1, -1, -1)
        return self.estimator.skin(self.garment, self.edge_index, self.features,
                                   self.shape_code, motion, transforms, self.gate)

    def _detail_input_terms(self, skinned: Tensor, joint_positions: Tensor,
                            frame_rotation: Tensor, frame_origin: Tensor) -> Tensor:
        inputs = self.estimator.detail_inputs(
            skinned, joint_positions[None].expand(self.graphs, -1, -1),
            frame_rotation[None].expand(self.graphs, -1, -1),
            frame_origin[None].expand(self.graphs, -1), self.batch)
        return self.estimator.detail.input_terms(inputs, self.edge_index)

    def _refine(self, terms_before_last: Tensor, terms_last: Tensor, terms_now: Tensor,
                skinned: Tensor, body_code: Tensor, frame_rotation: Tensor) -> Tensor:
        """The recurrence over the input terms of frames ``t-2, t-1, t`` from
        the zero state, then the correction of frame ``t``."""
        detail = self.estimator.detail
        state = detail.step_from_input_terms(terms_before_last, self.edge_index)
        state = detail.step_from_input_terms(terms_last, self.edge_index, state)
        state = detail.step_from_input_terms(terms_now, self.edge_index, state)
        return self.estimator.correct(skinned, state[0], body_code,
                                      frame_rotation[None].expand(self.graphs, -1, -1),
                                      self.batch, self.gate)
