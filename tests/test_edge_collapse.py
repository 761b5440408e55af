import numpy as np
import pytest
import trimesh

from swingar_pyg.geometry import (
    Mesh,
    as_mesh,
    boundary_edges,
    merge_short_edges,
    mesh_edges,
    sheet,
)
from swingar_pyg.geometry.weld import weld_mesh
from swingar_pyg.world.garment_assets import load_shipped_garment, shipped_garments


def edge_lengths(mesh):
    edges = mesh_edges(mesh.faces)
    return np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)


def topology(mesh):
    """Euler characteristic, connected pieces, boundary loops and consistent winding
    (trimesh's own measures, independent of the collapse's bookkeeping)."""
    surface = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    loops = trimesh.graph.connected_components(boundary_edges(mesh.faces))
    return (surface.euler_number, len(surface.split(only_watertight=False)), len(loops),
            surface.is_winding_consistent)


def squeezed_sheet(scale=1.0):
    """An 8 x 9 sheet whose fifth column is moved to within a tenth of a cell of the
    fourth: a row of short edges from the bottom border to the top one."""
    mesh = sheet(8, 9, width=0.8, height=0.7)
    vertices = mesh.vertices.copy()
    column = np.isclose(vertices[:, 0], 0.4)
    vertices[column, 0] = 0.31
    return as_mesh(scale * vertices, mesh.faces), column


