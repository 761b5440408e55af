"""Ground-truth cloth simulation (docs/design.md §8)."""

from swingar_pyg.sim.collider import BodyCollider
from swingar_pyg.sim.recording import STRETCH_BAR, SimulationResult
from swingar_pyg.sim.vbd import VBDCloth, VBDSettings
from swingar_pyg.sim.xpbd import SIMULATOR_REVISION, XPBDCloth, XPBDSettings

__all__ = ["SIMULATOR_REVISION", "STRETCH_BAR", "BodyCollider", "SimulationResult", "VBDCloth",
           "VBDSettings", "XPBDCloth", "XPBDSettings"]
