r"""Ground-truth cloth: extended position-based dynamics (XPBD, Macklin et al. 2016).

Each distance constraint :math:`C = \|\mathbf{x}_i - \mathbf{x}_j\| - L` with
compliance :math:`\alpha` (m/N; 0 is inextensible) is solved by

.. math::
    \Delta\lambda = \frac{-C - \tilde\alpha\lambda}{w_i + w_j + \tilde\alpha},
    \qquad \tilde\alpha = \alpha / \Delta t^2, \qquad
    \Delta\mathbf{x}_i = w_i \Delta\lambda\, \mathbf{n}, \quad
    \Delta\mathbf{x}_j = -w_j \Delta\lambda\, \mathbf{n},

with inverse masses :math:`w` (0 for pinned vertices; a constraint with
:math:`w_i + w_j + \tilde\alpha = 0` is skipped rather than dividing 0 by 0).
Stretch constraints are the mesh edges. Bending is either the hinges' dihedral
angles (``bending="dihedral"``, the default and the datasets' model:
:math:`C = \theta - \theta_0` wrapped to
:math:`(-\pi, \pi]`, energy :math:`\tfrac12 k \|\mathbf{e}_0\| C^2` with
``bend_stiffness`` :math:`k`, as newton's VBD cloth, so the two simulators
compare like for like; compliance :math:`1 / (k \|\mathbf{e}_0\|)`) or distance
constraints between the opposite vertices of adjacent triangles
(``bending="distance"``: it also resists the in-plane
compression that folding needs, so flares fall less). Each iteration solves the
bending, projects the tethers (:class:`~swingar_pyg.sim.constraints.TetherConstraints`:
no free vertex ends farther from its nearest pin than its rest geodesic distance plus
``tether_slack``, which bounds stretch when few sweeps cannot carry the pins' pull
across the cloth: large time steps, fast bodies), pushes the cloth out of the body,
and solves the stretch last, so that the positions a substep ends with are the ones
whose edges are nearest their rest lengths.
Distance constraints are coloured so that each colour is a parallel Gauss–Seidel
sweep. Hinges are solved in one Jacobi sweep, each vertex's corrections averaged
over its hinges (Macklin et al. 2014): a hinge has four vertices, so colouring
needs ~14 colours and costs ~4x the sweep (measured), for no closer agreement
with VBD. Many short substeps keep stiff cloth stable and the
swing free (docs/design.md §8). With ``max_substeps`` set the substep is error-controlled: a
frame that ends with an edge strain above ``target_stretch`` is run again from its
start at twice the substeps (up to ``max_substeps``), so the cost goes to the frames
that need it and each frame's substeps are recorded. Where the pins and the body hold
the cloth stretched (a leg kicking against a skirt's hem), no substep count relaxes it:
with ``stall_ratio`` the doubling stops once a re-run fails to lower the frame's largest
strain by that factor, and the frame keeps its least stretched run. Runs on any torch
device.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import Tensor

from swingar_pyg.geometry.mesh import Mesh
from swingar_pyg.geometry.weld import refuse_degenerate
from swingar_pyg.sim.collider import BodyCollider, ContactTrack
from swingar_pyg.sim.constraints import (
    DistanceConstraints,
    TetherConstraints,
    bending_pairs,
    dihedral_angles,
    dihedral_constraints,
    distance_constraints,
    stretch_pairs,
    tether_constraints,
)
from swingar_pyg.sim.recording import (
    STRETCH_BAR,
    FrameRecorder,
    SimulationResult,
    check_inputs,
    edge_strain,
)

# Raise whenever a change alters simulated positions: dataset files record it, and the
# datamodule warns when it trains on sequences an older simulator made. What each revision
# changed: CHANGELOG.md, "Simulator revisions".
SIMULATOR_REVISION = 9


@dataclass(frozen=True)
class XPBDSettings:
    r"""Solver settings, stored with every simulated sequence.

    Attributes:
        fps: output frames per second.
        substeps: solver steps per frame.
        iterations: constraint sweeps per substep.
        stretch_compliance: m/N; 0 is inextensible.
        bending: ``"dihedral"`` (hinge angles, ``bend_stiffness``) or ``"distance"``
            (opposite corners of adjacent triangles, compliance ``bend_compliance``).
        bend_compliance: m/N, distance bending; larger bends more easily.
        bend_stiffness: N m per radian² per metre of edge, dihedral bending (newton's
            VBD ``edge_ke``).
        bend_every: solve bending on one substep in this many, with its compliance
            divided by it, so that the bending impulse over those substeps stays the same
            (multirate stepping: the stretch that needs short steps is solved on every
            one). Bending at the default stiffness is soft, with its natural period far
            above a frame, and the XPBD projection cannot overshoot at any stiffness; the
            hinges are most of a substep's cost (``benchmarks/bench_sim.py`` measures the
            error this adds against the reference).
        tethers: keep each free vertex within its rest geodesic distance of its
            nearest pin (long-range attachments).
        tether_slack: how much farther than that it may go, as a fraction.
        density: cloth mass per area, kg/m².
        damping: velocity decay rate, 1/s.
        friction: Coulomb coefficient: tangential slip against the body is removed up
            to this times the penetration depth resolved.
        thickness: distance kept from the body surface, m.
        gravity: m/s², +Z up.
        settle_frames: frames simulated on the first pose before recording.
        contacts_per_frame: how often per frame each cloth vertex is paired with its
            nearest body vertex (measured: once beats twice on walk and kick).
        max_substeps: ``None`` runs every frame at ``substeps``. Otherwise a frame that
            ends with an edge strain :math:`|l / L - 1|` above ``target_stretch`` is run
            again from its start at twice the substeps, up to ``max_substeps``, and the
            last run is kept (error control: the cost goes to the frames that need it;
            see ``stall_ratio``).
        target_stretch: the largest edge strain a frame may end with before it is re-run.
        stall_ratio: ``None`` doubles up to ``max_substeps``. A ratio :math:`r \in (0, 1]`
            also stops the doubling once a re-run ends with a largest strain
            :math:`\varepsilon_{2n} > r\,\varepsilon_n`, the previous run's times
            :math:`r`, and the frame keeps whichever of its runs ended least stretched
            (an over-constrained frame then costs ``3 * substeps`` substeps, where
            doubling to a cap of ``4 * substeps`` costs ``7 * substeps``).
        backend: ``"torch"`` (tensor operations on any device, the reference) or
            ``"warp"`` (the substep loop as one compiled NVIDIA Warp kernel on the CPU,
            float32; the same steps, several times faster: ``benchmarks/bench_sim.py``).
    """

    fps: float = 30.0
    substeps: int = 50
    iterations: int = 2
    stretch_compliance: float = 0.0
    bending: str = "dihedral"
    bend_compliance: float = 1e-4
    bend_stiffness: float = 1e-3
    bend_every: int = 1
    tethers: bool = True
    tether_slack: float = 0.02
    density: float = 0.15
    damping: float = 1.0
    friction: float = 0.3
    thickness: float = 0.004
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    settle_frames: int = 15
    contacts_per_frame: int = 1
    max_substeps: int | None = None
    target_stretch: float = STRETCH_BAR
    stall_ratio: float | None = None
    backend: str = "torch"

    def __post_init__(self):
        if (self.fps <= 0 or self.substeps < 1 or self.iterations < 1
                or self.contacts_per_frame < 1 or self.bend_every < 1):
            raise ValueError(f"fps, substeps, iterations, contacts_per_frame and bend_every "
                             f"must be positive, got {self.fps}, {self.substeps}, "
                             f"{self.iterations}, {self.contacts_per_frame}, {self.bend_every}")
        if self.backend not in ("torch", "warp"):
            raise ValueError(f"backend must be 'torch' or 'warp', got {self.backend!r}")
        if self.bending not in ("distance", "dihedral"):
            raise ValueError(f"bending must be 'distance' or 'dihedral', got {self.bending!r}")
        for name in ("stretch_compliance", "bend_compliance", "bend_stiffness", "tether_slack",
                     "density", "damping", "thickness", "settle_frames"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if self.max_substeps is not None and self.max_substeps < self.substeps:
            raise ValueError(f"max_substeps must be None or >= substeps ({self.substeps}), "
                             f"got {self.max_substeps}")
        if not (np.isfinite(self.target_stretch) and self.target_stretch > 0):
            raise ValueError(f"target_stretch must be finite and > 0, got {self.target_stretch}")
        if self.stall_ratio is not None and not 0 < self.stall_ratio <= 1:
            raise ValueError(f"stall_ratio must be None or in (0, 1], got {self.stall_ratio}")
        if self.density == 0:
            raise ValueError("density must be > 0")
        if not 0 <= self.friction <= 1:
            raise ValueError(f"friction must be in [0, 1], got {self.friction}")


@dataclass(frozen=True)
class _Colour:
    """One colour of distance constraints, with what stays fixed for a run."""

    rows: slice
    i: Tensor
    j: Tensor
    rest_lengths: Tensor
    wi: Tensor  # (E, 1) inverse masses
    wj: Tensor
    inverse_denominator: Tensor  # 1 / (w_i + w_j + alpha), 0 where that is 0 (no step)


@dataclass(frozen=True)
class _Substep:
    r"""What the substep length fixes: ``dt`` and each constraint's XPBD compliance
    :math:`\alpha / \Delta t^2` (folded into the colours' denominators)."""

    substeps: int
    dt: float
    stretch_colours: tuple[float, tuple[_Colour, ...]]
    bend_colours: tuple[float, tuple[_Colour, ...]] | None  # distance bending
    hinge_compliance: Tensor | None  # dihedral: 1 / (k |e0| dt^2 bend_every) per hinge


def vertex_masses(mesh: Mesh, density: float) -> Tensor:
    """Lumped masses: a third of each incident triangle's area times density.
    Vertices without area get the smallest positive mass, so none is infinitely light."""
    v, f = mesh.vertices, mesh.faces
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    mass = np.zeros(len(v))
    for corner in range(3):
        np.add.at(mass, f[:, corner], density * area / 3.0)
    positive = mass[mass > 0]
    floor = positive.min() if positive.size else density * 1e-6
    return torch.from_numpy(np.maximum(mass, floor))


class XPBDCloth:
    """One garment's solver state: constraints, masses and pins.

    Args:
        mesh: the rest garment (rest lengths come from it).
        pinned: indices of vertices that follow ``pin_targets`` instead of physics.
        settings: solver settings.
        device, dtype: where and in what precision to run.

    Raises:
        ValueError: for pins out of range, and for a mesh with coincident vertices,
            zero-length edges or zero-area faces (weld it first:
            :func:`~swingar_pyg.geometry.weld.weld_mesh`, which
            :func:`~swingar_pyg.world.garment.garment_on_body` applies).
    """

    def __init__(self, mesh: Mesh, pinned: np.ndarray, settings: XPBDSettings,
                 device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32):
        refuse_degenerate(mesh)
        self.mesh, self.settings = mesh, settings
        self.device, self.dtype = torch.device(device), dtype
        pinned = np.asarray(pinned, dtype=np.int64)
        if pinned.size and (pinned.min() < 0 or pinned.max() >= mesh.num_vertices):
            raise ValueError(f"pinned indices must lie in [0, {mesh.num_vertices})")
        self.pinned = torch.as_tensor(pinned, device=self.device)
        self.stretch = distance_constraints(stretch_pairs(mesh), mesh.vertices).to(
            self.device, dtype)
        if settings.bending == "distance":
            self.bend = distance_constraints(bending_pairs(mesh), mesh.vertices).to(
                self.device, dtype)
        else:
            self.bend = dihedral_constraints(mesh).to(self.device, dtype)
        inverse_mass = 1.0 / vertex_masses(mesh, settings.density)
        inverse_mass[pinned] = 0.0
        self.inverse_mass = inverse_mass.to(self.device, dtype)
        self.free = self.inverse_mass > 0
        self.tethers = (tether_constraints(mesh, pinned).to(self.device, dtype)
                        if settings.tethers else None)
        # What stays fixed for every run: per hinge, its corners (4, H), their inverse
        # masses and those times each corner's share of its hinges; per substep count,
        # the terms of _Substep (made when first needed).
        if settings.bending == "dihedral":
            self.hinge_corners = self.bend.hinges.T.contiguous()
            self.hinge_weights = self.inverse_mass[self.hinge_corners]
            self.hinge_shares = self.hinge_weights * self.bend.share[self.hinge_corners, 0]
        self._substeps: dict[int, _Substep] = {}
        self.gravity = torch.tensor(settings.gravity, device=self.device, dtype=dtype)
        self._warp = self._warp_substeps() if settings.backend == "warp" else None

    def _warp_substeps(self):
        """The warp kernel's arrays for this cloth (:mod:`swingar_pyg.sim.warp_xpbd`)."""
        # Warp is optional (it comes with the sim extra's body model): imported on use
        from swingar_pyg.sim.warp_xpbd import WarpSubsteps

        no_pairs, none = torch.zeros(0, 2, dtype=torch.long), torch.zeros(0)
        distance_bending = self.settings.bending == "distance"
        hinged = not distance_bending and self.settings.bend_stiffness > 0
        tethers = self.tethers
        return WarpSubsteps(
            self.inverse_mass, self.pinned, self.stretch.pairs, self.stretch.rest_lengths,
            self.bend.pairs if distance_bending else no_pairs,
            self.bend.rest_lengths if distance_bending else none,
            self.bend.hinges if hinged else torch.zeros(0, 4, dtype=torch.long),
            self.hinge_weights.T if hinged else torch.zeros(0, 4),
            self.hinge_shares.T if hinged else torch.zeros(0, 4),
            self.bend.rest_angles if hinged else none,
            tethers.vertices if tethers is not None else none.long(),
            tethers.anchors if tethers is not None else none.long(),
            (1.0 + self.settings.tether_slack) * tethers.rest_lengths
            if tethers is not None else none)

    def _substep(self, substeps: int) -> _Substep:
        """The terms of ``substeps`` steps a frame, made once per cloth."""
        if substeps not in self._substeps:
            s = self.settings
            dt = 1.0 / (s.fps * substeps)
            bend_colours = hinge_compliance = None
            if s.bending == "distance":
                bend_colours = self._colours(self.bend, s.bend_compliance / s.bend_every, dt)
            else:
                stiffness_dt2 = (s.bend_stiffness * self.bend.rest_lengths * dt * dt
                                 * s.bend_every)
                hinge_compliance = 1.0 / stiffness_dt2.clamp_min(torch.finfo(self.dtype).tiny)
            self._substeps[substeps] = _Substep(
                substeps, dt, self._colours(self.stretch, s.stretch_compliance, dt),
                bend_colours, hinge_compliance)
        return self._substeps[substeps]

    def _colours(self, constraints: DistanceConstraints, compliance: float, dt: float
                 ) -> tuple[float, tuple["_Colour", ...]]:
        """The XPBD compliance ``compliance / dt^2`` and, per colour, what stays fixed
        for the run: pairs, rest lengths, inverse masses, ``1 / (w_i + w_j + alpha)``."""
        alpha = compliance / (dt * dt)
        w = self.inverse_mass
        colours = []
        for start, stop in constraints.colour_slices:
            i, j = constraints.pairs[start:stop, 0], constraints.pairs[start:stop, 1]
            denominator = w[i] + w[j] + alpha
            inverse = torch.where(denominator > 0, 1.0 / denominator.clamp_min(1e-30), 0.0)
            colours.append(_Colour(slice(start, stop), i, j, constraints.rest_lengths[start:stop],
                                   w[i, None], w[j, None], inverse))
        return alpha, tuple(colours)

    @staticmethod
    def _solve(p: Tensor, alpha: float, colours: tuple["_Colour", ...],
               lagrange: Tensor) -> None:
        r"""One Gauss–Seidel sweep, colour by colour, each colour's pairs at once:
        :math:`\Delta\lambda = (d_0 - |x_i - x_j| - \tilde\alpha \lambda) /
        (w_i + w_j + \tilde\alpha)`, :math:`x_i \mathrel{+}= w_i \Delta\lambda\, n`,
        :math:`x_j \mathrel{-}= w_j \Delta\lambda\, n` along the unit
        :math:`n = (x_i - x_j) / |x_i - x_j|`."""
        for c in colours:
            delta = p.index_select(0, c.i) - p.index_select(0, c.j)
            length = torch.linalg.vector_norm(delta, dim=-1)
            multiplier = lagrange[c.rows]  # a view: updated in place below
            step = (c.rest_lengths - length - alpha * multiplier) * c.inverse_denominator
            multiplier += step
            along = (step / length.clamp_min(1e-12)).unsqueeze(-1) * delta
            p.index_add_(0, c.i, c.wi * along)
            p.index_add_(0, c.j, -c.wj * along)

    def _solve_hinges(self, p: Tensor, compliance: Tensor, lagrange: Tensor) -> None:
        """One Jacobi sweep over every hinge: each hinge's XPBD step from the same
        positions, a vertex's corrections averaged over its hinges."""
        if self.settings.bend_stiffness == 0:
            return
        # coordinates first, (3, 4, H): see dihedral_angles
        corners = self.hinge_corners.reshape(-1)
        angle, gradient, valid = dihedral_angles(
            p.T.contiguous().index_select(1, corners).view(3, 4, -1))
        weights, alpha = self.hinge_weights, compliance
        difference = angle - self.bend.rest_angles
        violation = torch.atan2(torch.sin(difference), torch.cos(difference))
        denominator = alpha + (weights * gradient.square().sum(0)).sum(0)
        step = torch.where(valid & (denominator > 0),
                           (-violation - alpha * lagrange) / denominator, 0.0)
        lagrange += step
        correction = (self.hinge_shares * step * gradient).view(3, -1)
        p.add_(p.new_zeros(p.shape[::-1]).index_add_(1, corners, correction).T)

    def _tether(self, p: Tensor, tethers: TetherConstraints) -> None:
        """Moves each over-long tether's free end back onto its sphere around the pin."""
        delta = p.index_select(0, tethers.vertices) - p.index_select(0, tethers.anchors)
        length = torch.linalg.vector_norm(delta, dim=-1)
        excess = (length - (1.0 + self.settings.tether_slack) * tethers.rest_lengths
                  ).clamp_min(0.0)
        p.index_add_(0, tethers.vertices,
                     -(excess / length.clamp_min(1e-12)).unsqueeze(-1) * delta)

    def _collide(self, p: Tensor, x: Tensor, track: ContactTrack, fraction: float,
                 body_step: Tensor, thickness: float) -> None:
        r"""Pushes each free vertex behind its contact plane out onto it,
        :math:`p \mathrel{+}= \max(0, h - (p - b) \cdot n)\, n`, and removes its slip
        against the body up to ``friction`` times that push. The velocity update
        :math:`v = (p - x) / \Delta t` turns a push of depth :math:`d` into :math:`d /
        \Delta t` away from the body, so a vertex found deep inside leaves fast (README,
        "Contacts push out with velocity", for the remedies measured)."""
        point, normal = track.planes(fraction)
        depth = ((p - point) * normal).sum(-1) - thickness
        push_depth = torch.where((depth < 0) & self.free, -depth, 0.0)
        # Coulomb friction in position form: the tangential slip against the body is
        # removed up to friction x the depth just resolved (the normal impulse).
        slip = (p - x) - body_step
        slip = slip - (slip * normal).sum(-1, keepdim=True) * normal
        slip_length = torch.linalg.vector_norm(slip, dim=-1)
        keep = (self.settings.friction * push_depth / slip_length.clamp_min(1e-12)
                ).clamp_max(1.0)
        p.add_(push_depth.unsqueeze(-1) * normal - keep.unsqueeze(-1) * slip)

    def strain(self, x: Tensor) -> Tensor:
        return edge_strain(x, self.stretch)

    def _frame(self, x: Tensor, v: Tensor, frame: int, previous_target: Tensor,
               target: Tensor, collider: BodyCollider | None, settling: bool,
               step: _Substep) -> tuple[Tensor, Tensor]:
        """One output frame of ``step.substeps`` substeps from positions ``x`` and
        velocities ``v`` (left unchanged), the pins moving from ``previous_target`` to
        ``target``; returns the frame's end positions and velocities. The contacts are
        found again every ``substeps / contacts_per_frame`` substeps."""
        s = self.settings
        interval = (max(1, step.substeps // s.contacts_per_frame) if collider is not None
                    else step.substeps)
        for first in range(0, step.substeps, interval):
            count = min(interval, step.substeps - first)
            track = body_step = None
            if collider is not None:
                at = 1.0 if settling else first / step.substeps
                track = collider.track(frame, collider.nearest(frame, x, at))
                body_step = track.motion.to(self.device, self.dtype) / step.substeps
                if settling:
                    body_step = torch.zeros_like(body_step)
            run = self._warp_substeps_run if self._warp is not None else self._substeps_run
            x, v = run(x, v, first, count, previous_target, target, track, body_step,
                       collider.thickness if collider is not None else 0.0, settling, step)
        return x, v

    def _substeps_run(self, x: Tensor, v: Tensor, first: int, count: int,
                      previous_target: Tensor, target: Tensor, track: ContactTrack | None,
                      body_step: Tensor | None, thickness: float, settling: bool,
                      step: _Substep) -> tuple[Tensor, Tensor]:
        """Substeps ``first .. first + count`` with tensor operations (the reference)."""
        s, dt = self.settings, step.dt
        decay = float(np.exp(-s.damping * dt))
        stretch_lagrange = torch.zeros_like(self.stretch.rest_lengths)
        bend_lagrange = torch.zeros_like(self.bend.rest_lengths)
        for sub in range(first, first + count):
            fraction = (sub + 1) / step.substeps
            v = (v + dt * self.gravity) * decay
            p = x + dt * v
            p[self.pinned] = torch.lerp(previous_target, target, fraction)
            stretch_lagrange.zero_()
            bend_lagrange.zero_()
            bend = sub % s.bend_every == 0
            for _ in range(s.iterations):
                # Stretch last: bending, tethers and contacts move vertices without
                # regard to their edges; solved after them, the edges end each sweep
                # nearest their rest lengths (see SIMULATOR_REVISION).
                if bend and s.bending == "distance":
                    self._solve(p, *step.bend_colours, bend_lagrange)
                elif bend:
                    self._solve_hinges(p, step.hinge_compliance, bend_lagrange)
                if self.tethers is not None:
                    self._tether(p, self.tethers)
                if track is not None:
                    body_fraction = 1.0 if settling else fraction
                    self._collide(p, x, track, body_fraction, body_step, thickness)
                self._solve(p, *step.stretch_colours, stretch_lagrange)
            v = (p - x) / dt
            x = p
        return x, v

    def _warp_substeps_run(self, x: Tensor, v: Tensor, first: int, count: int,
                           previous_target: Tensor, target: Tensor,
                           track: ContactTrack | None, body_step: Tensor | None,
                           thickness: float, settling: bool,
                           step: _Substep) -> tuple[Tensor, Tensor]:
        """The same substeps as :meth:`_substeps_run`, in one warp kernel launch."""
        s = self.settings
        stretch_alpha, stretch_colours = step.stretch_colours
        bend_alpha, bend_colours = step.bend_colours or (0.0, ())
        compliance = self._warp.compliance(step.substeps, stretch_colours, bend_colours,
                                           step.hinge_compliance)
        contacts = None
        if track is not None:
            contacts = (track.start, track.end, track.start_normal, track.end_normal, body_step)
        return self._warp.run(x, v, first, count, step.substeps, s.iterations, s.bend_every,
                              step.dt,
                              float(np.exp(-s.damping * step.dt)), self.gravity,
                              previous_target, target, compliance, stretch_alpha, bend_alpha,
                              contacts, 1.0 if settling else -1.0, thickness, s.friction)

    def _controlled_frame(self, x: Tensor, v: Tensor, frame: int, previous_target: Tensor,
                          target: Tensor, collider: BodyCollider | None,
                          settling: bool) -> tuple[Tensor, Tensor, int]:
        """:meth:`_frame` at ``substeps``, re-run at twice the substeps while the
        settings' error control asks for it; returns the kept run's end positions,
        velocities and substeps."""
        s = self.settings
        substeps = s.substeps
        runs: list[tuple[float, Tensor, Tensor, int]] = []  # (largest strain, x, v, substeps)
        while True:
            # x and v are not changed in place, so a frame re-run starts where it did
            end_x, end_v = self._frame(x, v, frame, previous_target, target, collider,
                                       settling, self._substep(substeps))
            if s.max_substeps is None:
                return end_x, end_v, substeps
            # a non-finite run counts as infinitely stretched: never the one kept
            largest = float(self.strain(end_x).max().nan_to_num(nan=float("inf")))
            stalled = (s.stall_ratio is not None and bool(runs)
                       and largest > s.stall_ratio * runs[-1][0])
            runs.append((largest, end_x, end_v, substeps))
            if largest <= s.target_stretch or substeps >= s.max_substeps or stalled:
                break
            substeps = min(2 * substeps, s.max_substeps)
        _, end_x, end_v, substeps = (runs[-1] if s.stall_ratio is None
                                     else min(runs, key=lambda run: run[0]))
        return end_x, end_v, substeps

    def simulate(self, initial: Tensor, pin_targets: Tensor,
                 collider: BodyCollider | None = None,
                 progress: bool = False) -> SimulationResult:
        """Simulates from ``initial`` ``(N, 3)`` while the pins follow
        ``pin_targets`` ``(T, P, 3)``; frame 0 is settled first (see settings).

        Raises:
            ValueError: for inputs of the wrong shape or non-finite values.
            FloatingPointError: if the state ever becomes non-finite (a bug).
        """
        s = self.settings
        frames = pin_targets.shape[0]
        n = self.mesh.num_vertices
        check_inputs(initial, pin_targets, n, len(self.pinned), collider)

        x = initial.to(self.device, self.dtype).clone()
        targets = pin_targets.to(self.device, self.dtype)
        v = torch.zeros_like(x)
        recorder = FrameRecorder(frames, n, self.stretch, self.free, collider, self.dtype)
        schedule = [0] * s.settle_frames + list(range(frames))
        iterator = schedule
        if progress:
            from tqdm import tqdm

            iterator = tqdm(schedule, desc="simulating", unit="frame", leave=False)
        for step_index, frame in enumerate(iterator):
            start = time.perf_counter()
            settling = step_index < s.settle_frames
            previous_target = targets[0] if settling else targets[max(frame - 1, 0)]
            x, v, substeps = self._controlled_frame(x, v, frame, previous_target,
                                                    targets[frame], collider, settling)
            if settling:
                if not torch.isfinite(x).all():
                    raise FloatingPointError("cloth state became non-finite while settling")
                continue
            recorder.record(frame, x, time.perf_counter() - start, substeps)
        return recorder.result(asdict(s))
