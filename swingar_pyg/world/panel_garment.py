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
outward normal (:class:`~swingar_pyg.geometry.signed_distance.BodySurface`). Pinning,
skinning and the fit attribute are those of
:func:`~swingar_pyg.world.garment.garment_on_body`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RegularGridInterpolator
from scipy.ndimage import gaussian_filter, maximum_filter, minimum_filter
from scipy.spatial import Delaunay, cKDTree

from swingar_pyg.geometry.mesh import Mesh, as_mesh
from swingar_pyg.geometry.signed_distance import push_out
from swingar_pyg.world.body import BodyModel, rest_pose
from swingar_pyg.world.garment import (
    ARM_BONE_WORDS,
    Garment,
    check_jitter,
    dominant_joints,
    garment_on_body,
    joints_named,
    topology_tag,
)

_TAPER_RADIUS = 0.06
_DEPTH_BIN = 0.01


@dataclass(frozen=True)
class Pattern:
    """A closed polygon ``(K, 2)`` in the frontal plane (x, z), and whether each
    edge ``k -> k + 1`` (the last back to the first) is an opening (else a seam)."""

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
        return (f"tshirt-l{self.length:.2f}-s{self.sleeve:.2f}-n{self.vertices}-"
                f"{topology_tag(self.jitter)}")


@dataclass(frozen=True)
class JumpsuitSpec:
    """A procedural strapless jumpsuit with loose legs, pinned at the chest line.

    Attributes:
        leg: leg length as a share of hip-to-ankle (0.3 shorts ... 1 full length).
        ease, flare: room at the side seams and extra width at the leg ends, metres.
        crotch_drop: how far below the hip joints the inseams meet, metres. anny's
            crotch is 9-11 cm below them; a deeper crotch leaves the cloth between the
            legs room to follow a stride (``benchmarks/bench_fit.py`` measures it).
        vertices, jitter, clearance, seed: as for :class:`TShirtSpec`.
    """

    leg: float = 0.9
    ease: float = 0.04
    flare: float = 0.05
    crotch_drop: float = 0.09
    vertices: int = 2000
    jitter: float = 0.0
    clearance: float = 0.01
    seed: int = 0

    def __post_init__(self):
        _check(self, leg=(0.3, 1.0), ease=(0.0, 0.2), flare=(0.0, 0.3),
               crotch_drop=(0.05, 0.25))

    @property
    def name(self) -> str:
        """Leg length, vertices and topology; the cut too where it is not the default."""
        fields = ("ease", "flare", "clearance", "crotch_drop")
        cut = tuple(getattr(self, f) for f in fields)
        default = tuple(getattr(JumpsuitSpec, f) for f in fields)
        suffix = "" if cut == default else "-e{:.2f}-f{:.2f}-c{:.2f}-d{:.2f}".format(*cut)
        return f"jumpsuit-g{self.leg:.2f}-n{self.vertices}-{topology_tag(self.jitter)}{suffix}"


def _check(spec, **ranges: tuple[float, float]) -> None:
    for name, (low, high) in ranges.items():
        value = getattr(spec, name)
        if not low <= value <= high:
            raise ValueError(f"{type(spec).__name__}.{name} must be in [{low}, {high}], "
                             f"got {value}")
    if spec.vertices < 200:
        raise ValueError(f"a sewn garment needs at least 200 vertices, got {spec.vertices}")
    check_jitter(spec.jitter)
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
    length = np.linalg.norm(arm)
    side = torso_half_width + spec.ease
    # the sleeve's seams run along the upper arm, above and below its axis; the lower
    # one starts at the armpit, where it meets the side seam
    top = shoulder + (0.2 * length + spec.ease) * up
    lower_start = shoulder - (0.15 * length + spec.ease) * up
    armpit = lower_start + (side - lower_start[0]) / max(along[0], 0.1) * along
    armpit[0] = side
    reach = spec.sleeve * length * along
    hem = neck[1] - spec.length
    left = [(0.45 * shoulder[0], neck[1]), tuple(top), tuple(top + reach),
            tuple(armpit + reach), tuple(armpit),
            (max(side, hip_half_width + spec.ease) + spec.flare, hem), (0.0, hem)]
    # neck -> shoulder seam, sleeve top seam, sleeve end opening, sleeve bottom seam,
    # side seam, hem opening (to the centre)
    return _half_pattern(left, [False, False, True, False, False, True], neckline=True)


