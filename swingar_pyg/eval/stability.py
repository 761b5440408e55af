"""The stability suite: every public stage on stiff, extreme and degenerate input.

Each case runs one stage (FCAConv, the spectral descriptor, the cloth simulator,
the estimator, collision handling) on one hard input and either gives finite
output, measured against an independent reference where there is one, or must
raise a clear :class:`ValueError`. Finite is not enough where a case has a
``bound``: its measure must stay within it (float32 against float64 within a few
roundoffs, the simulator's strain below 100 %, where an edge twice its rest
length is torn cloth rather than stretched cloth). A row whose output is not
finite, beyond its bound, or that fails otherwise, is a bug (``outcome`` says
which); :func:`run_stability` never hides one. A case whose input is known to
take a stage beyond its bound names the reason in ``limitation``; such a row is
``degraded``, reported as such, and not a bug.

Sizes: :data:`SMALL` runs in well under a minute (the tests), :data:`FULL` at the
sizes of real use (the report): 10k-vertex graphs, a 1.5k-vertex skirt simulated
for seconds, a 10 000-frame stream.
"""

from __future__ import annotations

import importlib.util
import math
import time
from dataclasses import asdict, dataclass
from functools import cached_property
from typing import Callable

import numpy as np
import torch
from torch import Tensor

from swingar_pyg.inference import SwinGarStream


@dataclass(frozen=True)
class StabilitySizes:
    """How large each case is."""

    graph_side: int
    descriptor_side: int
    skirt_vertices: int
    sim_seconds: float
    substeps: int
    stream_frames: int


SMALL = StabilitySizes(graph_side=24, descriptor_side=16, skirt_vertices=200, sim_seconds=0.3,
                       substeps=10, stream_frames=300)
FULL = StabilitySizes(graph_side=100, descriptor_side=70, skirt_vertices=1500, sim_seconds=2.0,
                      substeps=50, stream_frames=10_000)


@dataclass
class StabilityRow:
    """One case: ``outcome`` is ``finite`` (within the case's bound) or
    ``raises`` when all is well, ``degraded`` when beyond a bound the case
    documents as a limitation; ``beyond bound``, ``non-finite``, ``failed`` or
    ``did not raise`` mark a bug."""

    component: str
    case: str
    outcome: str
    measure: str
    value: float | None
    bound: float | None = None
    note: str = ""
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.outcome in ("finite", "raises", "degraded")


@dataclass(frozen=True)
class Case:
    """One hard input for one stage.

    ``run`` returns the measure's value, the outputs checked for finiteness and
    optionally a note; ``bound`` is the largest acceptable value (``None``: any
    finite value); ``limitation`` says why this input may go beyond it;
    ``raises`` is the text the expected :class:`ValueError` contains."""

    component: str
    name: str
    measure: str
    run: Callable[["_Context"], tuple[float, list]]
    bound: float | None = None
    limitation: str = ""
    raises: str | None = None
    needs: str | None = None  # an optional package the case runs only with


def available_cases() -> list[Case]:
    """The cases whose optional packages are installed."""
    return [c for c in CASES if c.needs is None or importlib.util.find_spec(c.needs) is not None]


class _Context:
    """What the cases share, built on first use."""

    def __init__(self, sizes: StabilitySizes, estimator, body_sdf_checkpoint: str | None):
        self.sizes = sizes
        self.given_estimator = estimator
        self.body_sdf_checkpoint = body_sdf_checkpoint

    @cached_property
    def body(self):
        from swingar_pyg.world.body import AnnyBody

        return AnnyBody()

    @cached_property
    def shape(self) -> Tensor:
        return self.body.default_shape()

    @cached_property
    def skirt(self):
        from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt

        return fit_procedural_skirt(SkirtSpec(length=0.6, flare=0.35,
                                              vertices=self.sizes.skirt_vertices),
                                    self.body, self.shape)

    @cached_property
    def estimator(self):
        from swingar_pyg.models import SwinGarEstimator

        if self.given_estimator is not None:
            return self.given_estimator.eval()
        torch.manual_seed(0)
        model = SwinGarEstimator(channels=16, detail_channels=8, descriptor_size=32, history=16)
        # Untrained heads start at zero (rigid skinning); random ones exercise every path.
        for parameter in model.parameters():
            torch.nn.init.normal_(parameter, std=0.1)
        return model.eval()

    @cached_property
    def graph(self):
        from swingar_pyg.inference.prediction import garment_graph

        return garment_graph(self.skirt, len(self.body.joint_names),
                             self.estimator.descriptor_size)

    def motion(self, kind: str, seconds: float, **options):
        from swingar_pyg.world.motion_library import make_motion

        return make_motion(kind, self.body, self.shape, seconds=seconds, **options)

    @cached_property
    def neural(self):
        from swingar_pyg.collision import NeuralCollisions
        from swingar_pyg.training import load_body_sdf

        if self.body_sdf_checkpoint is None:
            return None
        return NeuralCollisions.for_body(load_body_sdf(self.body_sdf_checkpoint), self.body,
                                         self.shape)


