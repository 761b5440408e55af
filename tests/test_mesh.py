import numpy as np
import pytest
import torch

from swingar_pyg.geometry import (
    as_mesh,
    boundary_edges,
    edge_length_graph,
    farthest_point_sampling,
    geodesic_distances,
    load_mesh,
    mesh_edge_index,
    mesh_edges,
    sheet,
    vertex_normals,
)

TRIANGLE = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])


@pytest.mark.parametrize('vertices, faces, message', [
    (np.zeros((0, 3)), np.zeros((0, 3), int), 'no vertices'),
    (TRIANGLE, np.zeros((0, 3), int), 'no faces'),
    (TRIANGLE[:, :2], [[0, 1, 2]], r'shape \(N, 3\)'),
    (TRIANGLE, [[0, 1]], r'shape \(F, 3\)'),
    (TRIANGLE, [[0, 1, 5]], 'faces index vertex 5 but the mesh has 3 vertices'),
    (TRIANGLE, [[0, -1, 2]], 'faces index vertex -1'),
    (TRIANGLE, [[0, 1.5, 2]], 'integer vertex indices'),
    (np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), [[0, 1, 2]], 'not finite.*vertex 0'),
    (np.array([[0, 0, 0], [np.inf, 0, 0], [0, 1, 0]]), [[0, 1, 2]], 'not finite.*vertex 1'),
])
def test_as_mesh_rejects_bad_input(vertices, faces, message):
    with pytest.raises(ValueError, match=message):
        as_mesh(vertices, faces)


def test_as_mesh_splits_quads_and_accepts_trimesh():
    import trimesh

    quad = as_mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]])
    assert quad.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    box = trimesh.creation.box()
    mesh = as_mesh(box)
    assert mesh.num_vertices == len(box.vertices) and mesh.num_faces == len(box.faces)
    assert as_mesh(mesh) is mesh


def test_load_mesh_keeps_vertex_order(tmp_path):
    mesh = sheet(3, 4, jitter=0.2)
    path = tmp_path / 'sheet.obj'
    path.write_text(''.join(f'v {x} {y} {z}\n' for x, y, z in mesh.vertices) +
                    ''.join(f'f {a + 1} {b + 1} {c + 1}\n' for a, b, c in mesh.faces))
    loaded = load_mesh(path)
    assert np.allclose(loaded.vertices, mesh.vertices)
    assert np.array_equal(loaded.faces, mesh.faces)


def test_edges_are_unique_undirected_and_skip_degenerate_faces():
    faces = np.array([[0, 1, 2], [2, 1, 3], [3, 3, 1]])  # last face is degenerate
    mesh = as_mesh(np.random.rand(4, 3), faces)
    assert mesh_edges(mesh.faces).tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]
    edge_index = mesh_edge_index(mesh)
    assert edge_index.shape == (2, 10)
    pairs = set(map(tuple, edge_index.t().tolist()))
    assert all((j, i) in pairs for i, j in pairs)
    assert torch.equal(edge_index, edge_index[:, torch.argsort(edge_index[0] * 4 + edge_index[1])])


def test_sheet_euler_characteristic():
    for jitter in (0.0, 0.3):
        mesh = sheet(7, 9, jitter=jitter)
        edges = mesh_edges(mesh.faces)
        assert mesh.num_vertices - len(edges) + mesh.num_faces == 1  # a disc


def test_vertex_normals_against_face_normals():
    # A tetrahedron-like fan: normal of the apex is the area-weighted mean of its faces.
    vertices = torch.tensor([[0.0, 0, 1], [1, 0, 0], [0, 2, 0], [-1, -1, 0]], dtype=torch.float64)
    faces = torch.tensor([[0, 1, 2], [0, 2, 3], [0, 3, 1]])
    normals = vertex_normals(vertices, faces)
    face_cross = torch.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                             vertices[faces[:, 2]] - vertices[faces[:, 0]], dim=-1)
    expected = face_cross.sum(0) / face_cross.sum(0).norm()
    assert torch.allclose(normals[0], expected)
    assert torch.allclose(normals.norm(dim=-1), torch.ones(4, dtype=torch.float64))


@pytest.mark.parametrize('scale', [1e-20, 1e-3, 1.0, 1e3, 1e20])
@pytest.mark.parametrize('dtype', [torch.float32, torch.float16, torch.bfloat16])
def test_vertex_normals_at_extreme_scales_and_precisions(scale, dtype):
    mesh = sheet(4, 4, jitter=0.2)
    vertices = torch.from_numpy(mesh.vertices).to(dtype)
    faces = torch.from_numpy(mesh.faces)
    if not torch.isfinite(vertices * scale).all() or (vertices * scale == 0).all():
        pytest.skip(f'{scale} is outside the range of {dtype}')
    normals = vertex_normals(vertices * scale, faces)
    assert normals.dtype == dtype and torch.isfinite(normals).all()
    assert torch.allclose(normals.float(), torch.tensor([0.0, 0, 1]).expand(16, 3), atol=1e-2)


