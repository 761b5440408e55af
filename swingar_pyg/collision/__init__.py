"""Garment–body collisions after inference: the broad phase on the body's bones,
the neighbour-aware correction (driven by the exact signed distance of
:mod:`swingar_pyg.geometry.signed_distance` or by the neural body SDF), and
TailorNet's fixed-offset push."""

from swingar_pyg.collision.broad_phase import BoneCapsules
from swingar_pyg.collision.correction import (
    Correction,
    exact_signed_distance,
    fixed_offset_push,
    nearest_vertex_signed_distance,
    resolve_collisions,
)
from swingar_pyg.collision.neural import NeuralCollisions

__all__ = ["BoneCapsules", "Correction", "NeuralCollisions", "exact_signed_distance",
           "fixed_offset_push", "nearest_vertex_signed_distance", "resolve_collisions"]