# ----------------------------------------------------------------------------- FCAConv

def _sheet_graph(side: int):
    from swingar_pyg.geometry import mesh_edge_index, sheet

    return mesh_edge_index(sheet(side, side, jitter=0.3))


def _conv():
    from swingar_pyg.nn import FCAConv

    torch.manual_seed(0)
    return FCAConv(8, 16, heads=4, alpha=2.0)


def _relative_to_float64(conv, x: Tensor, edge_index: Tensor, dtype: torch.dtype) -> tuple:
    reference = _conv().double()
    reference.load_state_dict(conv.state_dict())
    exact = reference(x.double(), edge_index)
    out = conv.to(dtype)(x.to(dtype), edge_index).double()
    error = float((out - exact).abs().max() / exact.abs().max().clamp_min(1e-300))
    return error, [out]


def _fca_scale(scale: float):
    def run(context):
        edges = _sheet_graph(context.sizes.graph_side)
        x = scale * torch.randn(int(edges.max()) + 1, 8)
        return _relative_to_float64(_conv(), x, edges, torch.float32)
    return run


def _fca_precision(dtype: torch.dtype):
    def run(context):
        edges = _sheet_graph(context.sizes.graph_side)
        x = torch.randn(int(edges.max()) + 1, 8)
        return _relative_to_float64(_conv(), x, edges, dtype)
    return run


def _fca_isolated(context):
    edges = _sheet_graph(context.sizes.graph_side)
    n = int(edges.max()) + 1
    conv = _conv()
    x = torch.randn(n + 10, 8)
    out = conv(x, edges)
    # an isolated vertex attends to itself only: its output is its own message
    own = conv.lin(x[n:]).view(10, 4, 16).mean(1) if not conv.concat else conv.lin(x[n:])
    return float((out[n:] - own - conv.bias).abs().max()), [out]


def _fca_pieces(context):
    from torch_geometric.data import Batch, Data

    edges = _sheet_graph(context.sizes.graph_side)
    small = _sheet_graph(7)
    conv = _conv()
    a, b = torch.randn(int(edges.max()) + 1, 8), 1e3 * torch.randn(49, 8)
    batch = Batch.from_data_list([Data(x=a, edge_index=edges), Data(x=b, edge_index=small)])
    together = conv(batch.x, batch.edge_index)
    alone = torch.cat([conv(a, edges), conv(b, small)])
    scale = alone.abs().amax(dim=1, keepdim=True).clamp_min(1e-30)
    return float(((together - alone) / scale).abs().max()), [together]


def _fca_degenerate(context):
    from swingar_pyg.geometry import as_mesh, mesh_edge_index, sheet

    base = sheet(context.sizes.graph_side, context.sizes.graph_side)
    faces = np.concatenate([base.faces, [[0, 0, 1], [5, 5, 5]]])
    vertices = base.vertices.copy()
    vertices[1] = vertices[0]  # a zero-length edge
    edges = mesh_edge_index(as_mesh(vertices, faces))
    out = _conv()(torch.zeros(len(vertices), 8), edges)  # all-equal (zero) features too
    return float(out.abs().max()), [out]


# -------------------------------------------------------------------- spectral descriptor

