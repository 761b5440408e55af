r"""The XPBD substep loop of :class:`~swingar_pyg.sim.XPBDCloth` as one compiled
NVIDIA Warp kernel (``XPBDSettings(backend="warp")``).

The torch path spends most of a substep launching small tensor operations: at
1.5k vertices a substep is ~130 ops of a few thousand elements each. Here one
kernel launch runs every substep between two contact updates, and a single
thread walks the constraints in order. On one CPU core that is the fastest way
to run Gauss–Seidel: a colour of the torch path is a set of constraints with no
shared vertex, so solving the colour-sorted constraints one after another gives
what solving each colour at once does. The hinges stay a Jacobi sweep (every
hinge's step from the same positions, corrections summed into a buffer, then
applied) and tethers and contacts touch each vertex once, so the kernel computes
the torch path's substep term for term; only floating-point rounding differs
(``tests/test_simulator_backends.py`` bounds the difference).

One launch runs on one thread (``dim=1``); Warp compiles the kernel to native
code once per machine (a few seconds, then cached). Runs on the CPU: on a GPU the
torch path's parallel colours are the better fit.
"""

from __future__ import annotations

import torch
import warp as wp
from torch import Tensor

from swingar_pyg.verbosity import init_warp


@wp.func
def _solve_distance(p: wp.array(dtype=wp.vec3), inverse_mass: wp.array(dtype=float),
                    i: wp.array(dtype=int), j: wp.array(dtype=int),
                    rest: wp.array(dtype=float), inverse_denominator: wp.array(dtype=float),
                    alpha: float, lagrange: wp.array(dtype=float)):
    """One Gauss–Seidel sweep over distance constraints in their stored order."""
    for c in range(i.shape[0]):
        a = i[c]
        b = j[c]
        delta = p[a] - p[b]
        length = wp.length(delta)
        step = (rest[c] - length - alpha * lagrange[c]) * inverse_denominator[c]
        lagrange[c] = lagrange[c] + step
        along = (step / wp.max(length, 1.0e-12)) * delta
        p[a] = p[a] + inverse_mass[a] * along
        p[b] = p[b] - inverse_mass[b] * along


@wp.func
def _hinge_step(p: wp.array(dtype=wp.vec3), h: int, hinges: wp.array2d(dtype=int),
                weights: wp.array2d(dtype=float), shares: wp.array2d(dtype=float),
                rest_angle: wp.array(dtype=float), compliance: wp.array(dtype=float),
                lagrange: wp.array(dtype=float), correction: wp.array(dtype=wp.vec3)):
    """One hinge's XPBD step from ``p``, added to ``correction`` (see
    :func:`~swingar_pyg.sim.constraints.dihedral_angles` for the angle and gradient)."""
    x1 = p[hinges[h, 0]]
    x2 = p[hinges[h, 1]]
    x3 = p[hinges[h, 2]]
    x4 = p[hinges[h, 3]]
    e = x4 - x3
    length = wp.sqrt(wp.dot(e, e))
    d13 = x1 - x3
    d14 = x1 - x4
    d23 = x2 - x3
    d24 = x2 - x4
    n1 = wp.cross(d13, d14)
    n2 = wp.cross(d24, d23)
    area1 = wp.dot(n1, n1)
    area2 = wp.dot(n2, n2)
    tiny = (1.0e-6 * length * length) * (1.0e-6 * length * length)
    if area1 <= tiny or area2 <= tiny:
        return
    m1 = n1 * (1.0 / area1)
    m2 = n2 * (1.0 / area2)
    angle = wp.atan2(wp.dot(wp.cross(n1, n2), e), length * wp.dot(n1, n2))
    inverse_length = 1.0 / length
    a13 = wp.dot(d13, e) * inverse_length
    a14 = wp.dot(d14, e) * inverse_length
    a23 = wp.dot(d23, e) * inverse_length
    a24 = wp.dot(d24, e) * inverse_length
    g1 = -length * m1
    g2 = -length * m2
    g3 = -a14 * m1 - a24 * m2
    g4 = a13 * m1 + a23 * m2
    violation = angle - rest_angle[h]  # wrapped to (-pi, pi]
    if violation > wp.pi:
        violation = violation - 2.0 * wp.pi
    elif violation <= -wp.pi:
        violation = violation + 2.0 * wp.pi
    alpha = compliance[h]
    denominator = alpha + (weights[h, 0] * wp.dot(g1, g1) + weights[h, 1] * wp.dot(g2, g2)
                           + weights[h, 2] * wp.dot(g3, g3) + weights[h, 3] * wp.dot(g4, g4))
    if denominator <= 0.0:
        return
    step = (-violation - alpha * lagrange[h]) / denominator
    lagrange[h] = lagrange[h] + step
    correction[hinges[h, 0]] = correction[hinges[h, 0]] + shares[h, 0] * step * g1
    correction[hinges[h, 1]] = correction[hinges[h, 1]] + shares[h, 1] * step * g2
    correction[hinges[h, 2]] = correction[hinges[h, 2]] + shares[h, 2] * step * g3
    correction[hinges[h, 3]] = correction[hinges[h, 3]] + shares[h, 3] * step * g4


