r"""A second ground-truth simulator: vertex block descent (VBD, Chen et al. 2024) in
NVIDIA's ``newton`` engine, for cross-checking the XPBD solver and for GPU-scale
generation (``pip install swingar-pyg[newton]``).

VBD minimises the implicit-Euler variational energy of each substep,

.. math::
    \mathbf{x}^{t+1} = \arg\min_{\mathbf{x}} \; \frac{1}{2\Delta t^2}
    \|\mathbf{x} - \mathbf{y}\|_{\mathbf{M}}^2 + E_\text{StVK}(\mathbf{x})
    + E_\text{bend}(\mathbf{x}) + E_\text{contact}(\mathbf{x}),
    \qquad \mathbf{y} = \mathbf{x}^t + \Delta t\,\mathbf{v}^t + \Delta t^2\,\mathbf{g},

one vertex at a time (a Newton step on its 3x3 block), vertices of one colour in
parallel. Unlike the XPBD solver it models the membrane as StVK triangles and bending
as dihedral angles, so compressing a flared skirt into folds costs little: the two
solvers disagree most on how far a flare falls (measured in ``benchmarks/bench_sim_crosscheck.py``).

The body is one triangle-mesh shape whose points and velocities are re-posed every
substep (linearly within a frame, as :class:`~swingar_pyg.sim.XPBDCloth` does) and
whose BVH is refitted; pinned vertices have zero mass and follow their targets.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import Tensor

from swingar_pyg.geometry.mesh import Mesh
from swingar_pyg.geometry.weld import refuse_degenerate
from swingar_pyg.sim.collider import BodyCollider
from swingar_pyg.sim.constraints import distance_constraints, stretch_pairs
from swingar_pyg.sim.recording import FrameRecorder, SimulationResult, check_inputs
from swingar_pyg.sim.xpbd import vertex_masses
from swingar_pyg.verbosity import init_warp


@dataclass(frozen=True)
class VBDSettings:
    """VBD solver settings, stored with every simulated sequence.

    Attributes:
        fps: output frames per second.
        substeps: solver steps per frame.
        iterations: block-descent sweeps per substep.
        stretch_stiffness: StVK Lamé coefficients ``tri_ke = tri_ka`` (N/m).
        bend_stiffness: dihedral bending stiffness ``edge_ke``.
        damping: velocity decay rate, 1/s (air drag, as the XPBD solver's ``damping``:
            velocities are scaled by ``exp(-damping * dt)`` after each substep).
        material_damping: Rayleigh damping of membrane and bending (``tri_kd = edge_kd``).
        density: cloth mass per area, kg/m².
        contact_stiffness, contact_damping: penalty of the body contact.
        friction: Coulomb coefficient against the body.
        thickness: distance kept from the body surface, m.
        gravity: m/s², +Z up.
        settle_frames: frames simulated on the first pose before recording.
    """

    fps: float = 30.0
    substeps: int = 10
    iterations: int = 10
    stretch_stiffness: float = 1e4
    bend_stiffness: float = 1e-3
    damping: float = 1.0
    material_damping: float = 1e-4
    density: float = 0.15
    contact_stiffness: float = 1e4
    contact_damping: float = 1e-2
    friction: float = 0.3
    thickness: float = 0.004
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    settle_frames: int = 15

    def __post_init__(self):
        if self.fps <= 0 or self.substeps < 1 or self.iterations < 1:
            raise ValueError(f"fps, substeps and iterations must be positive, got {self.fps}, "
                             f"{self.substeps}, {self.iterations}")
        for name in ("stretch_stiffness", "bend_stiffness", "damping", "material_damping",
                     "density", "contact_stiffness", "contact_damping", "thickness",
                     "settle_frames"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if self.density == 0 or self.stretch_stiffness == 0:
            raise ValueError("density and stretch_stiffness must be > 0")
        if not 0 <= self.friction <= 1:
            raise ValueError(f"friction must be in [0, 1], got {self.friction}")


def _import_newton():
    init_warp()  # before newton initialises it: no start-up banner unless asked
    try:
        import newton
        import warp as wp
    except ImportError as error:
        raise ImportError("the VBD simulator needs NVIDIA's newton engine: "
                          "pip install 'swingar-pyg[newton]'") from error
    return newton, wp


class VBDCloth:
    """One garment in a ``newton`` VBD model: same interface as
    :class:`~swingar_pyg.sim.XPBDCloth`.

    Args:
        mesh: the rest garment.
        pinned: indices of vertices that follow ``pin_targets`` instead of physics.
        settings: solver settings.
        device: torch device to run on (its warp counterpart runs the kernels).
    """

    def __init__(self, mesh: Mesh, pinned: np.ndarray, settings: VBDSettings,
                 device: torch.device | str = "cpu"):
        refuse_degenerate(mesh)
        self.mesh, self.settings = mesh, settings
        self.device = torch.device(device)
        pinned = np.asarray(pinned, dtype=np.int64)
        if pinned.size and (pinned.min() < 0 or pinned.max() >= mesh.num_vertices):
            raise ValueError(f"pinned indices must lie in [0, {mesh.num_vertices})")
        self.pinned = torch.as_tensor(pinned, device=self.device)
        self.stretch = distance_constraints(stretch_pairs(mesh), mesh.vertices).to(
            self.device, torch.float32)
        self.free = torch.ones(mesh.num_vertices, dtype=torch.bool, device=self.device)
        self.free[self.pinned] = False

    def _build(self, initial: Tensor, body_rest: Tensor | None, body_faces: Tensor | None):
        newton, wp = _import_newton()
        s = self.settings
        builder = newton.ModelBuilder(gravity=s.gravity)
        builder.add_cloth_mesh(
            pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0,
            vel=wp.vec3(0.0, 0.0, 0.0), vertices=initial.double().cpu().numpy(),
            indices=self.mesh.faces.reshape(-1).tolist(), density=s.density,
            tri_ke=s.stretch_stiffness, tri_ka=s.stretch_stiffness, tri_kd=s.material_damping,
            edge_ke=s.bend_stiffness, edge_kd=s.material_damping, particle_radius=s.thickness)
        # Lumped masses as in the XPBD solver, so both move the same cloth.
        masses = vertex_masses(self.mesh, s.density).double().numpy()
        masses[self.pinned.cpu().numpy()] = 0.0
        builder.particle_mass = masses.tolist()
        body_mesh = None
        if body_rest is not None:
            body_mesh = newton.Mesh(body_rest.cpu().numpy(),
                                    body_faces.cpu().numpy().astype(np.int32).reshape(-1),
                                    compute_inertia=False)
            builder.add_shape_mesh(-1, mesh=body_mesh)
        builder.color(include_bending=True)
        model = builder.finalize(device=wp.device_from_torch(self.device))
        model.soft_contact_ke = s.contact_stiffness
        model.soft_contact_kd = s.contact_damping
        model.soft_contact_mu = s.friction
        return newton, wp, model, body_mesh

    def simulate(self, initial: Tensor, pin_targets: Tensor,
                 collider: BodyCollider | None = None,
                 progress: bool = False) -> SimulationResult:
        """Simulates from ``initial`` ``(N, 3)`` while the pins follow
        ``pin_targets`` ``(T, P, 3)``; frame 0 is settled first (see settings).

        Raises:
            ValueError: for inputs of the wrong shape or non-finite values.
            FloatingPointError: if the state ever becomes non-finite.
        """
        s = self.settings
        frames, n = pin_targets.shape[0], self.mesh.num_vertices
        check_inputs(initial, pin_targets, n, len(self.pinned), collider)

        body = None if collider is None else collider.vertices.to(self.device, torch.float32)
        newton, wp, model, body_mesh = self._build(
            initial, None if body is None else body[0],
            None if collider is None else collider.faces)
        if body is not None:
            # Broad phase culls against the shape's rest bounds: widen them to every pose.
            flat = body.reshape(-1, 3)
            margin = s.thickness + 0.05
            model.shape_collision_aabb_lower.assign(
                (flat.min(0).values - margin).cpu().numpy()[None].astype(np.float32))
            model.shape_collision_aabb_upper.assign(
                (flat.max(0).values + margin).cpu().numpy()[None].astype(np.float32))
            body_points = wp.to_torch(body_mesh.mesh.points)
            body_velocities = wp.to_torch(body_mesh.mesh.velocities)
        solver = newton.solvers.SolverVBD(model=model, iterations=s.iterations)
        pipeline = newton.CollisionPipeline(model, soft_contact_gap=2 * s.thickness)
        contacts = pipeline.contacts()
        state, next_state = model.state(), model.state()
        control = model.control()
        targets = pin_targets.to(self.device, torch.float32)
        dt = 1.0 / (s.fps * s.substeps)
        decay = float(np.exp(-s.damping * dt))
        recorder = FrameRecorder(frames, n, self.stretch, self.free, collider)

        schedule = [0] * s.settle_frames + list(range(frames))
        iterator = schedule
        if progress:
            from tqdm import tqdm

            iterator = tqdm(schedule, desc="simulating (VBD)", unit="frame", leave=False)
        for step_index, frame in enumerate(iterator):
            start = time.perf_counter()
            settling = step_index < s.settle_frames
            previous = frame if settling else max(frame - 1, 0)
            if body is not None:
                body_velocities.copy_((body[frame] - body[previous]) * s.fps)
            for sub in range(s.substeps):
                fraction = (sub + 1) / s.substeps
                x = wp.to_torch(state.particle_q)
                x[self.pinned] = torch.lerp(targets[previous], targets[frame], fraction)
                if body is not None:
                    body_points.copy_(torch.lerp(body[previous], body[frame], fraction))
                    body_mesh.mesh.refit()
                pipeline.collide(state, contacts)
                solver.step(state, next_state, control, contacts, dt)
                state, next_state = next_state, state
                wp.to_torch(state.particle_qd).mul_(decay)
            x = wp.to_torch(state.particle_q)
            if settling:
                if not torch.isfinite(x).all():
                    raise FloatingPointError("cloth state became non-finite while settling")
                continue
            recorder.record(frame, x, time.perf_counter() - start, s.substeps)
        return recorder.result(asdict(s))
