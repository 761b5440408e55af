"""Garment–body collisions: the exact signed distance and the post-inference
correction (a neural body SDF is issue #5's next slice)."""

from swingar_pyg.collision.correction import (
    Correction,
    exact_signed_distance,
    fixed_offset_push,
    resolve_collisions,
)
from swingar_pyg.collision.reference import body_signed_distance

__all__ = ["Correction", "body_signed_distance", "exact_signed_distance", "fixed_offset_push",
           "resolve_collisions"]
