import math

import numpy as np
import pytest
import torch

from swingar_pyg.geometry import as_mesh, sheet, weld_mesh
from swingar_pyg.sim import XPBDCloth, XPBDSettings
from swingar_pyg.sim.constraints import dihedral_angles, dihedral_constraints, hinges


def folded_quad(angle):
    """Two unit triangles on the edge (0,0,0)-(1,0,0): one in the x-y plane, the
    other turned by ``angle`` about the edge (0: flat)."""
    wing = [0.5, math.cos(angle), math.sin(angle)]
    return as_mesh([[0, 0, 0], [1, 0, 0], [0.5, -1, 0], wing], [[0, 1, 3], [1, 0, 2]])


def test_gradients_equal_autograd_on_random_and_nearly_flat_hinges():
    generator = torch.Generator().manual_seed(0)
    random = torch.randn(64, 4, 3, generator=generator, dtype=torch.float64)
    flat = random.clone()
    flat[:, :, 2] = 1e-7 * flat[:, :, 2]  # all but flat: angles near 0 and near pi
    for x in (random, flat):
        x = x.requires_grad_(True)
        angle, gradient, valid = dihedral_angles(x.permute(2, 1, 0))
        expected, = torch.autograd.grad(angle.sum(), x)
        assert valid.all()
        assert torch.allclose(gradient.permute(2, 1, 0), expected, rtol=1e-6, atol=1e-9)


def test_hinge_angles_are_signed_and_zero_when_flat():
    assert dihedral_constraints(folded_quad(0.0)).rest_angles.abs().max() < 1e-12
    up = dihedral_constraints(folded_quad(math.pi / 3)).rest_angles
    down = dihedral_constraints(folded_quad(-math.pi / 3)).rest_angles
    assert up.abs().item() == pytest.approx(math.pi / 3)
    assert down.item() == pytest.approx(-up.item())
    # a consistently oriented sheet is flat everywhere; every interior edge is one hinge
    mesh = sheet(6, 5, jitter=0.3)
    constraints = dihedral_constraints(mesh)
    assert constraints.rest_angles.abs().max() < 1e-9
    edges = np.sort(np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]],
                                    mesh.faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert len(constraints.hinges) == (counts == 2).sum() > 0
    counts = np.bincount(constraints.hinges.reshape(-1).numpy(), minlength=mesh.num_vertices)
    assert torch.allclose(constraints.share[:, 0], torch.from_numpy(1.0 / np.maximum(counts, 1)))


def test_degenerate_hinges_are_left_alone():
    x = torch.tensor([[0.0, 0, 0], [0.5, -1, 0], [0, 0, 0], [1, 0, 0]], dtype=torch.float64)
    angle, gradient, valid = dihedral_angles(x.T[:, :, None])  # first triangle has no area
    assert not valid.any()
    assert torch.equal(gradient, torch.zeros_like(gradient))
    # an edge of three triangles (non-manifold) is no hinge; its neighbours still are
    fan = as_mesh([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]],
                  [[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert len(hinges(fan)) == 0


@pytest.mark.parametrize('stiffness', [0.3, 1.0, 3.0])
def test_a_hinge_holds_a_wing_where_its_torque_balances_gravity(stiffness):
    """The pinned triangle of :func:`folded_quad` holds the other (edge length 1,
    wing tip 1 m from the edge, lumped tip mass m = density x area / 3): at rest the
    hinge's torque k |e| beta equals gravity's, m g cos(beta)."""
    from scipy.optimize import brentq

    mesh = folded_quad(0.0)
    settings = XPBDSettings(substeps=20, iterations=2, damping=8.0, bending="dihedral",
                            bend_stiffness=stiffness, settle_frames=0)
    tip_mass = settings.density * 0.5 / 3
    expected = brentq(lambda b: stiffness * b - tip_mass * 9.81 * math.cos(b), 0, math.pi / 2)
    cloth = XPBDCloth(mesh, np.array([0, 1, 2]), settings)
    initial = torch.from_numpy(mesh.vertices).float()
    result = cloth.simulate(initial, initial[:3].expand(60, -1, -1))
    assert torch.isfinite(result.positions).all()
    y, z = result.positions[-1][3, 1:].tolist()
    assert math.atan2(-z, y) == pytest.approx(expected, rel=0.03)
    assert result.max_stretch.max() < 0.01


def test_degenerate_cloth_is_refused_and_stiff_welded_cloth_stays_finite():
    flat = sheet(6, 6, width=0.2, height=0.2, jitter=0.3)
    vertices = flat.vertices.copy()
    vertices[7] = vertices[8]  # a collapsed edge: two zero-area triangles
    mesh = as_mesh(vertices, flat.faces)
    top = np.flatnonzero(np.isclose(vertices[:, 1], vertices[:, 1].max()))
    with pytest.raises(ValueError, match='2 coincident vertices, 1 zero-length edges'):
        XPBDCloth(mesh, top, XPBDSettings(bending="dihedral"))
    mesh, report = weld_mesh(mesh)
    assert report.merged_vertices == 1 and report.dropped_faces == 2
    top = report.new_index[top]
    initial = torch.from_numpy(mesh.vertices).float()
    for stiffness in (0.0, 1e-3, 1e6):
        settings = XPBDSettings(substeps=5, iterations=2, bending="dihedral",
                                bend_stiffness=stiffness, settle_frames=0)
        result = XPBDCloth(mesh, top, settings).simulate(initial, initial[top].expand(8, -1, -1))
        assert torch.isfinite(result.positions).all(), stiffness
        assert result.positions[-1][:, 2].min() < -0.01  # it falls


def test_bad_bending_model_is_refused():
    with pytest.raises(ValueError, match="bending must be 'distance' or 'dihedral'"):
        XPBDSettings(bending="springs")
    with pytest.raises(ValueError, match="bend_stiffness must be finite"):
        XPBDSettings(bending="dihedral", bend_stiffness=float("inf"))
