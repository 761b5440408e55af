"""Garment–body collisions: the exact signed distance (the reference), the
broad phase on the body's bones, the neighbour-aware correction, and the
correction driven by the neural body SDF."""

from swingar_pyg.collision.broad_phase import BoneCapsules
from swingar_pyg.collision.correction import (
    Correction,
    exact_signed_distance,
    fixed_offset_push,
    nearest_vertex_signed_distance,
    resolve_collisions,
)
from swingar_pyg.collision.neural import NeuralCollisions
from swingar_pyg.collision.reference import body_signed_distance

__all__ = ["BoneCapsules", "Correction", "NeuralCollisions", "body_signed_distance",
           "exact_signed_distance", "fixed_offset_push", "nearest_vertex_signed_distance",
           "resolve_collisions"]
