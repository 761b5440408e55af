"""Geodesic distances along mesh edges and geodesic farthest-point sampling."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from swingar_pyg.geometry.mesh import Mesh, mesh_edges

# Distances within this relative difference count as equal (rounding noise).
_TIE_TOLERANCE = 1e-9


def edge_length_graph(mesh: Mesh, weld_tolerance: float = 1e-9) -> sp.csr_array:
    """Symmetric sparse ``(N, N)`` graph of mesh-edge lengths.

    Vertices closer than ``weld_tolerance`` times the bounding-box diagonal
    (duplicates, e.g. split along a UV seam) are joined by a zero-length edge,
    so geodesics cross seams. Zero lengths are stored explicitly: csgraph
    treats explicit entries of a sparse graph as edges.
    """
    edges = mesh_edges(mesh.faces)
    extent = float(np.ptp(mesh.vertices, axis=0).max(initial=0.0))
    if weld_tolerance > 0 and extent > 0:
        pairs = cKDTree(mesh.vertices).query_pairs(weld_tolerance * extent,
                                                   output_type="ndarray")
        if len(pairs):
            edges = np.unique(np.concatenate([edges, np.sort(pairs, axis=1)]), axis=0)
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    n = mesh.num_vertices
    return sp.csr_array((np.concatenate([lengths, lengths]), (rows, cols)), shape=(n, n))


def geodesic_distances(graph: sp.csr_array, sources: np.ndarray | int) -> np.ndarray:
    """Dijkstra distances ``(S, N)`` from each source along the edge graph;
    ``inf`` where a vertex lies in another connected component."""
    return np.atleast_2d(dijkstra(graph, directed=True, indices=sources))


def farthest_point_sampling(
    graph: sp.csr_array, num_samples: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Geodesic farthest-point sampling.

    The first sample is drawn with ``seed``; each next one is the vertex
    farthest (geodesically) from all samples so far, the lowest index among
    those within a relative ``1e-9`` of the farthest, so that rounding noise
    (a rigid motion of the mesh) does not change the samples. A vertex in a
    component with no sample yet is infinitely far, so every connected
    component is sampled before any gets a second sample.

    Returns:
        ``(indices, distances)``: ``(S,)`` sample indices and the ``(S, N)``
        geodesic distances from each sample, with ``S = min(num_samples, N)``.
    """
    n = graph.shape[0]
    count = min(int(num_samples), n)
    if count < 1:
        raise ValueError(f"num_samples must be >= 1, got {num_samples}")
    indices = np.empty(count, dtype=np.int64)
    distances = np.empty((count, n))
    indices[0] = np.random.default_rng(seed).integers(n)
    nearest = np.full(n, np.inf)
    for k in range(count):
        if k > 0:
            nearest[indices[:k]] = -1.0  # never pick a sample twice
            farthest = nearest.max()
            if np.isfinite(farthest):
                farthest -= _TIE_TOLERANCE * farthest
            indices[k] = int(np.argmax(nearest >= farthest))
        distances[k] = dijkstra(graph, directed=True, indices=indices[k])
        np.minimum(nearest, distances[k], out=nearest)
    return indices, distances
