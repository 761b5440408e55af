"""What every simulator checks of its inputs and records per output frame, whatever
solved it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sparse
import torch
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree
from torch import Tensor

from swingar_pyg.geometry.mesh import mesh_edges
from swingar_pyg.sim.collider import BodyCollider
from swingar_pyg.sim.constraints import DistanceConstraints

if TYPE_CHECKING:
    from swingar_pyg.geometry.mesh import Mesh


# The largest edge stretch issue #3 asks of a simulated sequence (benchmarks/bench_strain.py
# measures which settings and motions keep to it).
STRETCH_BAR = 0.06


@dataclass
class SimulationResult:
    """A simulated sequence and how it was obtained.

    Attributes:
        positions: ``(T, N, 3)`` cloth vertices per output frame.
        seconds_per_frame: ``(T,)`` wall time of each frame.
        max_stretch, mean_stretch: ``(T,)`` edge strain ``|l / L - 1|``.
        penetration: ``(T,)`` fraction of free vertices inside the body (NaN without body).
        substeps_per_frame: ``(T,)`` solver substeps each frame was run with (the kept
            run of a frame the solver re-ran at more substeps; ``seconds_per_frame``
            counts all its runs).
        settings: the solver settings.
    """

    positions: Tensor
    seconds_per_frame: np.ndarray
    max_stretch: np.ndarray
    mean_stretch: np.ndarray
    penetration: np.ndarray
    substeps_per_frame: np.ndarray
    settings: dict = field(default_factory=dict)


def check_inputs(initial: Tensor, pin_targets: Tensor, vertices: int, pins: int,
                 collider: BodyCollider | None) -> None:
    """Raises ``ValueError`` unless ``initial`` is ``(vertices, 3)``, ``pin_targets``
    ``(T, pins, 3)``, the body (if any) has ``T`` frames, and both are finite."""
    frames = pin_targets.shape[0]
    if initial.shape != (vertices, 3):
        raise ValueError(f"initial positions must have shape ({vertices}, 3), got "
                         f"{tuple(initial.shape)}")
    if pin_targets.shape[1:] != (pins, 3):
        raise ValueError(f"pin_targets must have shape (T, {pins}, 3), got "
                         f"{tuple(pin_targets.shape)}")
    if collider is not None and collider.num_frames != frames:
        raise ValueError(f"the body has {collider.num_frames} frames, the pins {frames}")
    if not (torch.isfinite(initial).all() and torch.isfinite(pin_targets).all()):
        raise ValueError("initial positions and pin targets must be finite")


def signed_edge_strain(x: Tensor, pairs: Tensor, rest_lengths: Tensor) -> Tensor:
    r"""Edge strain :math:`l / L - 1` of positions ``x`` ``(..., N, 3)`` for the vertex
    ``pairs`` ``(E, 2)`` of rest lengths :math:`L`: positive stretched, negative
    compressed; ``(..., E)``."""
    length = (x[..., pairs[:, 0], :] - x[..., pairs[:, 1], :]).norm(dim=-1)
    return length / rest_lengths.clamp_min(1e-12) - 1.0


def edge_strain(x: Tensor, stretch: DistanceConstraints) -> Tensor:
    r"""Edge strain :math:`|l / L - 1|` of positions ``x`` ``(N, 3)`` against the rest
    lengths :math:`L` of the stretch constraints."""
    return signed_edge_strain(x, stretch.pairs, stretch.rest_lengths).abs()


class FrameRecorder:
    """Collects positions, wall time, substeps, strain and penetration of each output frame.

    Args:
        frames, vertices: size of the sequence.
        stretch: the mesh edges with their rest lengths (for the strain).
        free: ``(N,)`` bool, the vertices physics moves (penetration counts only these).
        collider: the body, or ``None`` (penetration is then NaN).
        dtype: precision the positions are stored in.
    """

    def __init__(self, frames: int, vertices: int, stretch: DistanceConstraints, free: Tensor,
                 collider: BodyCollider | None, dtype: torch.dtype = torch.float32):
        self.stretch, self.free, self.collider = stretch, free, collider
        self.positions = torch.empty(frames, vertices, 3, dtype=dtype)
        self.seconds = np.zeros(frames)
        self.max_stretch, self.mean_stretch = np.zeros(frames), np.zeros(frames)
        self.penetration = np.full(frames, np.nan)
        self.substeps = np.zeros(frames, dtype=np.int32)

    def record(self, frame: int, x: Tensor, seconds: float, substeps: int) -> None:
        """Stores frame ``frame``, reached in ``substeps`` solver substeps; raises
        ``FloatingPointError`` if ``x`` is not finite."""
        if not torch.isfinite(x).all():
            raise FloatingPointError(f"cloth state became non-finite at frame {frame}")
        self.positions[frame] = x.detach().cpu()
        self.seconds[frame] = seconds
        self.substeps[frame] = substeps
        strain = edge_strain(x, self.stretch)
        self.max_stretch[frame] = strain.max().item()
        self.mean_stretch[frame] = strain.mean().item()
        if self.collider is not None:
            # all vertices: the next frame's contacts search the same points
            inside = self.collider.signed_distance(frame, x)[self.free] < 0
            self.penetration[frame] = inside.float().mean().item()

    def result(self, settings: dict) -> SimulationResult:
        return SimulationResult(self.positions, self.seconds, self.max_stretch, self.mean_stretch,
                                self.penetration, self.substeps, settings)


def stretch_by_place(strain: Tensor, pairs: Tensor, pinned: np.ndarray, num_vertices: int,
                     body_distance: Tensor, pin_hops: int = 2, touch: float = 0.01
                     ) -> dict[str, float]:
    r"""The largest stretch (strain :math:`l / L - 1` above zero) of edges in three
    places, to tell what breaks :data:`STRETCH_BAR` in a sequence:

    * ``"near_pins"``: an end within ``pin_hops`` mesh edges of a pinned vertex (the
      rows that carry the garment's weight and the waistband's pull);
    * ``"touching"``: not near the pins, and at that frame an end within ``touch``
      metres of the body (stretch made by contacts);
    * ``"free"``: every other edge at that frame (swinging cloth).

    Args:
        strain: ``(T, E)`` signed strain of the edges ``pairs`` ``(E, 2)``.
        pinned: indices of the pinned vertices.
        num_vertices: vertices of the mesh.
        body_distance: ``(T, N)`` distance of each vertex to the body.

    Returns:
        The three largest stretches (0 where a place holds no stretched edge).
    """
    if strain.shape[1] != pairs.shape[0] or body_distance.shape != (strain.shape[0],
                                                                    num_vertices):
        raise ValueError(f"strain {tuple(strain.shape)}, pairs {tuple(pairs.shape)} and "
                         f"body_distance {tuple(body_distance.shape)} do not agree")
    ends = pairs.cpu().numpy()
    graph = sparse.coo_matrix((np.ones(len(ends)), (ends[:, 0], ends[:, 1])),
                              shape=(num_vertices, num_vertices))
    if len(pinned):
        hops = dijkstra(graph, directed=False, unweighted=True, indices=np.asarray(pinned),
                        min_only=True)
    else:
        hops = np.full(num_vertices, np.inf)
    near_pins = torch.as_tensor(np.minimum(hops[ends[:, 0]], hops[ends[:, 1]]) <= pin_hops,
                                device=strain.device)
    close = body_distance <= touch
    touching = (close[:, pairs[:, 0]] | close[:, pairs[:, 1]]) & ~near_pins
    stretch = strain.clamp_min(0.0)
    places = {"near_pins": near_pins.expand_as(strain), "touching": touching,
              "free": ~(near_pins | touching)}
    return {name: float(torch.where(mask, stretch, 0.0).max()) if strain.numel() else 0.0
            for name, mask in places.items()}


def garment_edge_strain(mesh: "Mesh", positions: Tensor) -> tuple[Tensor, Tensor]:
    """The mesh edges ``(E, 2)`` of a garment and their :func:`signed_edge_strain`
    ``(T, E)`` in ``positions`` ``(T, N, 3)`` against the rest ``mesh``."""
    pairs = torch.as_tensor(mesh_edges(mesh.faces))
    rest = torch.as_tensor(mesh.vertices, dtype=positions.dtype)
    rest_lengths = (rest[pairs[:, 0]] - rest[pairs[:, 1]]).norm(dim=-1)
    return pairs, signed_edge_strain(positions.cpu(), pairs, rest_lengths)


def nearest_body_distance(positions: Tensor, body_vertices: Tensor) -> Tensor:
    """Per frame, each of ``positions`` ``(T, N, 3)``'s distance to its nearest vertex
    of the body ``body_vertices`` ``(T, V, 3)``: ``(T, N)``."""
    if positions.shape[0] != body_vertices.shape[0]:
        raise ValueError(f"the cloth has {positions.shape[0]} frames, the body "
                         f"{body_vertices.shape[0]}")
    return torch.as_tensor(np.stack([
        cKDTree(body.detach().cpu().numpy()).query(cloth.detach().cpu().numpy())[0]
        for body, cloth in zip(body_vertices, positions)]), dtype=positions.dtype)


def sequence_stretch_by_place(mesh: "Mesh", pinned: np.ndarray, positions: Tensor,
                              body_vertices: Tensor) -> dict[str, float]:
    """:func:`stretch_by_place` of a simulated sequence: the garment ``mesh`` (its
    rest lengths) and ``pinned`` vertices, cloth ``positions`` ``(T, N, 3)`` and the body
    ``body_vertices`` ``(T, V, 3)``."""
    pairs, strain = garment_edge_strain(mesh, positions)
    return stretch_by_place(strain, pairs, pinned, mesh.num_vertices,
                            nearest_body_distance(positions, body_vertices))
