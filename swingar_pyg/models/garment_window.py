"""The estimator's input: one garment on a body over a short window of frames,
as a :class:`torch_geometric.data.Data` that batches garments of any topology
as disjoint graphs."""

from __future__ import annotations

from typing import Any

from torch_geometric.data import Data

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
    - ``frame_rotation`` ``(1, 3, 3)``, ``frame_origin`` ``(1, 3)``: the
      canonical frame of the last target frame ``t``.
    - ``joint_transforms`` ``(1, 3, J, 4, 4)`` skinning transforms and
      ``joint_positions`` ``(1, 3, J, 3)`` of the three frames.
    - Optional, for the collision loss: ``body_points``, ``body_normals``
      ``(1, P, 3)``, ``body_skin_indices``, ``body_skin_weights`` ``(1, P, K)``:
      rest-pose samples of the body surface, posed with the same transforms.
    """

    def __cat_dim__(self, key: str, value: Any, *args, **kwargs) -> Any:
        if key in GRAPH_LEVEL:
            return 0
        return super().__cat_dim__(key, value, *args, **kwargs)
