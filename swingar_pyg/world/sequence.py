"""One ground-truth sequence: a garment on a body of some shape, moving, simulated."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from swingar_pyg.geometry.signed_distance import inside_share
from swingar_pyg.geometry.skinning import linear_blend_skinning
from swingar_pyg.sim import BodyCollider, SimulationResult, XPBDCloth, XPBDSettings
from swingar_pyg.sim.vbd import VBDCloth, VBDSettings
from swingar_pyg.world.body import BodyModel
from swingar_pyg.world.garment import Garment
from swingar_pyg.world.motion import Motion


@dataclass
class SimulatedSequence:
    """Everything a dataset stores about a sequence (docs/design.md §7).

    Attributes:
        garment, motion: what was simulated.
        body_shape: ``(S,)`` shape parameters of the body.
        body_vertices: ``(T, V, 3)`` the posed body (recomputable from shape and motion).
        rigid: ``(T, N, 3)`` the garment rigidly skinned with its transferred weights
            (the baseline the estimator must beat).
        result: the simulator's output, cost and residuals.
        penetration_exact: ``(T,)`` share of free vertices inside the body by exact ray
            parity (:meth:`with_exact_penetration`), or ``None`` if not measured.
    """

    garment: Garment
    motion: Motion
    body_shape: Tensor
    body_vertices: Tensor
    rigid: Tensor
    result: SimulationResult
    penetration_exact: np.ndarray | None = None

    def with_exact_penetration(self, faces: Tensor) -> "SimulatedSequence":
        """This sequence with :attr:`penetration_exact` measured against the body of
        triangles ``faces`` (about 30 ms a frame for a 14k-vertex body)."""
        free = np.setdiff1d(np.arange(self.garment.mesh.num_vertices), self.garment.pinned)
        share = inside_share(self.body_vertices.numpy(), faces.numpy(),
                             self.result.positions.numpy()[:, free])
        return dataclasses.replace(self, penetration_exact=share)


def simulate_sequence(body: BodyModel, body_shape: Tensor, garment: Garment, motion: Motion,
                      settings: XPBDSettings | VBDSettings | None = None, device: str = "cpu",
                      progress: bool = False) -> SimulatedSequence:
    """Poses the body, drives the garment's pins with the body's skinning, starts
    the cloth from its rigidly skinned first frame, and simulates with the solver the
    settings are for (:class:`XPBDSettings`, the default, or :class:`VBDSettings`)."""
    settings = settings or XPBDSettings(fps=motion.fps)
    if settings.fps != motion.fps:
        raise ValueError(f"the motion runs at {motion.fps} fps but the simulator at "
                         f"{settings.fps}; resample the motion first")
    if tuple(motion.joint_names) != tuple(body.joint_names):
        raise ValueError("the motion was made for another rig than this body's")
    posed = body.pose(body_shape, motion.rotations, motion.translation)
    rigid = linear_blend_skinning(torch.as_tensor(garment.mesh.vertices, dtype=torch.float32),
                                  torch.as_tensor(garment.skin_indices),
                                  torch.as_tensor(garment.skin_weights, dtype=torch.float32),
                                  posed.joint_transforms)
    solver = VBDCloth if isinstance(settings, VBDSettings) else XPBDCloth
    cloth = solver(garment.mesh, garment.pinned, settings, device=device)
    collider = BodyCollider(posed.vertices.to(device), body.faces.to(device),
                            thickness=settings.thickness)
    result = cloth.simulate(rigid[0], rigid[:, garment.pinned], collider, progress=progress)
    return SimulatedSequence(garment, motion, torch.as_tensor(body_shape), posed.vertices,
                             rigid, result)
