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


@pytest.mark.parametrize('ratio', [0.0, 1.0, -0.5, float('nan')])
def test_a_ratio_outside_zero_one_is_refused(ratio):
    with pytest.raises(ValueError, match='ratio must be in'):
        merge_short_edges(sheet(3, 3), ratio)


def test_bad_meshes_are_refused_and_zero_area_faces_left_alone():
    mesh, _ = squeezed_sheet()
    vertices = mesh.vertices.copy()
    vertices[3] = np.nan
    with pytest.raises(ValueError, match='not finite'):
        merge_short_edges(Mesh(vertices, mesh.faces), 0.5)
    # a face repeating a vertex (unwelded input): the edges around it stay, the rest merge
    faces = np.concatenate([mesh.faces, [[0, 0, 1]]])
    merged, _ = merge_short_edges(as_mesh(mesh.vertices, faces), 0.5)
    assert len(merged.vertices) == len(mesh.vertices) - 8 and np.isfinite(merged.vertices).all()


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
