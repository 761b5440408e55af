"""The simulator cases: the XPBD and the VBD cloth simulators on stiff, heavy,
coarse-stepped and violently moving input, each measured by the largest edge
strain, which must stay below :data:`TORN`."""

from __future__ import annotations

import numpy as np

from swingar_pyg.eval.stability.records import Case
from swingar_pyg.sim import VBDSettings, XPBDSettings
from swingar_pyg.world.sequence import simulate_sequence

TORN = 1.0  # an edge at twice its rest length is torn cloth, not stretched cloth

_OVER_CONSTRAINED = ("a waist-pinned skirt around legs split wide is over-constrained; with "
                     "the default dihedral bending it stays under the bound")
_VBD_STEP = ("newton's VBD does not converge in a 33 ms step (VBDSettings' default is 10 "
             "substeps a frame)")


def _simulate(context, motion: str = "sway", speed: float = 1.0, **settings):
    options = dict(substeps=context.sizes.substeps, iterations=2, settle_frames=5)
    options.update(settings)
    solver = XPBDSettings(**options)
    return _simulated(context, motion, speed, solver)


def _simulated(context, motion: str, speed: float, solver) -> tuple:
    clip = context.motion(motion, context.sizes.sim_seconds, speed=speed, fps=solver.fps)
    result = simulate_sequence(context.body, context.shape, context.skirt, clip, solver).result
    note = (f"max stretch {100 * result.max_stretch.max():.1f} %, inside the body "
            f"{100 * np.nanmax(result.penetration):.2f} %")
    return float(result.max_stretch.max()), [result.positions], note


def _simulator(motion: str = "sway", speed: float = 1.0, **settings):
    return lambda context: _simulate(context, motion, speed, **settings)


def _simulator_coarse(context):
    substeps = max(1, context.sizes.substeps // 4)
    return _simulate(context, substeps=substeps)


def _vbd(motion: str = "sway", speed: float = 1.0, substeps: int | None = None, **settings):
    """A VBD case: 10 x 10 at full size, 5 x 5 at small size, unless told."""
    def run(context):
        steps = max(5, context.sizes.substeps // 5)
        solver = VBDSettings(substeps=substeps or steps, iterations=steps, settle_frames=5,
                             **settings)
        return _simulated(context, motion, speed, solver)
    return run


SIMULATOR_CASES: tuple[Case, ...] = (
    Case("simulator", "compliance 0 (stretch, distance bending)", "max edge strain",
         _simulator(bending="distance", bend_compliance=0.0), bound=TORN),
    Case("simulator", "bending 1e4x stiffer", "max edge strain", _simulator(bend_stiffness=10.0),
         bound=TORN),
    Case("simulator", "100x heavier cloth", "max edge strain", _simulator(density=15.0),
         bound=TORN),
    Case("simulator", "4x time step", "max edge strain", _simulator_coarse, bound=TORN),
    Case("simulator", "legs split", "max edge strain", _simulator("leg_split"), bound=TORN),
    Case("simulator", "arms crossed", "max edge strain", _simulator("arm_cross"), bound=TORN),
    Case("simulator", "fast spin (3 turns/s)", "max edge strain",
         _simulator("spin_stop", speed=3.0), bound=TORN),
    Case("simulator", "distance bending 100x stiffer", "max edge strain",
         _simulator(bending="distance", bend_compliance=1e-6), bound=TORN),
    Case("simulator", "distance bending, legs split", "max edge strain",
         _simulator("leg_split", bending="distance"), bound=TORN, limitation=_OVER_CONSTRAINED),
    # the datasets' path: the warp kernel, bending on one substep in ten (at 1e4x the
    # stiffness too: the multirate bending must not overshoot)
    Case("simulator", "warp kernel, bending every 10th substep, 1e4x stiffer", "max edge strain",
         _simulator(backend="warp", bend_every=10, bend_stiffness=10.0), bound=TORN),
    Case("simulator", "warp kernel, 100x heavier cloth", "max edge strain",
         _simulator(backend="warp", bend_every=10, density=15.0), bound=TORN),
    Case("simulator", "warp kernel, legs split", "max edge strain",
         _simulator("leg_split", backend="warp", bend_every=10), bound=TORN),
    Case("simulator", "warp kernel, fast spin (3 turns/s)", "max edge strain",
         _simulator("spin_stop", speed=3.0, backend="warp", bend_every=10), bound=TORN),
)

VBD_CASES: tuple[Case, ...] = (
    Case("VBD simulator", "membrane 100x stiffer", "max edge strain",
         _vbd(stretch_stiffness=1e6), bound=TORN, needs="newton"),
    Case("VBD simulator", "bending 1e4x stiffer", "max edge strain", _vbd(bend_stiffness=10.0),
         bound=TORN, needs="newton"),
    Case("VBD simulator", "100x heavier cloth", "max edge strain", _vbd(density=15.0),
         bound=TORN, needs="newton"),
    Case("VBD simulator", "one substep per frame (33 ms)", "max edge strain", _vbd(substeps=1),
         bound=TORN, limitation=_VBD_STEP, needs="newton"),
    Case("VBD simulator", "legs split", "max edge strain", _vbd("leg_split"), bound=TORN,
         needs="newton"),
    Case("VBD simulator", "fast spin (3 turns/s)", "max edge strain", _vbd("spin_stop", speed=3.0),
         bound=TORN, needs="newton"),
)
