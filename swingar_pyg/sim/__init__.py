"""Ground-truth cloth simulation (DESIGN §8)."""

from swingar_pyg.sim.collider import BodyCollider
from swingar_pyg.sim.xpbd import SIMULATOR_REVISION, SimulationResult, XPBDCloth, XPBDSettings

__all__ = ["BodyCollider", "SimulationResult", "XPBDCloth", "XPBDSettings"]
