r"""Procedural sewn garments: long t-shirts and jumpsuits cut as a front and a back
panel from one pattern, sewn along its seams and wrapped around the rest body.

A pattern is a polygon in the body's frontal plane :math:`(x, z)` whose edges are
seams or openings (neckline, sleeve ends, hem, chest line, ankles). Its inside is
triangulated at the spacing that gives the asked vertex count (a square grid,
optionally jittered, plus points along the outline; Delaunay, triangles outside
the polygon dropped). The back panel shares the front's vertices on seams, so the
two panels close into one surface with holes at the openings.

Each panel vertex is lifted to the depth of the body in front of (behind) it,
:math:`y_f(x, z) = \min y - c` and :math:`y_b(x, z) = \max y + c` over the body's
kept vertices near :math:`(x, z)` (clearance :math:`c`), and eased into the seam
plane :math:`m = (y_f + y_b) / 2` as it nears a seam, with an elliptic profile

.. math::
    y = m + (y_{f,b} - m) \sqrt{1 - (1 - u)^2}, \qquad u = \min(1, d / r),

:math:`d` its distance to the nearest seam and :math:`r` the taper radius. Vertices
still closer to the body than the clearance are moved out along the exact
outward normal (:class:`~swingar_pyg.collision.reference.BodySurface`). Pinning,
skinning and the fit attribute are those of
:func:`~swingar_pyg.world.garment.garment_on_body`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from swingar_pyg.geometry.mesh import Mesh, as_mesh

if TYPE_CHECKING:
    from swingar_pyg.world.body import BodyModel
    from swingar_pyg.world.garment import Garment

_TAPER_RADIUS = 0.06
_DEPTH_BIN = 0.01


@dataclass(frozen=True)
class Pattern:
    """A closed polygon ``(K, 2)`` in the frontal plane (x, z), counter-clockwise,
    and whether each edge ``k -> k + 1`` is an opening (else a seam)."""

    outline: np.ndarray
    opening: np.ndarray


@dataclass(frozen=True)
class TShirtSpec:
    """A procedural long t-shirt with short sleeves, pinned at the neckline.

    Attributes:
        length: neck to hem, metres (0.6 hip ... 1.0 above the knee: a tunic).
        sleeve: sleeve length as a share of the upper arm (0.2 ... 1).
        ease: room between body and cloth at the side seams, metres.
        flare: how far the hem stands out beyond the hips, metres.
        vertices: about how many vertices.
        jitter: 0 for a square grid; up to 0.4 moves interior points within their cells.
        clearance: the least gap kept from the body at rest, metres.
        seed: for the jitter.
    """

    length: float = 0.8
    sleeve: float = 0.5
    ease: float = 0.04
    flare: float = 0.08
    vertices: int = 1500
    jitter: float = 0.0
    clearance: float = 0.01
    seed: int = 0

    def __post_init__(self):
        _check(self, length=(0.4, 1.2), sleeve=(0.2, 1.0), ease=(0.0, 0.2), flare=(0.0, 0.4))

    @property
    def name(self) -> str:
        kind = "irregular" if self.jitter > 0 else "grid"
        return f"tshirt-l{self.length:.2f}-s{self.sleeve:.2f}-n{self.vertices}-{kind}"


@dataclass(frozen=True)
class JumpsuitSpec:
    """A procedural strapless jumpsuit with loose legs, pinned at the chest line.

    Attributes:
        leg: leg length as a share of hip-to-ankle (0.3 shorts ... 1 full length).
        ease, flare: room at the side seams and extra width at the leg ends, metres.
        vertices, jitter, clearance, seed: as for :class:`TShirtSpec`.
    """

    leg: float = 0.9
    ease: float = 0.04
    flare: float = 0.05
    vertices: int = 2000
    jitter: float = 0.0
    clearance: float = 0.01
    seed: int = 0

    def __post_init__(self):
        _check(self, leg=(0.3, 1.0), ease=(0.0, 0.2), flare=(0.0, 0.3))

    @property
    def name(self) -> str:
        kind = "irregular" if self.jitter > 0 else "grid"
        return f"jumpsuit-g{self.leg:.2f}-n{self.vertices}-{kind}"


def _check(spec, **ranges: tuple[float, float]) -> None:
    for name, (low, high) in ranges.items():
        value = getattr(spec, name)
        if not low <= value <= high:
            raise ValueError(f"{type(spec).__name__}.{name} must be in [{low}, {high}], "
                             f"got {value}")
    if spec.vertices < 200:
        raise ValueError(f"a sewn garment needs at least 200 vertices, got {spec.vertices}")
    if not 0.0 <= spec.jitter <= 0.4:
        raise ValueError(f"jitter must be in [0, 0.4], got {spec.jitter}")
    if not 0.0 < spec.clearance <= 0.1:
        raise ValueError(f"clearance must be in (0, 0.1] m, got {spec.clearance}")


# ------------------------------------------------------------------- patterns

def tshirt_pattern(spec: TShirtSpec, joints: dict[str, np.ndarray],
                   torso_half_width: float, hip_half_width: float) -> Pattern:
    """The t-shirt's outline from the rest joints (x, z) and the body's widths."""
    shoulder, elbow, neck = joints["LeftArm"], joints["LeftForeArm"], joints["Neck"]
    arm = elbow - shoulder
    along = arm / np.linalg.norm(arm)
    up = np.array([-along[1], along[0]])  # the arm's upper side in the frontal plane
    if up[1] < 0:
        up = -up
    half_sleeve = 0.06 + spec.ease
    end = shoulder + spec.sleeve * arm
    side = torso_half_width + spec.ease
    # the underarm point: where the sleeve's lower edge meets the side seam
    lower_start = shoulder - half_sleeve * up
    t = (side - lower_start[0]) / along[0] if abs(along[0]) > 1e-6 else 0.0
    armpit = lower_start + min(max(t, 0.0), spec.sleeve * np.linalg.norm(arm)) * along
    armpit = np.array([side, min(armpit[1], shoulder[1] - half_sleeve)])
    hem = neck[1] - spec.length
    neck_half = 0.075
    left = [(neck_half, neck[1]), tuple(shoulder + half_sleeve * up),
            tuple(end + half_sleeve * up), tuple(end - half_sleeve * up), tuple(armpit),
            (max(side, hip_half_width + spec.ease) + spec.flare, hem), (0.0, hem)]
    # neck -> shoulder seam, sleeve top seam, sleeve end opening, sleeve bottom seam,
    # side seam, hem opening (to the centre)
    return _half_pattern(left, [False, False, True, False, False, True], top_opening=True)


def jumpsuit_pattern(spec: JumpsuitSpec, joints: dict[str, np.ndarray],
                     chest_half_width: float, hip_half_width: float) -> Pattern:
    """The jumpsuit's outline from the rest joints (x, z) and the body's widths."""
    hip, knee, ankle = joints["LeftUpLeg"], joints["LeftLeg"], joints["LeftFoot"]
    chest = joints["Spine1"][1] - 0.02
    crotch = hip[1] - 0.09
    end_z = hip[1] + spec.leg * (ankle[1] + 0.06 - hip[1])
    centre_x = np.interp(end_z, [ankle[1], knee[1], hip[1]], [ankle[0], knee[0], hip[0]])
    half_leg = np.interp(end_z, [ankle[1], hip[1]], [0.06, 0.10]) + spec.ease + spec.flare
    left = [(0.0, chest), (chest_half_width + spec.ease, chest),
            (hip_half_width + spec.ease, hip[1]), (centre_x + half_leg, end_z),
            (max(centre_x - half_leg, 0.02), end_z), (0.0, crotch)]
    # chest opening (from the centre), side seam, outer leg seam, leg opening, inseam
    return _half_pattern(left, [True, False, False, True, False], top_opening=None)


def _half_pattern(left: list, left_opening: list[bool], top_opening: bool | None) -> Pattern:
    """A pattern symmetric about x = 0 from its left half: points ``P0 .. Pm`` from the
    top down to ``Pm`` on the centre line, and whether each edge ``Pk -> Pk+1`` is an
    opening. ``P0`` lies on the centre line too when ``top_opening`` is ``None``;
    otherwise the top edge from the mirrored ``P0`` to ``P0`` (a neckline) joins the
    halves and ``top_opening`` tells whether it is an opening."""
    left = [np.asarray(point, dtype=np.float64) for point in left]
    mirrored = [point * np.array([-1.0, 1.0]) for point in left]
    last = len(left) - 1
    back = range(last - 1, 0 if top_opening is None else -1, -1)
    outline = left + [mirrored[k] for k in back]
    opening = list(left_opening) + [left_opening[k] for k in range(last - 1, -1, -1)]
    if top_opening is not None:
        opening[-1:] = [left_opening[0], top_opening]
    return Pattern(np.array(outline), np.array(opening, dtype=bool))


# ------------------------------------------------------------ triangulation

def triangulate_pattern(pattern: Pattern, vertices: int, jitter: float = 0.0,
                        seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``(P, 2)`` and triangles ``(F, 3)`` filling ``pattern`` for about
    ``vertices`` vertices over both panels, and which points lie on a seam."""
    from matplotlib.path import Path as PolygonPath
    from scipy.spatial import Delaunay

    outline = pattern.outline
    edges = np.roll(outline, -1, axis=0) - outline
    x, z = outline[:, 0], outline[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1)))
    spacing = math.sqrt(2.0 * area / vertices)
    boundary, on_seam = [], []
    for k, edge in enumerate(edges):
        steps = max(1, round(np.linalg.norm(edge) / spacing))
        t = np.arange(steps) / steps
        boundary.append(outline[k] + t[:, None] * edge)
        # an edge's first point is a corner: on a seam if either edge at it is one
        seam = np.full(steps, not pattern.opening[k])
        seam[0] = not (pattern.opening[k] and pattern.opening[k - 1])
        on_seam.append(seam)
    boundary, on_seam = np.concatenate(boundary), np.concatenate(on_seam)
    low, high = outline.min(axis=0), outline.max(axis=0)
    gx, gz = np.meshgrid(np.arange(low[0] + spacing / 2, high[0], spacing),
                         np.arange(low[1] + spacing / 2, high[1], spacing))
    inner = np.stack([gx.ravel(), gz.ravel()], axis=1)
    if jitter > 0:
        inner += np.random.default_rng(seed).uniform(-jitter, jitter, inner.shape) * spacing
    polygon = PolygonPath(outline)
    inner = inner[polygon.contains_points(inner)]
    near = _distance_to_segments(inner, outline, edges) < 0.5 * spacing
    points = np.concatenate([boundary, inner[~near]])
    triangles = Delaunay(points).simplices
    centroids = points[triangles].mean(axis=1)
    triangles = triangles[polygon.contains_points(centroids)]
    return points, triangles, np.concatenate([on_seam, np.zeros(int((~near).sum()), bool)])


