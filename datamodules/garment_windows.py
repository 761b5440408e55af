"""Windows of simulated sequences as :class:`~swingar_pyg.models.GarmentWindow`
samples: the three target frames ``t-2, t-1, t`` (repeating frame 0 at the
start of a sequence, as streaming inference does) with each frame's pose
history of ``m`` frames."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import Dataset

from datamodules.feature_cache import FeatureSettings, current_feature_cache
from swingar_pyg.models import GarmentWindow, pose_window
from swingar_pyg.models.estimator import TARGET_FRAMES
from swingar_pyg.models.garment_window import dense_skinning_weights


@dataclass
class _Garment:
    rest: Tensor
    normal: Tensor
    fit: Tensor
    prior_weights: Tensor
    edge_index: Tensor
    descriptor: Tensor | None


@dataclass
class _Sequence:
    id: str
    garment: str
    motion: str
    fps: float
    body_shape: Tensor
    target: Tensor
    rigid: Tensor
    rotations: Tensor
    translation: Tensor
    joint_transforms: Tensor
    joint_positions: Tensor
    body: dict[str, Tensor]


class GarmentWindowDataset(Dataset):
    """All windows of a dataset split file, held in memory.

    Args:
        path: a split file whose feature cache for ``settings`` is current
            (:func:`~datamodules.feature_cache.ensure_feature_cache`).
        settings: the cache settings expected (a mismatch raises).
        history: pose history ``m``.
        stride: keep every ``stride``-th target frame of each sequence.
    """

    def __init__(self, path: str | Path, settings: FeatureSettings, history: int = 64,
                 stride: int = 1):
        import h5py

        if stride < 1:
            raise ValueError(f"stride must be >= 1, got {stride}")
        cache_path = current_feature_cache(path, settings)
        if cache_path is None:
            raise ValueError(f"{path} has no current feature cache for {settings}; "
                             "run the datamodule's prepare_data() first")
        self.history = history
        with h5py.File(path, "r") as file, h5py.File(cache_path, "r") as cache:
            self.sequences = [self._read_sequence(file, cache, k)
                              for k in sorted(file["sequences"])]
            joints = self.sequences[0].joint_transforms.shape[1] if self.sequences else 0
            used = {s.garment for s in self.sequences}
            self.garments = {name: self._read_garment(file, cache, name, joints)
                             for name in used}
        self.windows = [(k, t) for k, s in enumerate(self.sequences)
                        for t in range(0, len(s.target), stride)]

    @staticmethod
    def _read_garment(file, cache_file, name: str, joints: int) -> _Garment:
        source, cache = file[f"garments/{name}"], cache_file[f"garments/{name}"]
        descriptor = cache["descriptor"][:] if "descriptor" in cache else None
        return _Garment(
            rest=torch.as_tensor(source["rest_vertices"][:]),
            normal=torch.as_tensor(cache["normals"][:]),
            fit=torch.as_tensor(source["fit"][:]),
            prior_weights=dense_skinning_weights(source["skin_indices"][:],
                                                 source["skin_weights"][:], joints),
            edge_index=torch.as_tensor(cache["edge_index"][:]),
            descriptor=None if descriptor is None else torch.as_tensor(descriptor))

    @staticmethod
    def _read_sequence(file, cache_file, sequence_id: str) -> _Sequence:
        source = file[f"sequences/{sequence_id}"]
        cache = cache_file[f"sequences/{sequence_id}"]
        transforms = torch.as_tensor(cache["joint_transforms"][:])
        bottom = torch.tensor([0.0, 0.0, 0.0, 1.0]).expand(*transforms.shape[:2], 1, 4)
        body = {name: torch.as_tensor(cache[name][:]) for name in
                ("body_points", "body_normals", "body_skin_weights")}
        body["body_skin_indices"] = torch.as_tensor(cache["body_skin_indices"][:].astype(np.int64))
        return _Sequence(
            id=sequence_id, garment=str(source.attrs["garment"]),
            motion=str(source.attrs["motion"]), fps=float(source.attrs["fps"]),
            body_shape=torch.as_tensor(source["body_shape"][:]),
            target=torch.as_tensor(source["garment_vertices"][:]),
            rigid=torch.as_tensor(source["rigid_vertices"][:]),
            rotations=torch.as_tensor(source["rotations"][:]),
            translation=torch.as_tensor(source["translation"][:]),
            joint_transforms=torch.cat([transforms, bottom], dim=2),
            joint_positions=torch.as_tensor(cache["joint_positions"][:]),
            body=body)

    def __len__(self) -> int:
        return len(self.windows)

    def __getitem__(self, index: int) -> GarmentWindow:
        sequence = self.sequences[self.windows[index][0]]
        t = self.windows[index][1]
        garment = self.garments[sequence.garment]
        frames = [max(t - k, 0) for k in reversed(range(TARGET_FRAMES))]
        windows = [pose_window(sequence.rotations, sequence.translation, sequence.fps, k,
                               self.history) for k in frames]
        features, masks, rotation, origin = zip(*windows)
        data = GarmentWindow(
            rest=garment.rest, normal=garment.normal, fit=garment.fit,
            prior_weights=garment.prior_weights, edge_index=garment.edge_index,
            target=sequence.target[frames].transpose(0, 1),
            rigid=sequence.rigid[frames].transpose(0, 1),
            body_shape=sequence.body_shape[None],
            pose_history=torch.stack(features)[None], history_mask=torch.stack(masks)[None],
            frame_rotation=torch.stack(rotation)[None], frame_origin=torch.stack(origin)[None],
            joint_transforms=sequence.joint_transforms[frames][None],
            joint_positions=sequence.joint_positions[frames][None],
            garment=sequence.garment, motion=sequence.motion, sequence=sequence.id, frame=t,
            num_nodes=len(garment.rest),
            **{name: value[None] for name, value in sequence.body.items()})
        if garment.descriptor is not None:
            data.descriptor = garment.descriptor[None]
        return data

    def describe(self) -> dict:
        """Counts for logs: sequences, windows, garments, motions."""
        return {"sequences": len(self.sequences), "windows": len(self),
                "garments": sorted(self.garments),
                "motions": sorted({s.motion for s in self.sequences})}

