"""Networks of SwinGar; they know nothing of Lightning."""

from swingar_pyg.models.body_sdf import BodySDF
from swingar_pyg.models.estimator import EstimatorOutput, SwinGarEstimator
from swingar_pyg.models.garment_window import GarmentWindow
from swingar_pyg.models.pose_features import pose_feature_size, pose_window

__all__ = ["BodySDF", "EstimatorOutput", "GarmentWindow", "SwinGarEstimator", "pose_feature_size",
           "pose_window"]
