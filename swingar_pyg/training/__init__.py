"""Lightning training of the estimator and of the body SDF (needs the ``train`` extra)."""

from swingar_pyg.training.body_sdf_module import BodySDFModule
from swingar_pyg.training.checkpoints import (
    export_weights,
    load_body_sdf,
    load_estimator,
    load_pretrained,
    write_exported_weights,
)
from swingar_pyg.training.module import SwinGarModule
from swingar_pyg.training.vertex_errors import VertexErrors, error_stats, garment_family

__all__ = ["BodySDFModule", "SwinGarModule", "VertexErrors", "error_stats", "export_weights",
           "garment_family", "load_body_sdf", "load_estimator", "load_pretrained",
           "write_exported_weights"]
