"""A garment fitted on a body in its rest pose, and what every garment family shares:
the pinned bands that ride on the torso, skinning carried over from the body, and
dressing any mesh (a file, a shipped garment) on a body
(:func:`garment_on_body`). Procedural skirts and dresses: :mod:`~swingar_pyg.world.skirt`;
sewn t-shirts and jumpsuits: :mod:`~swingar_pyg.world.panel_garment`; a dataset's
garment entries: :mod:`~swingar_pyg.world.catalogue`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from swingar_pyg.geometry.mesh import Mesh, as_mesh, boundary_edges, mesh_edges
from swingar_pyg.geometry.signed_distance import closest_face_signed_distance, push_out
from swingar_pyg.geometry.weld import weld_mesh
from swingar_pyg.sim import XPBDSettings
from swingar_pyg.world.body import BodyModel

DRESSING_CLEARANCE = XPBDSettings.thickness + 0.002
"""The least gap (m) a dressed garment keeps from the body at rest: over the simulator's
contact thickness, so that no tight ring (a cuff, a waistband) starts inside the contact
layer and is stretched open by it (a trousers cuff 1 mm inside the ankle started 15 %
stretched at rest)."""

# Bones whose vertices do not bound a skirt: in the rest A-pose the hands hang beside
# the hips, but a skirt goes around the pelvis and legs, not around the arms.
ARM_BONE_WORDS = ("Shoulder", "Arm", "Hand", "Thumb", "Finger")

# Pins (waistband, neckline) ride on the torso: they follow its joints only, or the
# thighs would drag a waistband out of shape in a stride (measured: 37 % strain running).
_LIMB_WORDS = ("Leg", "Foot", "Toe", "HipJoint") + ARM_BONE_WORDS


def topology_tag(jitter: float) -> str:
    """``"irregular"`` for a jittered triangulation, ``"grid"`` for a regular one."""
    return "irregular" if jitter > 0 else "grid"


def check_jitter(jitter: float) -> None:
    """Raises ``ValueError`` unless a procedural garment's jitter lies in [0, 0.4]."""
    if not 0.0 <= jitter <= 0.4:
        raise ValueError(f"jitter must be in [0, 0.4], got {jitter}")


def dominant_joints(skin_indices: np.ndarray, skin_weights: np.ndarray) -> np.ndarray:
    """Each vertex's most weighted joint."""
    return skin_indices[np.arange(len(skin_indices)), np.argmax(skin_weights, axis=1)]


def joints_named(joint_names: tuple[str, ...], words: tuple[str, ...]) -> list[int]:
    """The joints whose name contains any of ``words``."""
    return [j for j, name in enumerate(joint_names) if any(w in name for w in words)]


@dataclass(frozen=True)
class Garment:
    """A garment fitted on a body's rest pose.

    Attributes:
        name: what it is, e.g. ``"skirt-l0.55-f0.40-n1500-irregular"``.
        mesh: rest vertices (metres, +Z up) and triangles.
        pinned: indices of the vertices attached to the body (waist, shoulders).
        skin_indices, skin_weights: ``(N, K)`` body joints each vertex follows in
            rigid skinning: those of the nearest body vertex, but for the pinned
            bands, each of which follows the torso's joints as one
            (:func:`transfer_skinning`).
        fit: ``(N,)`` the fit attribute: clearance (m) from the body surface in the
            rest pose, positive outside: minus the body's signed distance
            (:func:`~swingar_pyg.geometry.closest_face_signed_distance`).
    """

    name: str
    mesh: Mesh
    pinned: np.ndarray
    skin_indices: np.ndarray
    skin_weights: np.ndarray
    fit: np.ndarray


