"""Procedural skirts and dresses of any length, flare, resolution and
triangulation, fitted on a body in its rest pose: rings around the body's
envelope below the waist, pinned at the waistband (and at the straps of a dress).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from swingar_pyg.geometry.mesh import as_mesh
from swingar_pyg.geometry.primitives import split_quads
from swingar_pyg.geometry.signed_distance import closest_face_signed_distance
from swingar_pyg.world.body import BodyModel
from swingar_pyg.world.garment import (
    ARM_BONE_WORDS,
    Garment,
    check_jitter,
    dominant_joints,
    joints_named,
    topology_tag,
    transfer_skinning,
)


@dataclass(frozen=True)
class SkirtSpec:
    """A procedural skirt.

    Attributes:
        length: waist to hem, metres (0.3 mini ... 1.0 floor-length).
        flare: how far the hem stands out, as the sine of the cone's half-angle
            (0 straight, 0.3 A-line, 0.7 circle-like); never inside the body.
        vertices: about how many vertices.
        jitter: 0 for a regular quad-grid triangulation; up to 0.4 moves vertices
            within their cells and flips diagonals (irregular topology).
        waist_height: waist above the root joint (the hips), metres.
        clearance: gap kept between body and skirt at rest, metres.
        seed: for the jitter.
        slit: height of a vent up from the hem at the back, metres (0 for none):
            the column of cells at the back (``+y``) is left open below it, as a
            narrow long skirt needs to let the legs take a stride.
    """

    length: float = 0.55
    flare: float = 0.35
    vertices: int = 1500
    jitter: float = 0.0
    waist_height: float = 0.08
    clearance: float = 0.015
    seed: int = 0
    slit: float = 0.0

    def __post_init__(self):
        if not 0.1 <= self.length <= 1.5:
            raise ValueError(f"skirt length must be in [0.1, 1.5] m, got {self.length}")
        if not 0.0 <= self.flare < 1.0:
            raise ValueError(f"flare must be in [0, 1), got {self.flare}")
        if self.vertices < 64:
            raise ValueError(f"a skirt needs at least 64 vertices, got {self.vertices}")
        check_jitter(self.jitter)
        if not 0.0 <= self.slit < self.length:
            raise ValueError(f"slit must be in [0, length = {self.length}) m, got {self.slit}")

    @property
    def name(self) -> str:
        slit = f"-s{self.slit:.2f}" if self.slit else ""
        return (f"{self.family}-l{self.length:.2f}-f{self.flare:.2f}-n{self.vertices}-"
                f"{topology_tag(self.jitter)}{slit}")

    @property
    def family(self) -> str:
        return "skirt"


@dataclass(frozen=True)
class DressSpec(SkirtSpec):
    """A procedural strapless dress: a skirt that starts under the arms.

    Its top ring, pinned to the torso, sits ``waist_height`` above the hips (the
    chest); below, it follows the torso's envelope and never narrows below its
    widest point, so it hangs from the bust as a shift dress and flares from
    the hips.
    """

    length: float = 0.95
    flare: float = 0.25
    waist_height: float = 0.30

    @property
    def family(self) -> str:
        return "dress"


def body_envelope(vertices: np.ndarray, keep: np.ndarray, heights: np.ndarray,
                  angles: np.ndarray, band: float = 0.03) -> np.ndarray:
    r"""Distance from the vertical axis through the kept body vertices' centroid
    :math:`\mathbf{c}` to the convex hull of the body's cross-section, per height
    and angle: ``(len(heights), len(angles))``.

    The cross-section at height :math:`z` is the kept vertices within ``band`` of
    :math:`z`, projected on the horizontal plane. Its convex hull is the half-planes
    :math:`\mathbf{a}_k^\top \mathbf{q} + b_k \le 0` (unit :math:`\mathbf{a}_k`), and
    the envelope along :math:`\mathbf{u} = (\cos\theta, \sin\theta)` is where the
    ray :math:`\mathbf{c} + t\,\mathbf{u}` leaves it:

    .. math::
        r(\theta) = \min_{k:\ \mathbf{a}_k^\top \mathbf{u} > 0}
        \frac{-(\mathbf{a}_k^\top \mathbf{c} + b_k)}{\mathbf{a}_k^\top \mathbf{u}}.

    A skirt wraps that hull: it bridges the hollow between the breasts and the gap
    between the legs instead of following them, and however sparse the body's
    vertices, the envelope has no holes. Where the hull does not exist (fewer than
    three vertices, or all on a line) or does not contain the axis, the envelope is
    the largest distance of those vertices from the axis (0 where there are none).
    """
    points = vertices[keep]
    centre = points[:, :2].mean(axis=0)
    direction = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    envelope = np.zeros((len(heights), len(angles)))
    for k, z in enumerate(heights):
        section = points[np.abs(points[:, 2] - z) < band, :2]
        if not len(section):
            continue
        fallback = np.linalg.norm(section - centre, axis=1).max()
        try:
            hull = ConvexHull(section)
        except QhullError:
            envelope[k] = fallback
            continue
        normal, offset = hull.equations[:, :2], hull.equations[:, 2]
        depth = -(normal @ centre + offset)  # > 0 for every facet iff the axis is inside
        if (depth <= 0).any():
            envelope[k] = fallback
            continue
        facing = direction @ normal.T  # (angles, facets)
        reach = np.where(facing > 0, depth / np.where(facing > 0, facing, 1.0), np.inf)
        envelope[k] = reach.min(axis=1)
    return envelope


def procedural_skirt(spec: SkirtSpec, body_vertices: np.ndarray, body_faces: np.ndarray,
                     joint_names: tuple[str, ...], skin_indices: np.ndarray,
                     skin_weights: np.ndarray) -> Garment:
    r"""Fits ``spec`` around a body (rest-pose ``body_vertices`` and ``body_faces``).

    Rings run from the waist (pinned) to the hem; at each ring and angle the radius
    is the larger of the flared profile and the body's envelope
    (:func:`body_envelope`, the convex hull of its cross-section) plus clearance.
    A slit leaves out the column of cells at the back (centred nearest
    :math:`\theta = \pi / 2`; the body faces :math:`-y`) in the rows whose top ring
    lies below ``hem + slit``: a vent one cell (a few centimetres) wide, open at rest.
    """
    body_vertices = np.asarray(body_vertices, dtype=np.float64)
    keep = ~np.isin(dominant_joints(skin_indices, skin_weights),
                    joints_named(joint_names, ARM_BONE_WORDS))

    circumference_guess = 2 * math.pi * 0.2
    segments = max(8, round(math.sqrt(spec.vertices * circumference_guess / spec.length)))
    rings = max(3, round(spec.vertices / segments))
    angles = -math.pi + 2 * math.pi * np.arange(segments) / segments
    heights = spec.waist_height - spec.length * np.linspace(0.0, 1.0, rings)
    envelope = body_envelope(body_vertices, keep, heights, angles) + spec.clearance
    waist = envelope[0]
    drop = spec.waist_height - heights
    flared = waist[None, :] + drop[:, None] * math.tan(math.asin(spec.flare))
    # A skirt hangs from the hips: it never narrows below its widest point above.
    radius = np.maximum(flared, np.maximum.accumulate(envelope, axis=0))

    centre = body_vertices[keep, :2].mean(axis=0)
    u = np.arange(segments)[None, :].repeat(rings, 0).astype(np.float64)
    v = np.arange(rings)[:, None].repeat(segments, 1).astype(np.float64)
    if spec.jitter > 0:
        rng = np.random.default_rng(spec.seed)
        interior = v[:, 0] > 0
        u[interior] += rng.uniform(-spec.jitter, spec.jitter, size=u[interior].shape)
        v[interior & (np.arange(rings) < rings - 1)] += rng.uniform(
            -spec.jitter, spec.jitter, size=v[interior & (np.arange(rings) < rings - 1)].shape)
    theta = -math.pi + 2 * math.pi * u / segments
    ring_position = np.clip(v, 0, rings - 1)
    radius_at = _interpolate_rings(radius, ring_position, u)
    z = spec.waist_height - spec.length * ring_position / (rings - 1)
    vertices = np.stack([centre[0] + radius_at * np.cos(theta),
                         centre[1] + radius_at * np.sin(theta), z], axis=-1).reshape(-1, 3)

    index = np.arange(rings * segments).reshape(rings, segments)
    corners = (index[:-1], np.roll(index[:-1], -1, axis=1), np.roll(index[1:], -1, axis=1),
               index[1:])
    flip = np.zeros(corners[0].shape, dtype=bool)
    if spec.jitter > 0:
        flip = np.random.default_rng(spec.seed + 1).random(flip.shape) < 0.5
    closed = np.ones(corners[0].shape, dtype=bool)
    back = round(0.75 * segments - 0.5) % segments  # the cell from angles[back] onwards
    closed[heights[:-1] < heights[-1] + spec.slit - 1e-9, back] = False
    # Outward normals: the ring order runs counter-clockwise seen from above and
    # rows run downwards, so (a, b, c) faces inward; reverse to face outward.
    quads = tuple(corner[closed] for corner in corners)
    mesh = as_mesh(vertices, split_quads(*quads, flip[closed])[:, ::-1])

    indices, weights = transfer_skinning(mesh, index[0], body_vertices, joint_names,
                                         skin_indices, skin_weights)
    pinned = index[0].copy()
    fit = -closest_face_signed_distance(mesh.vertices, body_vertices, body_faces)
    return Garment(spec.name, mesh, pinned, indices, weights, fit)


def fit_procedural_skirt(spec: SkirtSpec, body: BodyModel, shape) -> Garment:
    """:func:`procedural_skirt` fitted on ``body`` with ``shape``, in its rest pose."""
    indices, weights = body.skinning()
    return procedural_skirt(spec, body.rest_vertices(shape).numpy(), body.faces.numpy(),
                            body.joint_names, indices.numpy(), weights.numpy())


def _interpolate_rings(radius: np.ndarray, ring_position: np.ndarray,
                       segment_position: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of the ``(rings, segments)`` radius table, periodic
    in the segment direction."""
    rings, segments = radius.shape
    r0 = np.clip(np.floor(ring_position).astype(int), 0, rings - 1)
    r1 = np.clip(r0 + 1, 0, rings - 1)
    s0 = np.floor(segment_position).astype(int) % segments
    s1 = (s0 + 1) % segments
    fr = ring_position - np.floor(ring_position)
    fs = segment_position - np.floor(segment_position)
    top = radius[r0, s0] * (1 - fs) + radius[r0, s1] * fs
    bottom = radius[r1, s0] * (1 - fs) + radius[r1, s1] * fs
    return top * (1 - fr) + bottom * fr
