"""Lightning datamodules of swingar_pyg."""

from datamodules.feature_cache import FeatureSettings, ensure_feature_cache
from datamodules.garment_windows import GarmentWindowDataset
from datamodules.swingar_datamodule import SwinGarDataModule

__all__ = ["FeatureSettings", "GarmentWindowDataset", "SwinGarDataModule",
           "ensure_feature_cache"]