def transfer_skinning(mesh: Mesh, pinned: np.ndarray, body_vertices: np.ndarray,
                      joint_names: tuple[str, ...], skin_indices: np.ndarray,
                      skin_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Skinning of garment vertices: the nearest body vertex's, except for the pinned
    vertices. Those keep only the torso's joints (renormalised; the root if none), and
    each band of them (pins joined by mesh edges: a waistband, a neckline, a strap's
    end) moves as one, with its vertices' mean weights: the body's own skin stretches
    under linear blend skinning where its weights change fast around the body (anny's
    chest by 52 % in a twist), and a band that followed it point by point would be
    stretched as much (a dress's top edge by 40 %, measured), which no cloth does."""
    nearest = cKDTree(body_vertices).query(mesh.vertices)[1]
    indices, weights = skin_indices[nearest].copy(), skin_weights[nearest].astype(np.float64)
    dense = np.zeros((len(pinned), len(joint_names)))
    np.add.at(dense, (np.arange(len(pinned))[:, None], indices[pinned]), weights[pinned])
    dense[:, joints_named(joint_names, _LIMB_WORDS)] = 0.0  # the torso's joints only
    dense[dense.sum(axis=1) == 0, 0] = 1.0
    for band in pin_bands(mesh, pinned):
        mean = dense[band].mean(axis=0)
        chosen = np.argsort(-mean, kind="stable")[:indices.shape[1]]
        indices[pinned[band]] = chosen
        weights[pinned[band]] = mean[chosen] / mean[chosen].sum()
    return indices, weights


def pin_bands(mesh: Mesh, pinned: np.ndarray) -> list[np.ndarray]:
    """The pinned vertices in bands: positions in ``pinned`` of each connected piece of
    the graph of mesh edges with both ends pinned (a pin on its own is a band)."""
    return _connected_pieces(mesh_edges(mesh.faces), pinned, mesh.num_vertices)


def _connected_pieces(edges: np.ndarray, vertices: np.ndarray,
                      num_vertices: int) -> list[np.ndarray]:
    """Positions in ``vertices`` of each connected piece of the graph they form with
    those ``edges`` whose ends both lie among them."""
    if not len(vertices):
        return []
    position = np.full(num_vertices, -1)
    position[vertices] = np.arange(len(vertices))
    ends = position[edges]
    ends = ends[(ends >= 0).all(axis=1)]
    graph = coo_matrix((np.ones(len(ends)), (ends[:, 0], ends[:, 1])),
                       shape=(len(vertices), len(vertices)))
    _, label = connected_components(graph, directed=False)
    return [np.flatnonzero(label == k) for k in range(label.max() + 1)]


def top_boundary_loops(mesh: Mesh, band: float = 0.1) -> np.ndarray:
    """Vertices of the mesh's boundary loops whose mean height lies within ``band``
    of the highest one's: a waistband, a neckline, or the top edge of a bib and
    the ends of its straps."""
    boundary = boundary_edges(mesh.faces)
    if not len(boundary):
        raise ValueError("the garment has no boundary to attach to the body")
    on_boundary = np.unique(boundary)
    loops = [on_boundary[piece]
             for piece in _connected_pieces(boundary, on_boundary, mesh.num_vertices)]
    heights = [mesh.vertices[loop, 2].mean() for loop in loops]
    top = max(heights)
    return np.sort(np.concatenate([loop for loop, z in zip(loops, heights) if z >= top - band]))


def refuse_undressed(name: str, mesh: Mesh, rest: np.ndarray) -> None:
    """Raises a ``ValueError`` naming the likely cause when ``mesh`` cannot be a
    garment dressed on the rest body ``rest`` ``(V, 3)`` in the package's units and
    axes: larger than twice the body's height (another unit: MakeHuman's OBJ files
    are in decimetres, many DCC exports in centimetres), or with fewer than half
    of its vertices within a quarter of that height of the body's bounding box
    (another up axis or origin)."""
    height = float(np.ptp(rest, axis=0).max())
    size = float(np.ptp(mesh.vertices, axis=0).max())
    hint = ("give it in metres, +Z up, dressed on the rest body of the shape it is "
            "animated with")
    if size > 2.0 * height:
        raise ValueError(f"garment {name!r} is {size:.3g} m across and the rest body "
                         f"{height:.2f} m tall: {hint} (MakeHuman's OBJ files are in "
                         "decimetres and +Y up, many DCC exports in centimetres)")
    margin = 0.25 * height
    near = np.all((mesh.vertices >= rest.min(axis=0) - margin)
                  & (mesh.vertices <= rest.max(axis=0) + margin), axis=1).mean()
    if near < 0.5:
        raise ValueError(f"garment {name!r} lies away from the rest body: {near:.0%} of its "
                         f"vertices are within {margin:.2f} m of the body's bounding box; "
                         f"{hint} (another up axis or origin moves it off the body)")


def garment_on_body(name: str, mesh: Mesh, body: BodyModel, shape,
                    pinned: np.ndarray | None = None) -> Garment:
    """A garment mesh already dressed on ``body``'s rest pose with ``shape``
    (metres, +Z up), made ready to animate: pinned at ``pinned`` or else at its
    highest boundary loops (:func:`top_boundary_loops`: waistband, neckline,
    straps; skinned to the torso), skinning transferred from the body, and the
    fit attribute measured on that body.

    Coincident vertices and zero-area faces are welded away first
    (:func:`~swingar_pyg.geometry.weld.weld_mesh`, with a warning saying what
    changed; ``pinned`` is carried over to the welded indices), and vertices nearer
    the body than :data:`DRESSING_CLEARANCE` are moved out to it
    (:func:`~swingar_pyg.geometry.signed_distance.push_out`). A mesh in other
    units or axes is refused (:func:`refuse_undressed`)."""
    mesh, welded = weld_mesh(as_mesh(mesh.vertices, mesh.faces))
    if welded:
        warnings.warn(f"garment {name!r}: {welded}", stacklevel=2)
        if pinned is not None:
            pinned = np.unique(welded.new_index[np.asarray(pinned, np.int64)])
            pinned = pinned[pinned >= 0]
    rest = body.rest_vertices(shape).numpy().astype(np.float64)
    refuse_undressed(name, mesh, rest)
    faces = body.faces.numpy()
    mesh = push_out(mesh, rest, faces, DRESSING_CLEARANCE)
    pinned = top_boundary_loops(mesh) if pinned is None else np.asarray(pinned, np.int64)
    indices, weights = body.skinning()
    skin_indices, skin_weights = transfer_skinning(mesh, pinned, rest, body.joint_names,
                                                   indices.numpy(), weights.numpy())
    fit = -closest_face_signed_distance(mesh.vertices, rest, faces)
    return Garment(name, mesh, pinned, skin_indices, skin_weights, fit)
