"""The cases that must raise: invalid input to a mesh, a simulator's settings,
the body, the body SDF, collision handling, the descriptor and the estimator,
each refused with a :class:`ValueError` that says what is wrong."""

from __future__ import annotations

import torch

from swingar_pyg.collision import resolve_collisions
from swingar_pyg.eval.stability.records import Case
from swingar_pyg.geometry import as_mesh, sheet, spectral_descriptor
from swingar_pyg.models import BodySDF, GarmentWindow
from swingar_pyg.sim import VBDSettings, XPBDCloth, XPBDSettings


def _raise_mesh_nan(context):
    as_mesh([[0, 0, 0], [1, 0, float("nan")], [0, 1, 0]], [[0, 1, 2]])


def _raise_simulator_settings(context):
    XPBDSettings(stretch_compliance=-1.0)


def _raise_simulator_coincident_vertices(context):
    flat = sheet(4, 4)
    vertices = flat.vertices.copy()
    vertices[5] = vertices[6]
    XPBDCloth(as_mesh(vertices, flat.faces), [0], XPBDSettings())


def _raise_vbd_settings(context):
    VBDSettings(bend_stiffness=-1.0)


def _raise_body_shape(context):
    context.body.rest_vertices(torch.full((6,), 1.5))


def _raise_body_sdf_nan(context):
    BodySDF()(torch.full((2, 3), float("nan")), torch.eye(4).expand(1, 31, 4, 4),
              torch.zeros(1, 31, 3), torch.zeros(1, 6))


def _raise_collision_nan(context):
    resolve_collisions(torch.full((3, 3), float("nan")), torch.zeros(2, 0, dtype=torch.long),
                       lambda x: (x[:, 0], x))


def _raise_descriptor_sigma(context):
    spectral_descriptor(sheet(4, 4), sigma=0.0)


def _raise_estimator_window(context):
    graph = context.graph
    window = GarmentWindow(rest=graph.rest, normal=graph.normal, fit=graph.fit,
                           prior_weights=graph.prior_weights[:, :3], edge_index=graph.edge_index,
                           pose_history=torch.zeros(1, 3, 4, 10))
    context.estimator(window)


ERROR_CASES: tuple[Case, ...] = (
    Case("mesh", "NaN vertex", "", _raise_mesh_nan, raises="not finite"),
    Case("simulator", "negative compliance", "", _raise_simulator_settings,
         raises="must be finite and >= 0"),
    Case("simulator", "coincident vertices, zero-area faces", "",
         _raise_simulator_coincident_vertices, raises="weld it first"),
    Case("VBD simulator", "negative bending stiffness", "", _raise_vbd_settings,
         raises="must be finite and >= 0", needs="newton"),
    Case("body", "shape outside [0, 1]", "", _raise_body_shape, raises="must lie in [0, 1]"),
    Case("body SDF", "NaN points", "", _raise_body_sdf_nan, raises="points must be finite"),
    Case("collisions", "NaN garment", "", _raise_collision_nan, raises="not finite"),
    Case("descriptor", "sigma 0", "", _raise_descriptor_sigma, raises="sigma must be"),
    Case("estimator", "wrong joint count", "", _raise_estimator_window, raises="prior_weights"),
)