def jumpsuit_pattern(spec: JumpsuitSpec, joints: dict[str, np.ndarray],
                     chest_half_width: float, hip_half_width: float) -> Pattern:
    """The jumpsuit's outline from the rest joints (x, z) and the body's widths."""
    hip, knee, ankle = joints["LeftUpLeg"], joints["LeftLeg"], joints["LeftFoot"]
    chest = joints["Spine1"][1] - 0.02
    crotch = hip[1] - spec.crotch_drop
    end_z = hip[1] + spec.leg * (ankle[1] + 0.06 - hip[1])
    if crotch < end_z + 0.05:
        raise ValueError(f"crotch_drop {spec.crotch_drop} m leaves no leg: the legs end "
                         f"{hip[1] - end_z:.2f} m below the hip joints (lengthen the legs or "
                         f"raise the crotch)")
    centre_x = np.interp(end_z, [ankle[1], knee[1], hip[1]], [ankle[0], knee[0], hip[0]])
    half_leg = np.interp(end_z, [ankle[1], hip[1]], [0.06, 0.10]) + spec.ease + spec.flare
    left = [(0.0, chest), (chest_half_width + spec.ease, chest),
            (hip_half_width + spec.ease, hip[1]), (centre_x + half_leg, end_z),
            (max(centre_x - half_leg, 0.02), end_z), (0.0, crotch)]
    # chest opening (from the centre), side seam, outer leg seam, leg opening, inseam
    return _half_pattern(left, [True, False, False, True, False], neckline=False)


def _half_pattern(left: list, left_opening: list[bool], neckline: bool) -> Pattern:
    """A pattern symmetric about x = 0 from its left half: points ``P0 .. Pm`` from the
    top down to ``Pm`` on the centre line, and whether each edge ``Pk -> Pk+1`` is an
    opening. With a ``neckline``, ``P0`` lies off the centre line and an opening joins
    it to its mirror image; without, ``P0`` lies on the centre line."""
    left = [np.asarray(point, dtype=np.float64) for point in left]
    mirrored = [point * np.array([-1.0, 1.0]) for point in left]
    last = len(left) - 1
    outline = left + [mirrored[k] for k in range(last - 1, -1 if neckline else 0, -1)]
    opening = list(left_opening) + [left_opening[k] for k in range(last - 1, -1, -1)]
    if neckline:
        opening.append(True)
    return Pattern(np.array(outline), np.array(opening, dtype=bool))


# ------------------------------------------------------------ triangulation

@dataclass(frozen=True)
class PatternMesh:
    """A triangulated pattern: ``points`` ``(P, 2)``, ``triangles`` ``(F, 3)``, and for
    each point the outline edge it lies on (``edge``; -1 inside) and whether it is
    on a seam (``on_seam``; corners between a seam and an opening are)."""

    points: np.ndarray
    triangles: np.ndarray
    edge: np.ndarray
    on_seam: np.ndarray


