"""Lightning training of the estimator (needs the ``train`` extra)."""

from swingar_pyg.training.module import SwinGarModule
from swingar_pyg.training.vertex_errors import VertexErrors, error_stats, garment_family

__all__ = ["SwinGarModule", "VertexErrors", "error_stats", "garment_family"]