def _tube(side: int, scale: float = 1.0):
    from swingar_pyg.geometry import as_mesh, roll_into_cylinder, sheet

    mesh = roll_into_cylinder(sheet(side, 2 * side, width=1.2, height=0.6, jitter=0.2),
                              radius=0.2)
    return as_mesh(mesh.vertices * scale, mesh.faces)


def _top_error(approximate: np.ndarray, exact: np.ndarray, k: int = 16) -> float:
    k = min(k, len(exact))
    return float(np.max(np.abs(approximate[:k] - exact[:k]) / np.abs(exact[:k]).max()))


def _descriptor_scale(scale: float):
    def run(context):
        from swingar_pyg.geometry import spectral_descriptor

        unit = spectral_descriptor(_tube(context.sizes.descriptor_side), z=128, sigma=0.1)
        scaled = spectral_descriptor(_tube(context.sizes.descriptor_side, scale), z=128,
                                     sigma=0.1 * scale)
        fixed = spectral_descriptor(_tube(context.sizes.descriptor_side, scale), z=128, sigma=0.1)
        return _top_error(scaled.eigenvalues, unit.eigenvalues), [scaled.eigenvalues,
                                                                   fixed.eigenvalues]
    return run


def _descriptor_small(context):
    from swingar_pyg.geometry import exact_affinity_spectrum, sheet, spectral_descriptor

    mesh = sheet(5, 6)
    descriptor = spectral_descriptor(mesh, z=256, sigma=0.1, return_eigenvectors=True)
    exact, _ = exact_affinity_spectrum(mesh, sigma=0.1)
    return _top_error(descriptor.eigenvalues[:descriptor.num_valid], exact, 30), [
        descriptor.eigenvalues, descriptor.eigenvectors]


