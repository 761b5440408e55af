import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import floyd_warshall

from swingar_pyg.geometry import as_mesh, sheet
from swingar_pyg.sim import XPBDCloth, XPBDSettings
from swingar_pyg.sim.constraints import tether_constraints
from tests.test_xpbd import hanging_sheet, run


def _all_pairs_edge_distances(mesh):
    """Independent reference: Floyd-Warshall over the mesh edges, no welding."""
    edges = np.unique(np.sort(np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]],
                                              mesh.faces[:, [2, 0]]]), axis=1), axis=0)
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    graph = sp.coo_matrix((lengths, (edges[:, 0], edges[:, 1])),
                          shape=(mesh.num_vertices,) * 2).tocsr()
    return floyd_warshall(graph, directed=False)


def test_each_free_vertex_is_tethered_to_its_nearest_pin_at_the_geodesic_distance():
    mesh, top = hanging_sheet(6, 5)
    tethers = tether_constraints(mesh, top)
    reference = _all_pairs_edge_distances(mesh)[top]  # (pins, N)
    free = np.setdiff1d(np.arange(mesh.num_vertices), top)
    assert tethers.vertices.tolist() == free.tolist()
    assert np.allclose(tethers.rest_lengths.numpy(), reference.min(axis=0)[free])
    anchor_row = np.searchsorted(top, tethers.anchors.numpy())
    assert np.allclose(reference[anchor_row, free], tethers.rest_lengths.numpy())
    # a path along the cloth is never shorter than the straight line
    straight = np.linalg.norm(mesh.vertices[free] - mesh.vertices[tethers.anchors], axis=1)
    assert (tethers.rest_lengths.numpy() >= straight - 1e-12).all()


def test_nothing_pinned_or_unreachable_gets_no_tether():
    mesh, top = hanging_sheet(4, 4)
    assert len(tether_constraints(mesh, np.array([], dtype=np.int64)).vertices) == 0
    assert len(tether_constraints(mesh, np.arange(mesh.num_vertices)).vertices) == 0
    other = sheet(3, 3)
    pieces = as_mesh(np.concatenate([mesh.vertices, other.vertices + 5.0]),
                     np.concatenate([mesh.faces, other.faces + mesh.num_vertices]))
    tethered = tether_constraints(pieces, top).vertices
    assert tethered.max() < mesh.num_vertices  # the unpinned piece stays free


def test_projection_pulls_over_long_tethers_back_and_leaves_slack_ones():
    mesh, top = hanging_sheet(4, 4)
    settings = XPBDSettings(tether_slack=0.1)
    cloth = XPBDCloth(mesh, top, settings, dtype=torch.float64)
    tethers = cloth.tethers
    p = torch.from_numpy(mesh.vertices).clone()
    far, near = tethers.vertices[-1], tethers.vertices[0]
    anchor = p[tethers.anchors[-1]]
    p[far] = anchor + 3.0 * (p[far] - anchor)  # 3x its rest distance, same direction
    before_near = p[near].clone()
    cloth._tether(p, tethers)
    assert torch.isclose((p[far] - anchor).norm(), 1.1 * tethers.rest_lengths[-1])
    assert torch.equal(p[near], before_near)


def test_tethers_bound_stretch_at_large_time_steps():
    # 4x the frame time with 5 substeps: two sweeps cannot carry the pins' pull down
    # an unsupported sheet (its hinges hold nothing in-plane) but the tethers can.
    mesh, top = hanging_sheet()
    coarse = dict(fps=7.5, substeps=5, settle_frames=0)
    tethered = run(mesh, top, frames=15, settings=XPBDSettings(**coarse))[1]
    loose = run(mesh, top, frames=15, settings=XPBDSettings(tethers=False, **coarse))[1]
    assert torch.isfinite(tethered.positions).all()
    assert tethered.max_stretch.max() < 0.1
    assert loose.max_stretch.max() > 5 * tethered.max_stretch.max()


def test_bad_slack_is_refused():
    with pytest.raises(ValueError, match='tether_slack must be finite and >= 0'):
        XPBDSettings(tether_slack=-0.1)
