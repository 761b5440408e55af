"""The newton VBD simulator, on the scenes the XPBD tests use, and against XPBD itself."""

import numpy as np
import pytest
import torch
import trimesh

from swingar_pyg.geometry import as_mesh, sheet
from swingar_pyg.sim import BodyCollider, VBDCloth, VBDSettings, XPBDCloth, XPBDSettings
from tests.extras import require

from .test_xpbd import hanging_sheet

require('newton')


def run(mesh, pinned, frames=20, settings=None, collider=None, targets=None):
    settings = settings or VBDSettings(settle_frames=0)
    cloth = VBDCloth(mesh, pinned, settings)
    initial = torch.from_numpy(mesh.vertices).float()
    if targets is None:
        targets = initial[pinned].expand(frames, -1, -1)
    return cloth.simulate(initial, targets, collider)


def test_swinging_sheet_follows_xpbd():
    # A horizontal sheet pinned along one edge swings down under gravity: two independent
    # models of nearly inextensible cloth must trace nearly the same swing.
    flat = sheet(10, 10, width=0.4, height=0.4, jitter=0.2)
    mesh = as_mesh(flat.vertices, flat.faces)
    edge = np.flatnonzero(np.isclose(mesh.vertices[:, 1], mesh.vertices[:, 1].max()))
    frames = 20
    initial = torch.from_numpy(mesh.vertices).float()
    targets = initial[edge].expand(frames, -1, -1)
    vbd = run(mesh, edge, frames=frames, targets=targets)
    xpbd = XPBDCloth(mesh, edge, XPBDSettings(settle_frames=0)).simulate(initial, targets)
    assert torch.isfinite(vbd.positions).all()
    assert torch.equal(vbd.positions[:, edge], targets)  # pins are exactly where they are told
    assert vbd.max_stretch.max() < 0.05
    swing = (xpbd.positions - initial).norm(dim=-1).mean(dim=1)
    gap = (vbd.positions - xpbd.positions).norm(dim=-1).mean(dim=1)
    assert swing.max() > 0.3  # it swung down by most of its 40 cm
    assert gap.max() < 0.1 * swing.max()  # measured: 19 mm at most against 386 mm


def test_cloth_dropped_on_a_sphere_does_not_enter_it():
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.15)
    frames = 30
    collider = BodyCollider(torch.tensor(ball.vertices, dtype=torch.float32).expand(frames, -1, -1),
                            torch.tensor(ball.faces), thickness=0.004)
    flat = sheet(12, 12, width=0.5, height=0.5, jitter=0.2)
    mesh = as_mesh(flat.vertices - [0.25, 0.25, -0.2], flat.faces)  # 5 cm above the top
    result = run(mesh, np.array([], dtype=np.int64), frames=frames, collider=collider)
    final = result.positions[-1]
    # A penalty contact lets cloth sink a little under its own weight: within 2 mm of
    # the analytic sphere (the faceted one lies up to 1.5 mm inside it).
    assert final.norm(dim=-1).min() > 0.15 - 0.002
    assert final[:, 2].min() < 0.0  # it draped over the sphere rather than floating


def test_a_moving_body_pushes_cloth_ahead():
    # A ball sweeping 3 cm per frame into a hanging curtain: the body's mesh is re-posed
    # every substep, so the cloth in front of it is pushed, never passed through.
    radius = 0.06
    ball = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    frames = 12
    path = torch.zeros(frames, 1, 3)
    path[:, 0, 1] = torch.linspace(-0.2, 0.13, frames)
    path[:, 0, 2] = 0.2
    vertices = torch.tensor(ball.vertices, dtype=torch.float32)[None] + path
    collider = BodyCollider(vertices, torch.tensor(ball.faces))
    mesh, top = hanging_sheet(12, 12, size=0.4)
    mesh = as_mesh(mesh.vertices - [0.2, 0.0, 0.0], mesh.faces)
    result = run(mesh, top, frames=frames, collider=collider)
    centre = vertices[-1].mean(dim=0)
    cloth = result.positions[-1]
    in_silhouette = (cloth[:, [0, 2]] - centre[[0, 2]]).norm(dim=-1) < 0.5 * radius
    assert in_silhouette.any()
    assert (cloth[in_silhouette, 1] > centre[1]).all()  # in front of the ball
    assert (cloth[:, 1] > 0.05).any()  # and it was pushed forward


@pytest.mark.parametrize('kwargs, message', [
    ({'substeps': 0}, 'must be positive'),
    ({'bend_stiffness': -1.0}, 'bend_stiffness must be finite'),
    ({'density': 0.0}, 'density and stretch_stiffness must be > 0'),
    ({'friction': 2.0}, r'friction must be in \[0, 1\]'),
])
def test_bad_settings_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        VBDSettings(**kwargs)


def test_bad_inputs_raise():
    mesh, top = hanging_sheet(4, 4)
    cloth = VBDCloth(mesh, top, VBDSettings(settle_frames=0))
    initial = torch.from_numpy(mesh.vertices).float()
    with pytest.raises(ValueError, match='initial positions must have shape'):
        cloth.simulate(initial[:-1], initial[top][None])
    with pytest.raises(ValueError, match='must be finite'):
        cloth.simulate(initial * float('nan'), initial[top][None])
    with pytest.raises(ValueError, match='pinned indices'):
        VBDCloth(mesh, np.array([999]), VBDSettings())