def triangulate_pattern(pattern: Pattern, vertices: int, jitter: float = 0.0,
                        seed: int = 0) -> PatternMesh:
    """Fills ``pattern`` with triangles for about ``vertices`` vertices over both panels.

    No edge inside the pattern may join two seam points (its front and back copies
    would be one edge of four triangles): such chords get a point at their middle
    and the triangulation is redone.

    Raises:
        ValueError: if the outline crosses itself.
    """
    from matplotlib.path import Path as PolygonPath
    outline = pattern.outline
    edges = np.roll(outline, -1, axis=0) - outline
    if _crosses_itself(outline):
        raise ValueError("the garment pattern's outline crosses itself: the garment does not "
                         "fit this body's proportions (try other lengths or ease)")
    x, z = outline[:, 0], outline[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1)))
    spacing = math.sqrt(2.0 * area / vertices)
    # Points along an edge sit a hair inside it while triangulating: on a straight run
    # Delaunay would otherwise leave flat triangles and chords along the outline.
    clockwise = np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1)) < 0
    inward = np.stack([-edges[:, 1], edges[:, 0]], axis=1) * (-1.0 if clockwise else 1.0)
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    boundary, edge_of, on_seam, nudge = [], [], [], []
    for k, edge in enumerate(edges):
        # an opening keeps at least one point of its own, or front and back would close it
        steps = max(2 if pattern.opening[k] else 1, round(np.linalg.norm(edge) / spacing))
        t = np.arange(steps) / steps
        boundary.append(outline[k] + t[:, None] * edge)
        nudge.append(np.where(t[:, None] > 0, 0.02 * spacing * inward[k], 0.0))
        edge_of.append(np.full(steps, k))
        seam = np.full(steps, not pattern.opening[k])
        seam[0] = not (pattern.opening[k] and pattern.opening[k - 1])  # a corner
        on_seam.append(seam)
    boundary, edge_of, on_seam, nudge = map(np.concatenate, (boundary, edge_of, on_seam, nudge))
    low, high = outline.min(axis=0), outline.max(axis=0)
    gx, gz = np.meshgrid(np.arange(low[0] + spacing / 2, high[0], spacing),
                         np.arange(low[1] + spacing / 2, high[1], spacing))
    inner = np.stack([gx.ravel(), gz.ravel()], axis=1)
    if jitter > 0:
        inner += np.random.default_rng(seed).uniform(-jitter, jitter, inner.shape) * spacing
    polygon = PolygonPath(outline)
    inner = inner[polygon.contains_points(inner)]
    inner = inner[_distance_to_segments(inner, outline, edges) >= 0.5 * spacing]
    count = len(boundary)

    def along_outline(a, b):
        return (a < count) & (b < count) & ((np.abs(b - a) == 1) | (np.abs(b - a) == count - 1))

    nudged = PolygonPath(boundary + nudge)
    for _ in range(8):
        points = np.concatenate([boundary + nudge, inner])
        triangles = Delaunay(points).simplices
        # inside: the centroid and the middle of every edge not on the outline (an edge
        # across a gap narrower than the spacing, under an arm or between the legs, is not)
        keep = nudged.contains_points(points[triangles].mean(axis=1))
        for i, j in ((0, 1), (1, 2), (2, 0)):
            a, b = triangles[:, i], triangles[:, j]
            middle = nudged.contains_points(0.5 * (points[a] + points[b]))
            keep &= middle | along_outline(a, b)
        triangles = triangles[keep]
        pairs = np.unique(np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                                  triangles[:, [2, 0]]]), axis=1), axis=0)
        a, b = pairs[:, 0], pairs[:, 1]
        seam_pair = (b < count) & on_seam[np.minimum(a, count - 1)] & \
            on_seam[np.minimum(b, count - 1)]
        chords = pairs[seam_pair & ~along_outline(a, b)]
        if not len(chords):
            break
        inner = np.concatenate([inner, points[chords].mean(axis=1)])
    else:
        raise ValueError("could not triangulate the garment pattern without chords between "
                         "seams (is it narrower than the vertex spacing somewhere?)")
    _check_filled(triangles, count)
    points[:count] = boundary
    return PatternMesh(points, triangles, np.concatenate([edge_of, np.full(len(inner), -1)]),
                       np.concatenate([on_seam, np.zeros(len(inner), bool)]))


def _check_filled(triangles: np.ndarray, count: int) -> None:
    """Every outline edge (between consecutive points of the first ``count``) lies on
    one triangle and every other edge on two: the pattern is filled without holes."""
    pairs = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    pairs, uses = np.unique(pairs, axis=0, return_counts=True)
    a, b = pairs[:, 0], pairs[:, 1]
    outline = (b < count) & ((b - a == 1) | (b - a == count - 1))
    if outline.sum() != count or (uses[outline] != 1).any() or (uses[~outline] != 2).any():
        raise ValueError("the garment pattern could not be filled without holes (is it "
                         "narrower than the vertex spacing somewhere? ask for more vertices)")