@wp.kernel
def xpbd_substeps(
        # state: x, v advanced in place; p and correction are scratch
        x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), p: wp.array(dtype=wp.vec3),
        correction: wp.array(dtype=wp.vec3), inverse_mass: wp.array(dtype=float),
        gravity: wp.vec3, dt: float, decay: float,
        first: int, count: int, substeps: int, iterations: int, bend_every: int,
        # pins move linearly from pin_start to pin_end over the frame
        pinned: wp.array(dtype=int), pin_start: wp.array(dtype=wp.vec3),
        pin_end: wp.array(dtype=wp.vec3),
        # stretch (and distance bending when bend_i is not empty), in solve order
        stretch_i: wp.array(dtype=int), stretch_j: wp.array(dtype=int),
        stretch_rest: wp.array(dtype=float), stretch_inverse: wp.array(dtype=float),
        stretch_alpha: float, stretch_lagrange: wp.array(dtype=float),
        bend_i: wp.array(dtype=int), bend_j: wp.array(dtype=int),
        bend_rest: wp.array(dtype=float), bend_inverse: wp.array(dtype=float),
        bend_alpha: float, bend_lagrange: wp.array(dtype=float),
        # dihedral bending (no hinges: empty arrays)
        hinges: wp.array2d(dtype=int), hinge_weights: wp.array2d(dtype=float),
        hinge_shares: wp.array2d(dtype=float), hinge_rest: wp.array(dtype=float),
        hinge_compliance: wp.array(dtype=float), hinge_lagrange: wp.array(dtype=float),
        # tethers (none: empty arrays)
        tether_vertex: wp.array(dtype=int), tether_anchor: wp.array(dtype=int),
        tether_reach: wp.array(dtype=float),
        # contact planes (no body: empty arrays); body_fraction < 0 follows the substep
        contact_start: wp.array(dtype=wp.vec3), contact_end: wp.array(dtype=wp.vec3),
        normal_start: wp.array(dtype=wp.vec3), normal_end: wp.array(dtype=wp.vec3),
        body_step: wp.array(dtype=wp.vec3), body_fraction: float, thickness: float,
        friction: float):
    """Substeps ``first .. first + count`` of a frame of ``substeps``, as
    :meth:`XPBDCloth._frame <swingar_pyg.sim.XPBDCloth>` runs them."""
    n = x.shape[0]
    for sub in range(first, first + count):
        fraction = float(sub + 1) / float(substeps)
        for k in range(n):
            velocity = (v[k] + dt * gravity) * decay
            v[k] = velocity
            p[k] = x[k] + dt * velocity
        for k in range(pinned.shape[0]):
            p[pinned[k]] = pin_start[k] + fraction * (pin_end[k] - pin_start[k])
        for c in range(stretch_lagrange.shape[0]):
            stretch_lagrange[c] = 0.0
        for c in range(bend_lagrange.shape[0]):
            bend_lagrange[c] = 0.0
        for h in range(hinge_lagrange.shape[0]):
            hinge_lagrange[h] = 0.0
        plane_fraction = body_fraction
        if plane_fraction < 0.0:
            plane_fraction = fraction
        bend = sub % bend_every == 0
        for iteration in range(iterations):
            # the torch path's order: bending, tethers, contacts, stretch last
            if bend:
                _solve_distance(p, inverse_mass, bend_i, bend_j, bend_rest, bend_inverse,
                                bend_alpha, bend_lagrange)
            if bend and hinges.shape[0] > 0:
                for h in range(hinges.shape[0]):
                    _hinge_step(p, h, hinges, hinge_weights, hinge_shares, hinge_rest,
                                hinge_compliance, hinge_lagrange, correction)
                for k in range(n):
                    p[k] = p[k] + correction[k]
                    correction[k] = wp.vec3(0.0)
            for t in range(tether_vertex.shape[0]):
                free = tether_vertex[t]
                delta = p[free] - p[tether_anchor[t]]
                length = wp.length(delta)
                excess = wp.max(length - tether_reach[t], 0.0)
                p[free] = p[free] - (excess / wp.max(length, 1.0e-12)) * delta
            for k in range(contact_start.shape[0]):
                if inverse_mass[k] > 0.0:
                    normal = wp.normalize(normal_start[k]
                                          + plane_fraction * (normal_end[k] - normal_start[k]))
                    point = contact_start[k] + plane_fraction * (contact_end[k] - contact_start[k])
                    depth = wp.dot(p[k] - point, normal) - thickness
                    push = wp.max(-depth, 0.0)
                    slip = (p[k] - x[k]) - body_step[k]
                    slip = slip - wp.dot(slip, normal) * normal
                    keep = wp.min(friction * push / wp.max(wp.length(slip), 1.0e-12), 1.0)
                    p[k] = p[k] + push * normal - keep * slip
            _solve_distance(p, inverse_mass, stretch_i, stretch_j, stretch_rest,
                            stretch_inverse, stretch_alpha, stretch_lagrange)
        for k in range(n):
            v[k] = (p[k] - x[k]) / dt
            x[k] = p[k]



