"""The warp backend of the XPBD solver against the torch path it compiles.

Cloth is chaotic, so two float32 runs of one scene drift apart by themselves. The
independent reference is the torch path in float64: the warp kernel (float32) must
stay as close to it as the torch path in float32 does, frame by frame, on scenes
that use every part of the substep (hinges or distance bending, tethers, a moving
body with friction, error-controlled re-runs).
"""

import dataclasses

import numpy as np
import pytest
import torch
import trimesh

from swingar_pyg.geometry import as_mesh, sheet
from swingar_pyg.sim import BodyCollider, XPBDCloth, XPBDSettings

from .extras import require

require('anny')  # warp comes with the body extra


def curtain(rows=10, cols=10, size=0.4):
    """A jittered sheet hanging in the x-z plane, top row pinned."""
    flat = sheet(rows, cols, width=size, height=size, jitter=0.2)
    vertices = flat.vertices[:, [0, 2, 1]] - [size / 2, 0.0, 0.0]
    mesh = as_mesh(vertices, flat.faces)
    return mesh, np.flatnonzero(np.isclose(vertices[:, 2], vertices[:, 2].max()))


def swinging_scene(frames=4):
    """The curtain's pins swinging sideways while a ball moves into the cloth."""
    mesh, top = curtain()
    initial = torch.from_numpy(mesh.vertices)
    shift = torch.zeros(frames, 1, 3, dtype=torch.float64)
    shift[:, 0, 0] = 0.05 * torch.sin(torch.linspace(0, 2.0, frames))
    targets = initial[top][None] + shift
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.06)
    path = torch.zeros(frames, 1, 3)
    path[:, 0, 1] = torch.linspace(-0.1, 0.05, frames)
    path[:, 0, 2] = 0.2
    body = torch.tensor(ball.vertices, dtype=torch.float32)[None] + path
    return mesh, top, initial, targets, BodyCollider(body, torch.tensor(ball.faces))


def simulate(settings, dtype, scene):
    mesh, top, initial, targets, collider = scene
    cloth = XPBDCloth(mesh, top, settings, dtype=dtype)
    return cloth.simulate(initial.to(dtype), targets.to(dtype), collider)


@pytest.mark.parametrize('changes', [
    {},
    {'bending': 'distance'},
    {'tethers': False, 'friction': 0.0},
    {'contacts_per_frame': 3, 'iterations': 2},
    {'substeps': 5, 'max_substeps': 40},
    {'bend_every': 3, 'contacts_per_frame': 2},
    {'bend_every': 2, 'bending': 'distance'},
], ids=['dihedral', 'distance-bending', 'no-tethers-no-friction', 'contacts-thrice', 'rerun',
        'bend-every-3', 'distance-bend-every-2'])
def test_the_warp_kernel_is_as_close_to_float64_as_the_torch_path(changes):
    scene = swinging_scene()
    settings = dataclasses.replace(XPBDSettings(substeps=10, settle_frames=1), **changes)
    reference = simulate(settings, torch.float64, scene)
    float32 = simulate(settings, torch.float32, scene)
    compiled = simulate(dataclasses.replace(settings, backend='warp'), torch.float32, scene)
    assert np.array_equal(compiled.substeps_per_frame, float32.substeps_per_frame)
    torch_error = (float32.positions.double() - reference.positions).norm(dim=-1).amax(1)
    warp_error = (compiled.positions.double() - reference.positions).norm(dim=-1).amax(1)
    moved = (reference.positions - reference.positions[:1]).norm(dim=-1).amax(1)
    assert moved[-1] > 0.01  # the scene moves: a kernel that did nothing would fail
    # rounding only: within a few float32 ulps of a metre-sized scene, as torch in float32
    assert (warp_error <= 3 * torch_error + 1e-6).all(), (warp_error, torch_error)


def test_the_warp_kernel_is_deterministic():
    scene = swinging_scene(frames=3)
    settings = XPBDSettings(substeps=10, settle_frames=1, backend='warp')
    first, second = (simulate(settings, torch.float32, scene) for _ in range(2))
    assert torch.equal(first.positions, second.positions)


def test_bending_off_and_nothing_pinned_run_on_the_warp_kernel():
    mesh, _ = curtain(6, 6)
    frames = 3
    settings = XPBDSettings(substeps=10, settle_frames=0, bend_stiffness=0.0, backend='warp')
    cloth = XPBDCloth(mesh, np.array([], dtype=np.int64), settings)
    result = cloth.simulate(torch.from_numpy(mesh.vertices).float(), torch.zeros(frames, 0, 3))
    # a free fall of damped symplectic Euler steps: v <- (v + g dt) decay, x <- x + v dt
    dt, decay = 1 / 300, np.exp(-settings.damping / 300)
    velocity, fall = 0.0, []
    for _ in range(frames):
        for _ in range(10):
            velocity = (velocity + 9.81 * dt) * decay
            fall.append((fall[-1] if fall else 0.0) + velocity * dt)
    drop = torch.from_numpy(mesh.vertices[:, 2]).float() - result.positions[..., 2]
    assert np.allclose(drop.numpy(), np.array(fall[9::10])[:, None], atol=1e-6)


def test_the_warp_backend_refuses_what_it_does_not_run():
    mesh, top = curtain(4, 4)
    with pytest.raises(ValueError, match="backend='warp' runs float32 on the CPU"):
        XPBDCloth(mesh, top, XPBDSettings(backend='warp'), dtype=torch.float64)
    with pytest.raises(ValueError, match="backend must be 'torch' or 'warp'"):
        XPBDSettings(backend='numba')