def _descriptor_pieces(context):
    from swingar_pyg.geometry import as_mesh, exact_affinity_spectrum, sheet, spectral_descriptor

    side = context.sizes.descriptor_side
    pieces = [_tube(side), sheet(side // 2, side // 2, width=0.3, height=0.3)]
    offset = pieces[0].num_vertices
    union = as_mesh(np.concatenate([pieces[0].vertices, pieces[1].vertices + [5.0, 0, 0]]),
                    np.concatenate([pieces[0].faces, pieces[1].faces + offset]))
    descriptor = spectral_descriptor(union, z=256, sigma=0.1)
    exact = np.sort(np.concatenate([exact_affinity_spectrum(p, sigma=0.1)[0]
                                    for p in pieces]))[::-1]
    return _top_error(descriptor.eigenvalues, exact), [descriptor.eigenvalues]


def _descriptor_degenerate(context):
    from swingar_pyg.geometry import as_mesh, exact_affinity_spectrum, spectral_descriptor

    tube = _tube(context.sizes.descriptor_side)
    vertices = np.concatenate([tube.vertices, tube.vertices[:1], [[9.0, 9.0, 9.0]]])
    faces = np.concatenate([tube.faces, [[0, 0, 1], [2, 2, 2]]])
    mesh = as_mesh(vertices, faces)  # a duplicate vertex, an isolated one, zero-area faces
    descriptor = spectral_descriptor(mesh, z=256, sigma=0.1, return_eigenvectors=True)
    exact, _ = exact_affinity_spectrum(mesh, sigma=0.1)
    return _top_error(descriptor.eigenvalues, exact), [descriptor.eigenvalues,
                                                       descriptor.eigenvectors]


# ------------------------------------------------------------------------- simulator

def _simulate(context, motion: str = "sway", speed: float = 1.0, **settings):
    from swingar_pyg.sim import XPBDSettings

    options = dict(substeps=context.sizes.substeps, iterations=2, settle_frames=5)
    options.update(settings)
    solver = XPBDSettings(**options)
    return _simulated(context, motion, speed, solver)


def _simulated(context, motion: str, speed: float, solver) -> tuple:
    from swingar_pyg.world.sequence import simulate_sequence

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
        from swingar_pyg.sim import VBDSettings

        steps = max(5, context.sizes.substeps // 5)
        solver = VBDSettings(substeps=substeps or steps, iterations=steps, settle_frames=5,
                             **settings)
        return _simulated(context, motion, speed, solver)
    return run


# ------------------------------------------------------------------------- estimator

def _stream(context, rotations, translation, autocast: torch.dtype | None = None) -> Tensor:
    from swingar_pyg.inference.prediction import animate

    posed = context.body.pose(context.shape, rotations, translation)
    with torch.autocast("cpu", dtype=autocast, enabled=autocast is not None):
        vertices, _ = animate(context.estimator, context.graph, context.shape, rotations,
                              translation, posed.joint_transforms, posed.joint_positions, 30.0,
                              progress=False)
    return vertices.float()


def _estimator_drift(context):
    # A periodic motion streamed for many periods: once the pose window is full,
    # the garment at a frame and at the same phase many periods later must agree.
    frames = context.sizes.stream_frames
    clip = context.motion("sway", frames / 30.0)
    vertices = _stream(context, clip.rotations, clip.translation)
    period = 30  # sway at speed 1: one period per second
    first = context.estimator.history + 2 * period
    last = first + ((frames - 1 - first) // period) * period
    drift = float((vertices[last] - vertices[first]).norm(dim=-1).max())
    return 1e3 * drift, [vertices], f"frames {first} and {last}"


def _estimator_bf16(context):
    clip = context.motion("kick", 2.0)
    full = _stream(context, clip.rotations, clip.translation)
    half = _stream(context, clip.rotations, clip.translation, autocast=torch.bfloat16)
    return 1e3 * float((half - full).norm(dim=-1).max()), [half]


def _estimator_extreme(kind: str):
    def run(context):
        from swingar_pyg.geometry.skinning import linear_blend_skinning

        clip = context.motion(kind, 2.0)
        vertices = _stream(context, clip.rotations, clip.translation)
        posed = context.body.pose(context.shape, clip.rotations, clip.translation)
        skirt = context.skirt
        rigid = linear_blend_skinning(context.graph.rest, torch.as_tensor(skirt.skin_indices),
                                      torch.as_tensor(skirt.skin_weights, dtype=torch.float32),
                                      posed.joint_transforms)
        return 1e3 * float((vertices - rigid).norm(dim=-1).mean()), [vertices]
    return run


def _estimator_large(context):
    from swingar_pyg.inference.prediction import garment_graph
    from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt

    vertices = 20 * context.sizes.skirt_vertices
    skirt = fit_procedural_skirt(SkirtSpec(length=0.8, vertices=vertices, jitter=0.3),
                                 context.body, context.shape)
    graph = garment_graph(skirt, len(context.body.joint_names), context.estimator.descriptor_size)
    clip = context.motion("walk", 0.3)
    posed = context.body.pose(context.shape, clip.rotations, clip.translation)
    stream = SwinGarStream(context.estimator, graph, context.shape, 30.0)
    start = time.perf_counter()
    out = [stream.step(clip.rotations[t], clip.translation[t], posed.joint_transforms[t],
                       posed.joint_positions[t]) for t in range(len(clip.rotations))]
    ms = 1e3 * (time.perf_counter() - start) / len(out)
    return ms, out, f"{skirt.mesh.num_vertices} vertices"


# ------------------------------------------------------------------- collision handling

SURFACE_TOLERANCE = 1e-6
"""A corrected vertex counts as inside the body when deeper than this (1 µm): one
moved onto the surface lands on either side of it by rounding alone."""


def _collide(context, vertices: Tensor, posed_index: int, posed) -> tuple:
    from swingar_pyg.collision import exact_signed_distance, resolve_collisions

    exact = exact_signed_distance(posed.vertices[posed_index], context.body.faces)
    if context.neural is not None:
        result = context.neural.correct(vertices.float(), context.graph.edge_index,
                                        posed.joint_transforms[posed_index],
                                        posed.joint_positions[posed_index])
        sdf = "neural SDF"
    else:
        result = resolve_collisions(vertices.double(), context.graph.edge_index, exact)
        sdf = "exact SDF"
    before = float((exact(vertices.double())[0] > 0).float().mean())
    depth = exact(result.vertices.double())[0]
    after = float((depth > SURFACE_TOLERANCE).float().mean())
    return 100 * after, [result.vertices], (f"{sdf}; inside before {100 * before:.1f} %, "
                                            f"deepest after {1e3 * float(depth.max()):.3g} mm")


def _collision_inside(context):
    # the skirt shrunk onto the body's axis: every vertex deep inside
    clip = context.motion("sway", 0.1)
    posed = context.body.pose(context.shape, clip.rotations[:1], clip.translation[:1])
    rest = context.graph.rest
    centre = rest.mean(0)
    inside = centre + 0.3 * (rest - centre) * torch.tensor([1.0, 1.0, 0.0]) + \
        (rest - centre) * torch.tensor([0.0, 0.0, 1.0])
    return _collide(context, inside, 0, posed)


def _collision_extreme(kind: str, seconds: float):
    def run(context):
        # The skirt carried by the hips alone while the legs split or the arms cross
        # through it: as deep a collision as a badly skinned garment meets.
        clip = context.motion(kind, 2.0)
        frame = round(seconds * clip.fps)
        posed = context.body.pose(context.shape, clip.rotations, clip.translation)
        hips = posed.joint_transforms[frame, 0]
        carried = context.graph.rest @ hips[:3, :3].T + hips[:3, 3]
        return _collide(context, carried, frame, posed)
    return run


def _collision_scale(context):
    from swingar_pyg.collision import resolve_collisions

    def ball(points):  # a sphere of radius 1 km, positive inside
        norm = points.norm(dim=-1, keepdim=True)
        return 1e3 - norm[:, 0], -points / norm.clamp_min(1e-300)

    rest = context.graph.rest.double() * 1e3
    result = resolve_collisions(rest - rest.mean(0), context.graph.edge_index, ball)
    inside = ball(result.vertices)[0] > 1e3 * SURFACE_TOLERANCE
    return 100 * float(inside.float().mean()), [result.vertices]


# ------------------------------------------------------------------- clear errors

def _raise_mesh_nan(context):
    from swingar_pyg.geometry import as_mesh

    as_mesh([[0, 0, 0], [1, 0, float("nan")], [0, 1, 0]], [[0, 1, 2]])


def _raise_simulator_settings(context):
    from swingar_pyg.sim import XPBDSettings

    XPBDSettings(stretch_compliance=-1.0)


def _raise_vbd_settings(context):
    from swingar_pyg.sim import VBDSettings

    VBDSettings(bend_stiffness=-1.0)


def _raise_body_shape(context):
    context.body.rest_vertices(torch.full((6,), 1.5))


def _raise_body_sdf_nan(context):
    from swingar_pyg.models import BodySDF

    BodySDF()(torch.full((2, 3), float("nan")), torch.eye(4).expand(1, 31, 4, 4),
              torch.zeros(1, 31, 3), torch.zeros(1, 6))


def _raise_collision_nan(context):
    from swingar_pyg.collision import resolve_collisions

    resolve_collisions(torch.full((3, 3), float("nan")), torch.zeros(2, 0, dtype=torch.long),
                       lambda x: (x[:, 0], x))


def _raise_descriptor_sigma(context):
    from swingar_pyg.geometry import sheet, spectral_descriptor

    spectral_descriptor(sheet(4, 4), sigma=0.0)


def _raise_estimator_window(context):
    from swingar_pyg.models import GarmentWindow

    graph = context.graph
    window = GarmentWindow(rest=graph.rest, normal=graph.normal, fit=graph.fit,
                           prior_weights=graph.prior_weights[:, :3], edge_index=graph.edge_index,
                           pose_history=torch.zeros(1, 3, 4, 10))
    context.estimator(window)


FLOAT32 = 1e-5  # float32 against float64: a few hundred roundoffs of 2^-24
BFLOAT16 = 8 * 2.0**-8  # eight roundoffs of bfloat16's 8-bit significand
FLOAT16 = 8 * 2.0**-11
EXACT = 1e-9  # float64 against float64
NYSTROM = 0.05  # Nyström's top eigenvalues against the exact spectrum
TORN = 1.0  # an edge at twice its rest length is torn cloth, not stretched cloth
BF16_MM = 5 * 2.0**-8 * 1e3  # five bfloat16 roundoffs of a coordinate 1 m from the origin
INSIDE_PERCENT = 0.5
# The motion's phase is float32: 10,000 frames in, 2*pi*333 s = 2,092 rad carries a
# roundoff of 2.4e-4 rad, which moves a 12-degree sway of a 1 m body by up to ~0.05 mm.
# Drift beyond twice that is the estimator's recurrent state, not the clock.
DRIFT_MM = 0.1

_OVER_CONSTRAINED = ("a waist-pinned skirt around legs split wide is over-constrained; with "
                     "the default dihedral bending it stays under the bound")
_VBD_STEP = ("newton's VBD does not converge in a 33 ms step (VBDSettings' default is 10 "
             "substeps a frame)")

CASES: tuple[Case, ...] = (
    Case("FCAConv", "input x 1e-3", "max relative error vs float64", _fca_scale(1e-3),
         bound=FLOAT32),
    Case("FCAConv", "input x 1e3", "max relative error vs float64", _fca_scale(1e3),
         bound=FLOAT32),
    Case("FCAConv", "bfloat16", "max relative error vs float64", _fca_precision(torch.bfloat16),
         bound=BFLOAT16),
    Case("FCAConv", "float16", "max relative error vs float64", _fca_precision(torch.float16),
         bound=FLOAT16),
    Case("FCAConv", "isolated vertices", "max |output - own message|", _fca_isolated,
         bound=FLOAT32),
    Case("FCAConv", "disconnected pieces (1 : 1e3 scale)", "max relative gap Batch vs alone",
         _fca_pieces, bound=FLOAT32),
    Case("FCAConv", "zero-area faces, zero features", "max |output|", _fca_degenerate,
         bound=FLOAT32),
    Case("descriptor", "scale 1e-3 (sigma scaled)", "top-16 error vs unit scale",
         _descriptor_scale(1e-3), bound=EXACT),
    Case("descriptor", "scale 1e3 (sigma scaled)", "top-16 error vs unit scale",
         _descriptor_scale(1e3), bound=EXACT),
    Case("descriptor", "N < z (30 vertices, z = 256)", "error vs exact spectrum",
         _descriptor_small, bound=EXACT),
    Case("descriptor", "disconnected pieces", "top-16 error vs exact spectra", _descriptor_pieces,
         bound=NYSTROM),
    Case("descriptor", "duplicate + isolated vertex, zero-area faces", "top-16 error vs exact",
         _descriptor_degenerate, bound=NYSTROM),
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
    Case("estimator", "long stream (drift)", "max mm between equal phases", _estimator_drift,
         bound=DRIFT_MM),
    Case("estimator", "bfloat16 autocast", "max mm vs float32", _estimator_bf16, bound=BF16_MM),
    Case("estimator", "legs split", "mean mm from rigid skinning", _estimator_extreme("leg_split")),
    Case("estimator", "arms crossed", "mean mm from rigid skinning",
         _estimator_extreme("arm_cross")),
    Case("estimator", "20x the vertices", "ms per streamed frame", _estimator_large),
    Case("collisions", "garment entirely inside", "% over 1 µm inside after", _collision_inside,
         bound=INSIDE_PERCENT),
    Case("collisions", "legs split through a hip-carried skirt", "% over 1 µm inside after",
         _collision_extreme("leg_split", 0.5), bound=INSIDE_PERCENT),
    Case("collisions", "front split through a hip-carried skirt", "% over 1 µm inside after",
         _collision_extreme("leg_split", 1.5), bound=INSIDE_PERCENT),
    Case("collisions", "coordinates x 1e3", "% over 1 mm inside after (x 1e3)", _collision_scale,
         bound=INSIDE_PERCENT),
    Case("mesh", "NaN vertex", "", _raise_mesh_nan, raises="not finite"),
    Case("simulator", "negative compliance", "", _raise_simulator_settings,
         raises="must be finite and >= 0"),
    Case("VBD simulator", "negative bending stiffness", "", _raise_vbd_settings,
         raises="must be finite and >= 0", needs="newton"),
    Case("body", "shape outside [0, 1]", "", _raise_body_shape, raises="must lie in [0, 1]"),
    Case("body SDF", "NaN points", "", _raise_body_sdf_nan, raises="points must be finite"),
    Case("collisions", "NaN garment", "", _raise_collision_nan, raises="not finite"),
    Case("descriptor", "sigma 0", "", _raise_descriptor_sigma, raises="sigma must be"),
    Case("estimator", "wrong joint count", "", _raise_estimator_window, raises="prior_weights"),
)


def _finite(value) -> bool:
    if value is None:
        return True
    if isinstance(value, (list, tuple)):
        return all(_finite(v) for v in value)
    if isinstance(value, Tensor):
        return bool(torch.isfinite(value).all())
    return bool(np.isfinite(np.asarray(value, dtype=np.float64)).all())


def run_case(case: Case, context: _Context) -> StabilityRow:
    start = time.perf_counter()
    row = StabilityRow(case.component, case.name, "", case.measure, None, case.bound)
    try:
        with torch.no_grad():
            out = case.run(context)
    except ValueError as error:
        row.seconds = time.perf_counter() - start
        if case.raises is not None and case.raises in str(error):
            row.outcome, row.note = "raises", f"ValueError: {error}"
        else:
            row.outcome, row.note = "failed", f"ValueError: {error}"
        return row
    except Exception as error:  # a bug: reported, not hidden
        row.outcome, row.note = "failed", f"{type(error).__name__}: {error}"
        row.seconds = time.perf_counter() - start
        return row
    row.seconds = time.perf_counter() - start
    if case.raises is not None:
        row.outcome = "did not raise"
        return row
    value, outputs, *note = out
    row.value = float(value)
    row.note = note[0] if note else ""
    if not (_finite(outputs) and math.isfinite(row.value)):
        row.outcome = "non-finite"
    elif case.bound is None or row.value <= case.bound:
        row.outcome = "finite"
    else:
        row.outcome = "degraded" if case.limitation else "beyond bound"
        row.note = "; ".join(filter(None, [row.note, f"beyond {case.bound:.3g}: "
                                                     f"{case.limitation or 'a bug'}"]))
    return row


def run_stability(sizes: StabilitySizes = FULL, estimator=None, body_sdf: str | None = None,
                  components: tuple[str, ...] | None = None,
                  progress: bool = True) -> list[StabilityRow]:
    """Runs every case (or those of ``components``) and returns their rows.

    Args:
        sizes: :data:`SMALL` or :data:`FULL`.
        estimator: a trained :class:`~swingar_pyg.models.SwinGarEstimator`
            (default: a small one with random weights).
        body_sdf: a body SDF checkpoint for the collision cases (default: the
            exact SDF).
    """
    context = _Context(sizes, estimator, body_sdf)
    cases = [c for c in available_cases() if components is None or c.component in components]
    if progress:
        from tqdm import tqdm

        cases = tqdm(cases, desc="stability suite", unit="case")
    return [run_case(case, context) for case in cases]


def stability_summary(rows: list[StabilityRow]) -> str:
    """How many rows had each outcome, naming the degraded and the failing ones."""
    def named(some: list[StabilityRow]) -> str:
        return ": " + ", ".join(f"{r.component} / {r.case}" for r in some) if some else ""

    degraded = [row for row in rows if row.outcome == "degraded"]
    bad = [row for row in rows if not row.ok]
    return (f"{len(rows)} cases, {sum(r.outcome == 'finite' for r in rows)} finite within their "
            f"bounds, {sum(r.outcome == 'raises' for r in rows)} raising a clear ValueError, "
            f"{len(degraded)} degraded by a documented limitation{named(degraded)}; "
            f"{len(bad)} failing{named(bad)}")


def stability_table(rows: list[StabilityRow]) -> str:
    """The rows as a Markdown table."""
    lines = ["| component | case | outcome | measure | value | bound | note |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        value = "" if row.value is None else f"{row.value:.3g}"
        bound = "" if row.bound is None else f"{row.bound:.3g}"
        lines.append(f"| {row.component} | {row.case} | {row.outcome} | {row.measure} | "
                     f"{value} | {bound} | {row.note} |")
    return "\n".join(lines)


def as_dicts(rows: list[StabilityRow]) -> list[dict]:
    return [asdict(row) for row in rows]