def test_vertex_normals_batched_and_degenerate():
    vertices = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [5, 5, 5]])
    faces = torch.tensor([[0, 1, 2], [0, 1, 3]])  # second face has zero area; vertex 4 isolated
    normals = vertex_normals(torch.stack([vertices, 2 * vertices]), faces)
    assert normals.shape == (2, 5, 3) and torch.isfinite(normals).all()
    assert torch.allclose(normals[:, :3], torch.tensor([0.0, 0, 1]).expand(2, 3, 3))
    assert torch.equal(normals[:, 4], torch.zeros(2, 3))
    assert torch.allclose(normals[:, 3], torch.zeros(2, 3))
    grad_input = vertices.clone().requires_grad_()
    vertex_normals(grad_input, faces).sum().backward()
    assert torch.isfinite(grad_input.grad).all()


def test_geodesic_distances_on_a_regular_sheet():
    # Along grid lines of a unit-spaced sheet, geodesic = number of edges.
    mesh = sheet(5, 6, width=5.0, height=4.0)
    distances = geodesic_distances(edge_length_graph(mesh), 0)
    assert distances.shape == (1, 30)
    assert np.isclose(distances[0, 5], 5.0) and np.isclose(distances[0, 24], 4.0)
    # Diagonal edges: the far corner is 4 diagonals + 1 straight step away.
    assert np.isclose(distances[0, 29], 4 * np.sqrt(2) + 1)


def test_duplicate_vertices_are_welded_and_components_stay_apart():
    left = sheet(3, 3)
    right = sheet(3, 3)
    # Right sheet shares its left column with the left sheet's right column (a seam),
    # plus a third piece far away.
    far = sheet(3, 3)
    vertices = np.concatenate([left.vertices, right.vertices + [1, 0, 0],
                               far.vertices + [10, 0, 0]])
    faces = np.concatenate([left.faces, right.faces + 9, far.faces + 18])
    mesh = as_mesh(vertices, faces)
    distances = geodesic_distances(edge_length_graph(mesh), 0)[0]
    assert np.isclose(distances[9 + 2], 2.0)  # across the seam
    assert np.isinf(distances[18:]).all()
    assert np.isfinite(distances[:18]).all()
    unwelded = geodesic_distances(edge_length_graph(mesh, weld_tolerance=0.0), 0)[0]
    assert np.isinf(unwelded[9:]).all()


def test_farthest_point_sampling_reaches_every_component_first():
    pieces = [sheet(4, 4), sheet(3, 3), sheet(5, 2)]
    offsets = np.cumsum([0] + [p.num_vertices for p in pieces])
    vertices = np.concatenate([p.vertices + [5 * k, 0, 0] for k, p in enumerate(pieces)])
    faces = np.concatenate([p.faces + offsets[k] for k, p in enumerate(pieces)])
    graph = edge_length_graph(as_mesh(vertices, faces))
    indices, distances = farthest_point_sampling(graph, 3, seed=4)
    assert sorted(np.searchsorted(offsets, indices, side='right') - 1) == [0, 1, 2]
    assert np.array_equal(distances, geodesic_distances(graph, indices))


def test_farthest_point_sampling_is_seeded_and_spread():
    graph = edge_length_graph(sheet(6, 6))
    first, _ = farthest_point_sampling(graph, 4, seed=1)
    assert np.array_equal(first, farthest_point_sampling(graph, 4, seed=1)[0])
    assert len(set(first.tolist())) == 4
    # Each sample is the vertex farthest from all earlier ones (all-pairs reference).
    all_pairs = geodesic_distances(graph, np.arange(36))
    samples, _ = farthest_point_sampling(graph, 8, seed=14)
    for k in range(1, 8):
        nearest = all_pairs[samples[:k]].min(axis=0)
        assert np.isclose(nearest[samples[k]], nearest.max())
    everything, _ = farthest_point_sampling(graph, 100)
    assert sorted(everything.tolist()) == list(range(36))
    with pytest.raises(ValueError, match='num_samples must be >= 1'):
        farthest_point_sampling(graph, 0)


def test_boundary_edges_are_the_open_border():
    mesh = sheet(4, 5)
    border = boundary_edges(mesh.faces)
    # A 4 x 5 grid's border has 2 * (3 + 4) edges, all on the outer rows and columns.
    assert len(border) == 14
    on_border = np.zeros(20, bool)
    on_border[np.arange(20).reshape(4, 5)[[0, -1]].ravel()] = True
    on_border[np.arange(20).reshape(4, 5)[:, [0, -1]].ravel()] = True
    assert on_border[border].all()
    closed = as_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                     [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    assert len(boundary_edges(closed.faces)) == 0