class WarpSubsteps:
    """One cloth's arrays for :func:`xpbd_substeps`, shared with torch (zero copy),
    and the launches.

    Args:
        inverse_mass: ``(N,)`` float32 on the CPU, 0 at pins.
        pinned: ``(P,)`` pinned vertices.
        stretch_pairs, stretch_rest: ``(C, 2)`` and ``(C,)`` edges in solve (colour) order.
        bend_pairs, bend_rest: the same for distance bending (empty otherwise).
        hinges: ``(H, 4)`` hinge corners, with ``hinge_weights`` (their inverse masses),
            ``hinge_shares`` (those over each corner's hinge count), ``(H, 4)``, and
            ``hinge_rest`` angles ``(H,)`` (all empty without dihedral bending).
        tether_vertices, tether_anchors, tether_reach: ``(T,)`` each tether's free
            vertex, its pin and the farthest it may be from it (empty: no tethers).

    Raises:
        ValueError: for anything but float32 on the CPU.
    """

    def __init__(self, inverse_mass: Tensor, pinned: Tensor, stretch_pairs: Tensor,
                 stretch_rest: Tensor, bend_pairs: Tensor, bend_rest: Tensor, hinges: Tensor,
                 hinge_weights: Tensor, hinge_shares: Tensor, hinge_rest: Tensor,
                 tether_vertices: Tensor, tether_anchors: Tensor, tether_reach: Tensor):
        if inverse_mass.dtype != torch.float32 or inverse_mass.device.type != "cpu":
            raise ValueError(f"backend='warp' runs float32 on the CPU, got {inverse_mass.dtype} "
                             f"on {inverse_mass.device}; use backend='torch' there")
        init_warp()
        wp.load_module(device="cpu")  # compiles (or loads from the cache) before any frame
        self._tensors: list[Tensor] = []  # the torch memory the warp arrays view
        n = len(inverse_mass)
        self.x, self.v, self.p, self.correction = (self._vectors(torch.zeros(n, 3))
                                                   for _ in range(4))
        self.inverse_mass = self._floats(inverse_mass)
        self.pinned = self._ints(pinned)
        self.stretch = (self._ints(stretch_pairs[:, 0]), self._ints(stretch_pairs[:, 1]),
                        self._floats(stretch_rest))
        self.bend = (self._ints(bend_pairs[:, 0]), self._ints(bend_pairs[:, 1]),
                     self._floats(bend_rest))
        self.hinges = (self._ints(hinges), self._floats(hinge_weights),
                       self._floats(hinge_shares), self._floats(hinge_rest))
        self.tethers = (self._ints(tether_vertices), self._ints(tether_anchors),
                        self._floats(tether_reach))
        self.stretch_lagrange = self._floats(torch.zeros(len(stretch_rest)))
        self.bend_lagrange = self._floats(torch.zeros(len(bend_rest)))
        self.hinge_lagrange = self._floats(torch.zeros(len(hinge_rest)))
        self.no_contacts = self._vectors(torch.zeros(0, 3))
        self._per_substeps: dict[int, tuple] = {}

    def _keep(self, tensor: Tensor) -> Tensor:
        tensor = tensor.contiguous()
        self._tensors.append(tensor)
        return tensor

    def _vectors(self, tensor: Tensor) -> wp.array:
        return wp.from_torch(self._keep(tensor.float()), dtype=wp.vec3)

    def _floats(self, tensor: Tensor) -> wp.array:
        return wp.from_torch(self._keep(tensor.float()))

    def _ints(self, tensor: Tensor) -> wp.array:
        return wp.from_torch(self._keep(tensor.to(torch.int32)))

    def compliance(self, substeps: int, stretch_colours: tuple, bend_colours: tuple,
                   hinge_compliance: Tensor | None) -> tuple:
        """The per-substep-length arrays, made once per substep count: each stretch and
        bend pair's ``1 / (w_i + w_j + alpha)`` in solve order (from the torch path's
        colours) and the hinge compliances (empty where this cloth has no hinges)."""
        if substeps not in self._per_substeps:
            def in_solve_order(colours: tuple) -> Tensor:
                return (torch.cat([c.inverse_denominator for c in colours]) if colours
                        else torch.zeros(0))

            hinged = self.hinges[0].shape[0] > 0
            self._per_substeps[substeps] = (
                self._floats(in_solve_order(stretch_colours)),
                self._floats(in_solve_order(bend_colours)),
                self._floats(hinge_compliance if hinged else torch.zeros(0)))
        return self._per_substeps[substeps]

    def run(self, x: Tensor, v: Tensor, first: int, count: int, substeps: int,
            iterations: int, bend_every: int, dt: float, decay: float, gravity: Tensor,
            pin_start: Tensor, pin_end: Tensor, compliance: tuple, stretch_alpha: float,
            bend_alpha: float, contacts: tuple[Tensor, Tensor, Tensor, Tensor, Tensor] | None,
            body_fraction: float, thickness: float, friction: float) -> tuple[Tensor, Tensor]:
        """Substeps ``first .. first + count`` of a frame of ``substeps`` from ``x``,
        ``v`` (left unchanged); returns the new positions and velocities.
        ``contacts``: contact points and normals at the frame's start and end and
        each vertex's body step, ``(N, 3)`` each; ``body_fraction`` < 0 moves the
        planes with the substep."""
        state_x, state_v = wp.to_torch(self.x), wp.to_torch(self.v)
        state_x.copy_(x)
        state_v.copy_(v)
        stretch_inverse, bend_inverse, hinge_compliance = compliance
        planes = [c.float().contiguous() for c in contacts or ()]  # alive through the launch
        targets = [pin_start.float().contiguous(), pin_end.float().contiguous()]
        plane_arrays = ([wp.from_torch(c, dtype=wp.vec3) for c in planes] if planes
                        else [self.no_contacts] * 5)
        corners, weights, shares, rest = self.hinges
        wp.launch(xpbd_substeps, dim=1, device="cpu", inputs=[
            self.x, self.v, self.p, self.correction, self.inverse_mass,
            wp.vec3(*gravity.tolist()), dt, decay, first, count, substeps, iterations,
            bend_every,
            self.pinned, *(wp.from_torch(t, dtype=wp.vec3) for t in targets),
            *self.stretch, stretch_inverse, stretch_alpha, self.stretch_lagrange,
            *self.bend, bend_inverse, bend_alpha, self.bend_lagrange,
            corners, weights, shares, rest, hinge_compliance, self.hinge_lagrange,
            *self.tethers, *plane_arrays, body_fraction, thickness, friction])
        return state_x.clone(), state_v.clone()
