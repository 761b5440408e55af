"""Collision of cloth vertices with a moving body surface."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch import Tensor

from swingar_pyg.geometry.normals import vertex_normals


@dataclass
class BodyCollider:
    """A body surface over time: ``vertices`` ``(T, V, 3)`` and ``faces`` ``(F, 3)``.

    Each cloth vertex is paired with its nearest body vertex, found in the body as
    it is at that moment (linearly between the previous frame and this one): a
    pairing against the body's end-of-frame pose would put cloth ahead of a fast
    limb inside it, and push it out through the wrong side. Within a frame the
    body vertex and its normal move linearly, and the cloth vertex is kept on
    the outer side of the plane through them, ``thickness`` away.

    The last search is kept: the body at the end of a frame is the body at the
    start of the next, so a frame's recorded penetration and the next frame's
    contacts (and the contacts of a frame that is re-run) share one k-d tree and
    one query.
    """

    vertices: Tensor
    faces: Tensor
    thickness: float = 0.004
    _last_tree: tuple = field(default=(None, None), init=False, repr=False)
    _last_query: tuple = field(default=(None, None, None), init=False, repr=False)

    def __post_init__(self):
        self.normals = vertex_normals(self.vertices, self.faces)

    @property
    def num_frames(self) -> int:
        return self.vertices.shape[0]

    def nearest(self, frame: int, points: Tensor, fraction: float = 1.0) -> Tensor:
        """Index of the nearest body vertex for each point, with the body at
        ``fraction`` of the way from ``frame - 1`` to ``frame``."""
        previous = max(frame - 1, 0)
        # lerp is exact at 0 and 1: the body there is a stored frame
        key = (previous,) if fraction == 0 else (frame,) if fraction == 1 else (
            previous, frame, fraction)
        cached_key, cached_points, cached_index = self._last_query
        if cached_key == key and torch.equal(cached_points, points):
            return cached_index
        if self._last_tree[0] != key:
            body = torch.lerp(self.vertices[previous], self.vertices[frame], fraction)
            # unbalanced trees build ~2x faster and find the same nearest vertices
            self._last_tree = (key, cKDTree(body.detach().cpu().numpy(), balanced_tree=False,
                                            compact_nodes=False))
        _, index = self._last_tree[1].query(points.detach().cpu().numpy())
        index = torch.as_tensor(np.asarray(index), device=points.device)
        self._last_query = (key, points.clone(), index)
        return index

    def track(self, frame: int, index: Tensor) -> "ContactTrack":
        """The body vertices ``index`` and their normals at ``frame - 1`` and ``frame``."""
        previous = max(frame - 1, 0)
        return ContactTrack(self.vertices[previous, index], self.vertices[frame, index],
                            self.normals[previous, index], self.normals[frame, index])

    def signed_distance(self, frame: int, points: Tensor) -> Tensor:
        """Distance of each point above the tangent plane of its nearest body
        vertex (negative: inside the body)."""
        point, normal = self.track(frame, self.nearest(frame, points)).planes(1.0)
        return ((points - point) * normal).sum(-1)


@dataclass(frozen=True)
class ContactTrack:
    """Contact points and normals at the start and end of a frame."""

    start: Tensor
    end: Tensor
    start_normal: Tensor
    end_normal: Tensor

    @property
    def motion(self) -> Tensor:
        """How far each contact point moves over the frame."""
        return self.end - self.start

    def planes(self, fraction: float) -> tuple[Tensor, Tensor]:
        """Contact points and unit normals ``fraction`` of the way through the frame."""
        normal = torch.lerp(self.start_normal, self.end_normal, fraction)
        return (torch.lerp(self.start, self.end, fraction),
                torch.nn.functional.normalize(normal, dim=-1, eps=1e-12))
