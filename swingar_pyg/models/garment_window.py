"""The estimator's input: one garment on a body over a short window of frames,
as a :class:`torch_geometric.data.Data` that batches garments of any topology
as disjoint graphs."""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor
from torch_geometric.data import Data

from swingar_pyg.geometry import mesh_edge_index, spectral_descriptor, vertex_normals
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA

# Graph-level tensors carry a leading dimension of 1 per garment, so that a
# Batch concatenates them into one row per garment.
GRAPH_LEVEL = ("descriptor", "body_shape", "pose_history", "history_mask",
               "frame_rotation", "frame_origin", "joint_transforms", "joint_positions",
               "body_points", "body_normals", "body_skin_indices", "body_skin_weights")


class GarmentWindow(Data):
    r"""A garment and the body motion around target frames ``t-2, t-1, t``.

    Node-level (``N`` garment vertices, rest pose fitted to the body, metres):

    - ``rest`` ``(N, 3)``, ``normal`` ``(N, 3)``, ``fit`` ``(N,)`` signed
      distance to the rest body, ``prior_weights`` ``(N, J)`` skinning weights
      transferred from the body, ``edge_index`` ``(2, E)`` mesh edges, both ways.
    - For training only: ``target`` ``(N, 3, 3)`` and ``rigid`` ``(N, 3, 3)``,
      ground truth and rigid skinning at the three frames.

    Graph-level (leading dimension 1 per garment):

    - ``descriptor`` ``(1, z)`` spectral descriptor (absent when unused),
      ``body_shape`` ``(1, S)``.
    - ``pose_history`` ``(1, 3, m, F)`` and ``history_mask`` ``(1, 3, m)``: for
      each target frame its own pose window (:func:`pose_window`).
    - ``frame_rotation`` ``(1, 3, 3, 3)``, ``frame_origin`` ``(1, 3, 3)``: the
      canonical frame of each target frame.
    - ``joint_transforms`` ``(1, 3, J, 4, 4)`` skinning transforms and
      ``joint_positions`` ``(1, 3, J, 3)`` of the three frames.
    - Optional, for the collision loss: ``body_points``, ``body_normals``
      ``(1, P, 3)``, ``body_skin_indices``, ``body_skin_weights`` ``(1, P, K)``:
      rest-pose samples of the body surface, posed with the same transforms.
    """

    @classmethod
    def from_garment(cls, garment, num_joints: int, features: dict[str, Any]) -> GarmentWindow:
        """The garment fields (``rest``, ``normal``, ``fit``, ``prior_weights``,
        ``edge_index`` and, if computed, ``descriptor``) of a fitted garment (a
        :class:`~swingar_pyg.world.garment.Garment`: ``mesh``, ``fit``,
        ``skin_indices``, ``skin_weights``) and its :func:`garment_graph_features`."""
        mesh = garment.mesh
        window = cls(
            rest=torch.as_tensor(mesh.vertices, dtype=torch.float32), normal=features["normal"],
            fit=torch.as_tensor(garment.fit, dtype=torch.float32),
            prior_weights=dense_skinning_weights(garment.skin_indices, garment.skin_weights,
                                                 num_joints),
            edge_index=features["edge_index"], num_nodes=mesh.num_vertices)
        if "descriptor" in features:
            window.descriptor = features["descriptor"][None]
        return window

    def __cat_dim__(self, key: str, value: Any, *args, **kwargs) -> Any:
        if key in GRAPH_LEVEL:
            return 0
        return super().__cat_dim__(key, value, *args, **kwargs)


def dense_skinning_weights(indices, weights, num_joints: int) -> Tensor:
    """``(N, K)`` joint indices and weights (numpy or torch) as dense ``(N, J)``
    weights, the estimator's ``prior_weights``."""
    indices = torch.as_tensor(indices).long()
    dense = torch.zeros(len(indices), num_joints)
    return dense.scatter_add_(1, indices, torch.as_tensor(weights, dtype=torch.float32))


def garment_graph_features(mesh, descriptor_size: int | None, sigma: float = DESCRIPTOR_SIGMA,
                           seed: int = 0, weighting: str = "voronoi") -> dict[str, Any]:
    """What the estimator needs of a rest garment mesh beyond its vertices:
    ``edge_index`` (mesh edges, both ways), unit ``normal`` ``(N, 3)`` and, unless
    ``descriptor_size`` is ``None``, the ``descriptor`` (eigenvalues of ``A / N``,
    :func:`~swingar_pyg.geometry.spectral_descriptor` with ``normalize=True``)
    with its ``num_valid`` entries."""
    features: dict[str, Any] = {
        "edge_index": mesh_edge_index(mesh),
        "normal": vertex_normals(torch.as_tensor(mesh.vertices),
                                 torch.as_tensor(mesh.faces)).float()}
    if descriptor_size is not None:
        descriptor = spectral_descriptor(mesh, z=descriptor_size, sigma=sigma, normalize=True,
                                         weighting=weighting, seed=seed)
        features["descriptor"] = torch.as_tensor(descriptor.eigenvalues, dtype=torch.float32)
        features["num_valid"] = descriptor.num_valid
    return features