def test_short_edges_merge_into_a_sheet_one_column_narrower():
    mesh, column = squeezed_sheet()
    merged, new_index = merge_short_edges(mesh, 0.5)
    assert len(merged.vertices) == len(mesh.vertices) - column.sum()
    assert len(merged.faces) == len(mesh.faces) - 2 * 7  # two triangles a cell of the column
    assert topology(merged) == topology(mesh) == (1, 1, 1, True)
    assert edge_lengths(merged).min() >= 0.5 * np.median(edge_lengths(mesh))
    assert np.allclose(merged.vertices[:, 2], 0.0)  # still the plane
    # each merged pair sits at its midpoint; the border keeps its corners
    pairs = new_index[column] == new_index[np.flatnonzero(column) - 1]
    assert pairs.all()
    assert np.allclose(merged.vertices[new_index[column], 0], 0.305)
    assert np.allclose(np.ptp(merged.vertices[:, :2], axis=0), [0.8, 0.7])
    triangles = merged.vertices[merged.faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    assert (normals[:, 2] > 0).all()  # none turned over


def test_a_run_of_short_edges_merges_into_one_vertex():
    """Two columns squeezed beside a third: merging the first short edge of a row makes a
    new short edge to the next column, which merges in turn."""
    mesh = sheet(8, 9, width=0.8, height=0.7)
    vertices = mesh.vertices.copy()
    squeezed = np.isclose(vertices[:, 0], 0.4) | np.isclose(vertices[:, 0], 0.5)
    vertices[np.isclose(vertices[:, 0], 0.4), 0] = 0.31
    vertices[np.isclose(vertices[:, 0], 0.5), 0] = 0.32
    merged, _ = merge_short_edges(as_mesh(vertices, mesh.faces), 0.5)
    assert len(merged.vertices) == len(vertices) - squeezed.sum()
    assert topology(merged) == (1, 1, 1, True)


def test_a_boundary_end_keeps_its_place():
    mesh = sheet(6, 6, width=0.5, height=0.5)
    vertices = mesh.vertices.copy()
    inner = np.flatnonzero(np.isclose(vertices[:, 0], 0.1) & np.isclose(vertices[:, 1], 0.2))
    vertices[inner, 0] = 0.01  # 1 cm from the left border's vertex at (0, 0.2)
    merged, new_index = merge_short_edges(as_mesh(vertices, mesh.faces), 0.5)
    border = np.flatnonzero(np.isclose(vertices[:, 0], 0.0) & np.isclose(vertices[:, 1], 0.2))
    assert new_index[inner] == new_index[border]
    assert np.allclose(merged.vertices[new_index[border]], vertices[border])


def test_a_thin_strip_is_not_pinched():
    """Every rung of a 1 mm strip is short, but the inner rungs join two stretches of the
    border: merging one would pinch the strip, so only the two end rungs (border edges
    themselves) merge."""
    mesh = sheet(2, 20, width=1.0, height=0.001)
    merged, new_index = merge_short_edges(mesh, 0.5)
    assert len(merged.vertices) == 38 and topology(merged) == topology(mesh)
    assert new_index[0] == new_index[20] and new_index[19] == new_index[39]
    assert (new_index[1:19] != new_index[21:39]).all()


@pytest.mark.parametrize('scale', [1e-6, 1e6])
def test_the_merge_does_not_depend_on_scale(scale):
    mesh, _ = squeezed_sheet()
    small_or_huge, _ = squeezed_sheet(scale)
    merged, index = merge_short_edges(mesh, 0.5)
    scaled, scaled_index = merge_short_edges(small_or_huge, 0.5)
    assert np.array_equal(scaled.faces, merged.faces) and np.array_equal(scaled_index, index)
    assert np.allclose(scaled.vertices, scale * merged.vertices, rtol=1e-9)


def test_a_mesh_without_short_edges_is_left_as_it_is():
    mesh = sheet(5, 6, width=0.5, height=0.4)
    merged, new_index = merge_short_edges(mesh, 0.5)
    assert np.array_equal(merged.faces, mesh.faces)
    assert np.array_equal(merged.vertices, mesh.vertices)
    assert np.array_equal(new_index, np.arange(len(mesh.vertices)))


@pytest.mark.parametrize('ratio', [0.0, 1.0, -0.5, float('nan')])
def test_a_ratio_outside_zero_one_is_refused(ratio):
    with pytest.raises(ValueError, match='ratio must be in'):
        merge_short_edges(sheet(3, 3), ratio)


def test_bad_meshes_are_refused():
    mesh, _ = squeezed_sheet()
    vertices = mesh.vertices.copy()
    vertices[3] = np.nan
    with pytest.raises(ValueError, match='not finite'):
        merge_short_edges(Mesh(vertices, mesh.faces), 0.5)
    unwelded = as_mesh(mesh.vertices, np.concatenate([mesh.faces, [[0, 0, 1]]]))
    with pytest.raises(ValueError, match='zero-area faces.*weld it first'):
        merge_short_edges(unwelded, 0.5)


def test_a_tetrahedron_and_a_lone_triangle_are_kept():
    """Each short edge passes the vertex part of the link condition but would fold a
    tetrahedron flat (two copies of one face) or delete a triangle standing alone."""
    tetrahedron = as_mesh([[0, 0, 0], [0.05, 0, 0], [0.5, 1, 0], [0.5, 0.4, 1]],
                          [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    merged, new_index = merge_short_edges(tetrahedron, 0.5)
    assert np.array_equal(merged.faces, tetrahedron.faces)
    mesh = sheet(5, 5)
    lone = [[3, 0, 0], [3.01, 0, 0], [3, 0.3, 0]]
    both = as_mesh(np.concatenate([mesh.vertices, lone]),
                   np.concatenate([mesh.faces, [[25, 26, 27]]]))
    merged, _ = merge_short_edges(both, 0.5)
    assert np.array_equal(merged.faces, both.faces) and topology(merged) == (2, 2, 2, True)


def fan(far_corner):
    """Six triangles around an interior vertex ``a`` (vertex 0) whose shortest edge, the
    only one under 0.7 times the median, runs to ``b = (0.1, 0)`` on the border; the
    thin triangle ``(a, d, e)`` has its far corner ``e`` at ``far_corner``."""
    corners = [[0, 0], [0.1, 0], [0.13, 0.13], [0.01, 0.12], far_corner, [-0.15, -0.1],
               [0.1, -0.12]]
    mesh = as_mesh(np.pad(np.array(corners, float), ((0, 0), (0, 1))),
                   [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 6], [0, 6, 1]])
    lengths = edge_lengths(mesh)
    assert lengths.min() == pytest.approx(0.1) and (lengths < 0.7 * np.median(lengths)).sum() == 1
    return mesh


@pytest.mark.parametrize('far_corner, what', [
    ([-0.04, 0.24], 'turned over'),  # past the line through b and d
    ([-0.08 - 2e-5, 0.24], 'a sliver'),  # 2e-5 m off it: (b, d, e) keeps 0.02 % of its area
])
def test_a_merge_that_would_turn_a_triangle_over_or_to_a_sliver_is_refused(far_corner, what):
    """Moving ``a`` onto ``b`` would leave ``(b, d, e)`` {what}."""
    mesh = fan(far_corner)
    merged, new_index = merge_short_edges(mesh, 0.7)
    assert np.array_equal(merged.faces, mesh.faces)
    assert np.array_equal(new_index, np.arange(7))


def test_the_fan_merges_once_the_far_corner_is_out_of_the_way():
    mesh = fan([-0.25, 0.1])
    merged, new_index = merge_short_edges(mesh, 0.7)
    assert len(merged.vertices) == 6 and new_index[0] == new_index[1]
    assert np.allclose(merged.vertices[new_index[0]], mesh.vertices[1])  # onto the border
    triangles = merged.vertices[merged.faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    assert (normals[:, 2] > 0).all()


def test_a_closed_surface_and_several_pieces_keep_their_topology():
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    vertices = ball.vertices.copy()
    rng = np.random.default_rng(0)
    edges = ball.edges_unique[rng.choice(len(ball.edges_unique), 10, replace=False)]
    vertices[edges[:, 1]] = 0.9 * vertices[edges[:, 0]] + 0.1 * vertices[edges[:, 1]]
    squeezed, _ = squeezed_sheet()
    pieces = as_mesh(np.concatenate([vertices, squeezed.vertices + [2, 0, 0]]),
                     np.concatenate([ball.faces, squeezed.faces + len(vertices)]))
    merged, new_index = merge_short_edges(pieces, 0.5)
    assert topology(merged) == topology(pieces) == (3, 2, 1, True)
    assert len(merged.vertices) < len(pieces.vertices) - 8
    sorted_faces = np.sort(merged.faces, axis=1)
    assert len(np.unique(sorted_faces, axis=0)) == len(merged.faces)  # no doubled face
    assert (sorted_faces[:, 0] != sorted_faces[:, 1]).all() and (
        sorted_faces[:, 1] != sorted_faces[:, 2]).all()  # no corner repeated
    ball_part = trimesh.Trimesh(merged.vertices, merged.faces, process=False).split(
        only_watertight=True)
    assert len(ball_part) == 1 and ball_part[0].is_watertight


@pytest.mark.parametrize('name', shipped_garments())
def test_the_shipped_garments_keep_their_topology(name):
    mesh = weld_mesh(load_shipped_garment(name))[0]
    merged, new_index = merge_short_edges(mesh, 0.5)
    assert topology(merged) == topology(mesh)
    assert edge_lengths(merged).min() > edge_lengths(mesh).min()
    assert len(merged.vertices) < len(mesh.vertices)
    # every old vertex went to a new vertex close by (a chain of merges moves it by at
    # most a few short edges)
    moved = np.linalg.norm(merged.vertices[new_index] - mesh.vertices, axis=1)
    assert moved.max() <= 2 * np.median(edge_lengths(mesh))
