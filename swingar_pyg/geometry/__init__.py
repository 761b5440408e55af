"""Mesh geometry on numpy/scipy (preprocessing) and torch (batched, differentiable)."""

from swingar_pyg.geometry.distance import signed_distance_to_surface
from swingar_pyg.geometry.geodesic import (
    edge_length_graph,
    farthest_point_sampling,
    geodesic_distances,
)
from swingar_pyg.geometry.mesh import (
    Mesh,
    as_mesh,
    boundary_edges,
    load_mesh,
    mesh_edge_index,
    mesh_edges,
)
from swingar_pyg.geometry.normals import vertex_normals
from swingar_pyg.geometry.primitives import roll_into_cylinder, sheet, split_quads
from swingar_pyg.geometry.spectral import (
    SpectralDescriptor,
    exact_affinity_spectrum,
    gaussian_affinity,
    spectral_descriptor,
)

__all__ = [
    "Mesh",
    "SpectralDescriptor",
    "as_mesh",
    "boundary_edges",
    "edge_length_graph",
    "exact_affinity_spectrum",
    "farthest_point_sampling",
    "gaussian_affinity",
    "geodesic_distances",
    "load_mesh",
    "mesh_edge_index",
    "mesh_edges",
    "roll_into_cylinder",
    "sheet",
    "signed_distance_to_surface",
    "split_quads",
    "spectral_descriptor",
    "vertex_normals",
]