def _crosses_itself(outline: np.ndarray) -> bool:
    """Whether two non-adjacent edges of the closed polygon intersect."""
    count = len(outline)
    start, end = outline, np.roll(outline, -1, axis=0)

    def side(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                       - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    for i in range(count):
        for j in range(i + 2, count):
            if i == 0 and j == count - 1:
                continue
            if (side(start[i], end[i], start[j]) * side(start[i], end[i], end[j]) < 0
                    and side(start[j], end[j], start[i]) * side(start[j], end[j], end[i]) < 0):
                return True
    return False


def _distance_to_segments(points: np.ndarray, starts: np.ndarray, edges: np.ndarray
                          ) -> np.ndarray:
    """Distance of each point to the nearest segment ``starts + t edges``."""
    offset = points[:, None, :] - starts[None]
    t = np.clip((offset * edges[None]).sum(-1) / (edges * edges).sum(-1)[None], 0.0, 1.0)
    return np.linalg.norm(offset - t[..., None] * edges[None], axis=-1).min(axis=1)


def sew_panels(points: np.ndarray, triangles: np.ndarray, on_seam: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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

def _depth_maps(body_xyz: np.ndarray) -> tuple[Callable, Callable]:
    """Smooth front (min y) and back (max y) depth of the body points over (x, z),
    filled outside the body from its nearest part."""
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


# ------------------------------------------------------------------ fitting

# the body parts a garment's depth ignores: a t-shirt's covers the upper arms
_FOREARMS_AND_HEAD = ("ForeArm", "Hand", "Thumb", "Finger", "Neck1", "Head")


def fit_sewn_garment(spec: TShirtSpec | JumpsuitSpec, body: BodyModel, shape) -> Garment:
    """A t-shirt or jumpsuit cut for ``body`` with ``shape`` and dressed on its rest pose."""
    posed = rest_pose(body, shape)
    rest = posed.vertices[0].numpy().astype(np.float64)
    faces = body.faces.numpy()
    joints = {name: position[[0, 2]].numpy().astype(np.float64)
              for name, position in zip(body.joint_names, posed.joint_positions[0])}
    indices, weights = body.skinning()
    dominant = dominant_joints(indices.numpy(), weights.numpy())
    arms_and_head = ARM_BONE_WORDS + ("Neck", "Head")
    words = _FOREARMS_AND_HEAD if isinstance(spec, TShirtSpec) else arms_and_head
    kept = rest[~np.isin(dominant, joints_named(body.joint_names, words))]
    torso = rest[~np.isin(dominant, joints_named(body.joint_names, arms_and_head))]

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
    cut = triangulate_pattern(pattern, spec.vertices, spec.jitter, spec.seed)
    front_index, back_index, sewn = sew_panels(cut.points, cut.triangles, cut.on_seam)
    mesh = lift_panels(cut.points, front_index, back_index, sewn, pattern, kept,
                       spec.clearance)
    mesh = push_out(_facing_out(mesh), rest, faces, spec.clearance)
    # pinned: the highest openings (the neckline, both halves of the chest line) with
    # their end corners, on both panels
    openings = np.flatnonzero(pattern.opening)
    height = 0.5 * (pattern.outline[openings, 1] +
                    np.roll(pattern.outline, -1, axis=0)[openings, 1])
    top = openings[height > height.max() - 0.01]
    ends = [np.flatnonzero(cut.edge == (k + 1) % len(pattern.outline))[0] for k in top]
    on_top = np.concatenate([np.flatnonzero(np.isin(cut.edge, top)), ends])
    pinned = np.unique(np.concatenate([front_index[on_top], back_index[on_top]]))
    return garment_on_body(spec.name, mesh, body, shape, pinned=pinned[pinned >= 0])


def _facing_out(mesh: Mesh) -> Mesh:
    """The mesh with its faces wound so that the front panel's normals point to -y."""
    v, f = mesh.vertices, mesh.faces
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    centre = v.mean(axis=0)
    outward = np.einsum("ij,ij->i", normals, v[f].mean(axis=1) - centre)
    return mesh if np.median(np.sign(outward)) >= 0 else as_mesh(v, f[:, ::-1])
