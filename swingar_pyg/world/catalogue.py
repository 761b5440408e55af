"""The garments a dataset config names: ``{kind: skirt | dress | tshirt | jumpsuit |
shipped, ...}`` entries turned into specs, and any spec fitted on a body."""

from __future__ import annotations

from dataclasses import dataclass

from swingar_pyg.world.body import BodyModel
from swingar_pyg.world.garment import Garment
from swingar_pyg.world.garment_assets import fit_shipped_garment
from swingar_pyg.world.panel_garment import JumpsuitSpec, TShirtSpec, fit_sewn_garment
from swingar_pyg.world.skirt import DressSpec, SkirtSpec, fit_procedural_skirt


@dataclass(frozen=True)
class ShippedGarmentSpec:
    """A shipped MakeHuman garment (:func:`~swingar_pyg.world.garment_assets.shipped_garments`)
    carried onto the body: its edges shorter than ``merge_edges_below`` times the median
    merged when that is above 0, then its triangles split ``subdivisions`` times (4x the
    faces each) for other resolutions of the same topology."""

    name: str
    subdivisions: int = 0
    merge_edges_below: float = 0.0

    def __post_init__(self):
        if not 0 <= self.subdivisions <= 3:
            raise ValueError(f"subdivisions must be in [0, 3], got {self.subdivisions}")
        if not 0.0 <= self.merge_edges_below < 1.0:
            raise ValueError(f"merge_edges_below must be in [0, 1), got {self.merge_edges_below}")


def garment_spec(entry: dict):
    """A garment of a dataset config: ``{kind: skirt | dress | tshirt | jumpsuit |
    shipped, ...}`` (``skirt`` when no kind is given) with the fields of
    :class:`SkirtSpec`, :class:`DressSpec`,
    :class:`~swingar_pyg.world.panel_garment.TShirtSpec`,
    :class:`~swingar_pyg.world.panel_garment.JumpsuitSpec` or :class:`ShippedGarmentSpec`."""
    entry = dict(entry)
    kind = entry.pop("kind", "skirt")
    kinds = {"skirt": SkirtSpec, "dress": DressSpec, "tshirt": TShirtSpec,
             "jumpsuit": JumpsuitSpec, "shipped": ShippedGarmentSpec}
    if kind not in kinds:
        raise ValueError(f"unknown garment kind {kind!r}; use {', '.join(kinds)}")
    return kinds[kind](**entry)


def fit_garment(spec, body: BodyModel, shape) -> Garment:
    """Any garment spec fitted on ``body`` with ``shape`` in its rest pose."""
    if isinstance(spec, ShippedGarmentSpec):
        garment = fit_shipped_garment(spec.name, body, shape, spec.subdivisions,
                                      spec.merge_edges_below)
        suffix = (f"-m{spec.merge_edges_below}" if spec.merge_edges_below else "") + (
            f"-s{spec.subdivisions}" if spec.subdivisions else "")
        return Garment(garment.name + suffix, garment.mesh, garment.pinned, garment.skin_indices,
                       garment.skin_weights, garment.fit)
    if isinstance(spec, SkirtSpec):
        return fit_procedural_skirt(spec, body, shape)
    return fit_sewn_garment(spec, body, shape)
