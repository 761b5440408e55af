"""Mesh geometry on numpy/scipy (preprocessing) and torch (batched, differentiable)."""

from swingar_pyg.geometry.edge_collapse import merge_short_edges
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
from swingar_pyg.geometry.signed_distance import (
    BodySurface,
    body_signed_distance,
    closest_face_signed_distance,
    inside_share,
)
from swingar_pyg.geometry.spectral import (
    DESCRIPTOR_SIGMA,
    SpectralDescriptor,
    exact_affinity_spectrum,
    gaussian_affinity,
    spectral_descriptor,
)
from swingar_pyg.geometry.weld import (
    WELD_TOLERANCE,
    WeldReport,
    degeneracies,
    refuse_degenerate,
    weld_mesh,
)

__all__ = [
    "BodySurface",
    "Mesh",
    "SpectralDescriptor",
    "as_mesh",
    "body_signed_distance",
    "boundary_edges",
    "closest_face_signed_distance",
    "edge_length_graph",
    "exact_affinity_spectrum",
    "farthest_point_sampling",
    "gaussian_affinity",
    "geodesic_distances",
    "inside_share",
    "load_mesh",
    "mesh_edge_index",
    "mesh_edges",
    "merge_short_edges",
    "roll_into_cylinder",
    "sheet",
    "split_quads",
    "spectral_descriptor",
    "DESCRIPTOR_SIGMA",
    "vertex_normals",
    "WELD_TOLERANCE",
    "WeldReport",
    "degeneracies",
    "refuse_degenerate",
    "weld_mesh",
]
