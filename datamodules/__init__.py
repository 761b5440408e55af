"""Lightning datamodules of swingar_pyg."""

from datamodules.body_sdf_data import SDFSampleSettings
from datamodules.body_sdf_datamodule import BodySDFDataModule, BodySDFFrames
from datamodules.feature_cache import FeatureSettings, ensure_feature_cache
from datamodules.garment_windows import GarmentWindowDataset
from datamodules.swingar_datamodule import SwinGarDataModule

__all__ = ["BodySDFDataModule", "BodySDFFrames", "FeatureSettings", "GarmentWindowDataset",
           "SDFSampleSettings", "SwinGarDataModule", "ensure_feature_cache"]
