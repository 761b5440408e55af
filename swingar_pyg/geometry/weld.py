r"""Coincident vertices and zero-area faces: found, and welded away.

Meshes from modelling tools often split vertices along UV or material seams, so
two vertices sit at one place. To a cloth solver that is a zero-length edge (its
strain :math:`l / L - 1` divides by zero) and a seam that opens; a zero-area face
has no normal and no bending angle. :func:`weld_mesh` merges every vertex within
``tolerance`` of another (relative to the mesh's bounding-box diagonal
:math:`D`: within :math:`\tau D`), then drops the faces that merging collapsed,
the faces of zero area (height under :math:`\tau` times their longest side:
:math:`2A < \tau\, l_{\max}^2`) and the vertices no face uses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from swingar_pyg.geometry.mesh import Mesh, as_mesh, mesh_edges

WELD_TOLERANCE = 1e-6
"""Vertices closer than this times the bounding-box diagonal are one vertex; a face
whose height is under this times its longest side has no area."""


@dataclass(frozen=True)
class Degeneracies:
    """What would make a mesh unfit to simulate.

    Attributes:
        zero_length_edges: mesh edges shorter than the tolerance.
        coincident_vertices: vertices within the tolerance of another one.
        zero_area_faces: faces whose height is under the tolerance times their longest side.
    """

    zero_length_edges: int
    coincident_vertices: int
    zero_area_faces: int

    def __bool__(self) -> bool:
        return bool(self.zero_length_edges or self.coincident_vertices or self.zero_area_faces)

    def __str__(self) -> str:
        return (f"{self.coincident_vertices} coincident vertices, {self.zero_length_edges} "
                f"zero-length edges and {self.zero_area_faces} zero-area faces")


@dataclass(frozen=True)
class WeldReport:
    """What :func:`weld_mesh` changed.

    Attributes:
        merged_vertices: vertices merged into another one.
        dropped_faces: faces removed (collapsed by merging, or of zero area).
        dropped_vertices: vertices removed because no face used them any more
            (the merged ones included).
        new_index: ``(N,)`` each old vertex's index in the welded mesh (a merged
            vertex maps to the one it merged into; -1 where dropped).
    """

    merged_vertices: int
    dropped_faces: int
    dropped_vertices: int
    new_index: np.ndarray

    def __bool__(self) -> bool:
        return bool(self.merged_vertices or self.dropped_faces or self.dropped_vertices)

    def __str__(self) -> str:
        return (f"merged {self.merged_vertices} coincident vertices, dropped "
                f"{self.dropped_faces} collapsed or zero-area faces and "
                f"{self.dropped_vertices - self.merged_vertices} unused vertices")


def _scale(vertices: np.ndarray) -> float:
    diagonal = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    return diagonal if diagonal > 0 else 1.0


def _zero_area(vertices: np.ndarray, faces: np.ndarray, tolerance: float) -> np.ndarray:
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    doubled_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max([np.einsum("ij,ij->i", d, d) for d in (b - a, c - b, a - c)], axis=0)
    return doubled_area <= tolerance * longest


def degeneracies(mesh: Mesh, tolerance: float = WELD_TOLERANCE) -> Degeneracies:
    """Counts the coincident vertices, zero-length edges and zero-area faces of ``mesh``."""
    vertices = mesh.vertices
    radius = tolerance * _scale(vertices)
    edges = mesh_edges(mesh.faces)
    lengths = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    pairs = cKDTree(vertices).query_pairs(radius, output_type="ndarray")
    return Degeneracies(int((lengths <= radius).sum()), len(np.unique(pairs)),
                        int(_zero_area(vertices, mesh.faces, tolerance).sum()))


def refuse_degenerate(mesh: Mesh, what: str = "the cloth mesh") -> None:
    """Raises a ``ValueError`` naming the coincident vertices, zero-length edges and
    zero-area faces of ``mesh``, if it has any."""
    problems = degeneracies(mesh)
    if problems:
        raise ValueError(f"{what} has {problems}: their strain and bending are undefined; "
                         "weld it first (swingar_pyg.geometry.weld_mesh)")


def weld_mesh(mesh: Mesh, tolerance: float = WELD_TOLERANCE) -> tuple[Mesh, WeldReport]:
    """``mesh`` with coincident vertices merged (each group into its lowest index, at
    that vertex's position), collapsed and zero-area faces dropped, and unused
    vertices removed; vertex order is otherwise kept.

    Raises:
        ValueError: if no face is left.
    """
    if not tolerance >= 0:
        raise ValueError(f"tolerance must be >= 0, got {tolerance}")
    vertices, faces = mesh.vertices, mesh.faces
    n = len(vertices)
    pairs = cKDTree(vertices).query_pairs(tolerance * _scale(vertices), output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    first = np.full(group.max() + 1, n)
    np.minimum.at(first, group, np.arange(n))
    merged_into = first[group]
    faces = merged_into[faces]
    collapsed = ((faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2])
                 | (faces[:, 2] == faces[:, 0]))
    keep = ~collapsed & ~_zero_area(vertices, faces, tolerance)
    if not keep.any():
        raise ValueError("welding left no face: every face is collapsed or has zero area")
    faces = faces[keep]
    used = np.zeros(n, dtype=bool)
    used[faces.reshape(-1)] = True
    compact = np.full(n, -1)
    compact[used] = np.arange(int(used.sum()))
    new_index = compact[merged_into]
    report = WeldReport(int((merged_into != np.arange(n)).sum()), int((~keep).sum()),
                        int((~used).sum()), new_index)
    return as_mesh(vertices[used], compact[faces]), report
