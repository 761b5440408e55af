import numpy as np
import pytest
import torch

from swingar_pyg.geometry import as_mesh, degeneracies, sheet, weld_mesh
from swingar_pyg.sim import XPBDCloth, XPBDSettings

from .extras import require


def split_along_a_seam(mesh):
    """``mesh`` with the vertices of its middle column duplicated: the faces right
    of the seam use the copies (as a modelling tool's UV seam does)."""
    x = mesh.vertices[:, 0]
    middle = np.median(np.unique(x))
    seam = np.flatnonzero(np.isclose(x, middle))
    copies = len(mesh.vertices) + np.arange(len(seam))
    copy_of = np.arange(len(mesh.vertices))
    copy_of[seam] = copies
    faces = mesh.faces.copy()
    right = mesh.vertices[faces].mean(axis=1)[:, 0] > middle
    faces[right] = copy_of[faces[right]]
    return as_mesh(np.concatenate([mesh.vertices, mesh.vertices[seam]]), faces), seam


def test_a_split_seam_welds_back_into_the_original_mesh():
    original = sheet(6, 7, width=0.4, height=0.3)
    split, seam = split_along_a_seam(original)
    problems = degeneracies(split)
    assert problems.coincident_vertices == 2 * len(seam) and problems.zero_area_faces == 0
    welded, report = weld_mesh(split)
    assert report.merged_vertices == len(seam) and report.dropped_faces == 0
    assert np.array_equal(welded.vertices, original.vertices)
    assert np.array_equal(welded.faces, original.faces)
    assert np.array_equal(report.new_index[len(original.vertices):], seam)  # copies -> seam
    assert not degeneracies(welded)
    assert not weld_mesh(original)[1]  # a clean mesh is left as it is


@pytest.mark.parametrize('scale', [1e-6, 1.0, 1e6])
def test_collapsed_and_zero_area_faces_and_unused_vertices_are_dropped(scale):
    vertices = scale * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0],
                                 [2, 0, 0],        # on the line through 0 and 1
                                 [1, 1, 1e-9],     # coincident with 3
                                 [5, 5, 5]], float)  # used by no face
    faces = np.array([[0, 1, 2], [1, 3, 2], [0, 1, 4], [1, 5, 3], [2, 3, 5]])
    welded, report = weld_mesh(as_mesh(vertices, faces))
    assert report.merged_vertices == 1  # 5 into 3
    assert report.dropped_faces == 3  # [0 1 4] zero area, [1 5 3] and [2 3 5] collapsed
    assert welded.num_vertices == 4 and np.array_equal(welded.faces, [[0, 1, 2], [1, 3, 2]])
    assert list(report.new_index) == [0, 1, 2, 3, -1, 3, -1]
    assert str(report) == ("merged 1 coincident vertices, dropped 3 collapsed or zero-area "
                           "faces and 2 unused vertices")


def test_welding_everything_away_raises():
    with pytest.raises(ValueError, match='welding left no face'):
        weld_mesh(as_mesh(np.zeros((3, 3)), np.array([[0, 1, 2]])))


def test_the_simulator_refuses_coincident_vertices_and_zero_area_faces():
    split, _ = split_along_a_seam(sheet(5, 5, width=0.3, height=0.3))
    with pytest.raises(ValueError, match='coincident vertices.*weld it first'):
        XPBDCloth(split, np.array([0]), XPBDSettings())
    flat = as_mesh(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float),
                   np.array([[0, 1, 3], [0, 1, 2]]))
    with pytest.raises(ValueError, match='1 zero-area faces'):
        XPBDCloth(flat, np.array([0]), XPBDSettings())


def test_a_garment_with_a_split_seam_is_welded_with_a_warning_and_simulates():
    require('anny')
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.garment import garment_on_body
    from swingar_pyg.world.garment_assets import fit_shipped_garment
    from swingar_pyg.world.motion import procedural_motion
    from swingar_pyg.world.sequence import simulate_sequence

    body = AnnyBody()
    shape = body.default_shape()
    trousers = fit_shipped_garment('trousers', body, shape)
    x = trousers.mesh.vertices[:, 0]
    left = x < np.median(x)  # duplicate every vertex of the left leg's faces' corners
    faces = trousers.mesh.faces.copy()
    on_left = left[faces].all(axis=1)
    copy = np.arange(trousers.mesh.num_vertices) + trousers.mesh.num_vertices
    faces[on_left] = copy[faces[on_left]]
    split = as_mesh(np.concatenate([trousers.mesh.vertices] * 2), faces)
    pinned = np.concatenate([trousers.pinned, copy[trousers.pinned]])
    with pytest.warns(UserWarning, match=r"garment 'split': merged \d+ coincident vertices"):
        garment = garment_on_body('split', split, body, shape, pinned=pinned)
    assert garment.mesh.num_vertices == trousers.mesh.num_vertices
    assert np.array_equal(garment.pinned, np.sort(trousers.pinned))
    motion = procedural_motion('walk', body.joint_names, seconds=0.1)
    settings = XPBDSettings(fps=motion.fps, substeps=20, iterations=1, settle_frames=1,
                            backend='warp')
    result = simulate_sequence(body, shape, garment, motion, settings).result
    assert torch.isfinite(result.positions).all() and result.max_stretch.max() < 0.5


def test_a_garment_in_other_units_or_axes_is_refused_with_the_likely_cause():
    require('anny')
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.garment import garment_on_body
    from swingar_pyg.world.garment_assets import fit_shipped_garment

    body = AnnyBody()
    shape = body.default_shape()
    top = fit_shipped_garment('sport_top', body, shape).mesh
    in_decimetres = as_mesh(top.vertices * 10.0, top.faces)
    with pytest.raises(ValueError, match=r"'top' is .* m across .* metres, \+Z up.*decimetres"):
        garment_on_body('top', in_decimetres, body, shape)
    y_up_at_the_feet = as_mesh(top.vertices[:, [0, 2, 1]] + [0.0, 0.0, -1.5], top.faces)
    with pytest.raises(ValueError, match=r"'top' lies away from the rest body: 0% of its"):
        garment_on_body('top', y_up_at_the_feet, body, shape)
    assert garment_on_body('top', top, body, shape).mesh.num_vertices == top.num_vertices
