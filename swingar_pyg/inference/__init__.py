"""Inference with a trained estimator: streaming frame by frame, scenes that run only
the stages they need, and prediction to files."""

from swingar_pyg.inference.prediction import animate, garment_graph
from swingar_pyg.inference.scene import (
    GarmentFeatureCache,
    Scene,
    ScenePipeline,
    SceneResult,
    Stage,
    StageCost,
    StageTimer,
    compile_scene,
    stage_table,
)
from swingar_pyg.inference.streaming import SwinGarStream

__all__ = ["GarmentFeatureCache", "Scene", "ScenePipeline", "SceneResult", "Stage",
           "StageCost", "StageTimer", "SwinGarStream", "animate", "compile_scene", "garment_graph",
           "stage_table"]