def _distance_to_segments(points: np.ndarray, starts: np.ndarray, edges: np.ndarray
                          ) -> np.ndarray:
    """Distance of each point to the nearest segment ``starts + t edges``."""
    offset = points[:, None, :] - starts[None]
    t = np.clip((offset * edges[None]).sum(-1) / (edges * edges).sum(-1)[None], 0.0, 1.0)
    return np.linalg.norm(offset - t[..., None] * edges[None], axis=-1).min(axis=1)


def sew_panels(points: np.ndarray, triangles: np.ndarray, on_seam: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """One surface from a front and a back copy of a triangulated pattern: the back
    shares the front's seam vertices. Returns each point's front and back vertex
    index and the faces (the back's wound the other way, so both face outwards once
    lifted). A triangle with all three corners on seams would be its own back copy (two
    faces on the same corners): it is cut off, and a corner left without faces goes."""
    count = len(points)
    triangles = triangles[~on_seam[triangles].all(axis=1)]
    back = np.arange(count)
    own = ~on_seam
    back[own] = count + np.arange(int(own.sum()))
    faces = np.concatenate([triangles, back[triangles][:, ::-1]])
    used = np.zeros(count + int(own.sum()), dtype=bool)
    used[faces.ravel()] = True
    new_index = np.cumsum(used) - 1
    front = np.where(used[:count], new_index[:count], -1)
    back = np.where(used[back], new_index[back], -1)
    return front, back, new_index[faces]


# ------------------------------------------------------------------ lifting

def _depth_maps(body_xyz: np.ndarray) -> tuple[callable, callable]:
    """Smooth front (min y) and back (max y) depth of the body points over (x, z),
    filled outside the body from its nearest part."""
    from scipy.interpolate import RegularGridInterpolator
    from scipy.ndimage import gaussian_filter
    from scipy.spatial import cKDTree

    low = body_xyz[:, [0, 2]].min(axis=0) - 0.3
    high = body_xyz[:, [0, 2]].max(axis=0) + 0.3
    shape = np.ceil((high - low) / _DEPTH_BIN).astype(int) + 1
    cell = np.round((body_xyz[:, [0, 2]] - low) / _DEPTH_BIN).astype(int)
    front = np.full(shape, np.inf)
    back = np.full(shape, -np.inf)
    np.minimum.at(front, (cell[:, 0], cell[:, 1]), body_xyz[:, 1])
    np.maximum.at(back, (cell[:, 0], cell[:, 1]), body_xyz[:, 1])
    filled = np.isfinite(front)
    full = np.stack(np.nonzero(filled), axis=1)
    empty = np.stack(np.nonzero(~filled), axis=1)
    nearest = full[cKDTree(full).query(empty)[1]]
    for grid in (front, back):
        grid[~filled] = grid[nearest[:, 0], nearest[:, 1]]
    axes = tuple(low[k] + _DEPTH_BIN * np.arange(shape[k]) for k in range(2))
    # widen by the bins a vertex covers, then smooth: the cloth does not dip into gaps
    from scipy.ndimage import maximum_filter, minimum_filter

    front = gaussian_filter(minimum_filter(front, size=5), 2.0)
    back = gaussian_filter(maximum_filter(back, size=5), 2.0)
    return (RegularGridInterpolator(axes, front, bounds_error=False, fill_value=None),
            RegularGridInterpolator(axes, back, bounds_error=False, fill_value=None))


def lift_panels(points: np.ndarray, front_index: np.ndarray, back_index: np.ndarray,
                faces: np.ndarray, pattern: Pattern, body_xyz: np.ndarray,
                clearance: float) -> Mesh:
    """The sewn panels (:func:`sew_panels`; index -1: not used) wrapped around the body
    points (see the module docstring)."""
    front_depth, back_depth = _depth_maps(body_xyz)
    outline = pattern.outline
    edges = np.roll(outline, -1, axis=0) - outline
    seams = ~pattern.opening
    distance = _distance_to_segments(points, outline[seams], edges[seams])
    u = np.minimum(distance / _TAPER_RADIUS, 1.0)
    taper = np.sqrt(1.0 - (1.0 - u) ** 2)
    y_front = front_depth(points) - clearance
    y_back = back_depth(points) + clearance
    middle = 0.5 * (y_front + y_back)
    vertices = np.zeros((int(faces.max()) + 1, 3))
    for index, depth in ((front_index, y_front), (back_index, y_back)):
        used = index >= 0
        lifted = np.stack([points[:, 0], middle + (depth - middle) * taper, points[:, 1]], 1)
        vertices[index[used]] = lifted[used]
    return as_mesh(vertices, faces)


def push_out(mesh: Mesh, body_vertices: np.ndarray, body_faces: np.ndarray,
             clearance: float) -> Mesh:
    """``mesh`` with every vertex nearer the body than ``clearance`` (or inside it)
    moved out along the body's outward normal to ``clearance``."""
    from swingar_pyg.collision.reference import BodySurface

    surface = BodySurface(body_vertices, body_faces)
    depth, normal = surface.signed_distance(mesh.vertices)  # positive inside
    move = np.maximum(depth + clearance, 0.0)
    return as_mesh(mesh.vertices + move[:, None] * normal, mesh.faces)


# ------------------------------------------------------------------ fitting

_ARM_AND_HEAD = ("ForeArm", "Hand", "Thumb", "Finger", "Neck1", "Head")
_ARMS_AND_HEAD = ("Shoulder", "Arm", "Hand", "Thumb", "Finger", "Neck", "Head")


def fit_sewn_garment(spec: TShirtSpec | JumpsuitSpec, body: "BodyModel", shape) -> "Garment":
    """A t-shirt or jumpsuit cut for ``body`` with ``shape`` and dressed on its rest pose."""
    import torch

    from swingar_pyg.world.garment import garment_on_body

    rest = body.rest_vertices(shape).numpy().astype(np.float64)
    faces = body.faces.numpy()
    count = len(body.joint_names)
    posed = body.pose(shape, torch.eye(3).expand(1, count, 3, 3), torch.zeros(1, 3))
    joints = {name: position[[0, 2]].numpy().astype(np.float64)
              for name, position in zip(body.joint_names, posed.joint_positions[0])}
    indices, weights = body.skinning()
    dominant = indices.numpy()[np.arange(len(rest)), weights.numpy().argmax(axis=1)]
    words = _ARM_AND_HEAD if isinstance(spec, TShirtSpec) else _ARMS_AND_HEAD
    left_out = [j for j, name in enumerate(body.joint_names) if any(w in name for w in words)]
    kept = rest[~np.isin(dominant, left_out)]
    no_arms = [j for j, name in enumerate(body.joint_names)
               if any(w in name for w in _ARMS_AND_HEAD)]
    torso = rest[~np.isin(dominant, no_arms)]

    def half_width(z: float) -> float:
        band = torso[np.abs(torso[:, 2] - z) < 0.03]
        return float(np.abs(band[:, 0]).max())

    hips = joints["LeftUpLeg"][1]
    if isinstance(spec, TShirtSpec):
        chest = joints["Spine1"][1]
        pattern = tshirt_pattern(spec, joints, half_width(chest), half_width(hips - 0.05))
    else:
        pattern = jumpsuit_pattern(spec, joints, half_width(joints["Spine1"][1] - 0.02),
                                   half_width(hips - 0.05))
    points, triangles, on_seam = triangulate_pattern(pattern, spec.vertices, spec.jitter,
                                                     spec.seed)
    front_index, back_index, sewn = sew_panels(points, triangles, on_seam)
    mesh = lift_panels(points, front_index, back_index, sewn, pattern, kept, spec.clearance)
    mesh = _facing_out(mesh)
    mesh = push_out(mesh, rest, faces, spec.clearance)
    return garment_on_body(spec.name, mesh, body, shape)


def _facing_out(mesh: Mesh) -> Mesh:
    """The mesh with its faces wound so that the front panel's normals point to -y."""
    v, f = mesh.vertices, mesh.faces
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    centre = v.mean(axis=0)
    outward = np.einsum("ij,ij->i", normals, v[f].mean(axis=1) - centre)
    return mesh if np.median(np.sign(outward)) >= 0 else as_mesh(v, f[:, ::-1])
