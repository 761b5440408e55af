import numpy as np
import pytest

from swingar_pyg.geometry import (
    as_mesh,
    exact_affinity_spectrum,
    roll_into_cylinder,
    sheet,
    spectral_descriptor,
)

SIGMA = 0.1


def relative_error(approx, exact, k):
    return np.max(np.abs(approx[:k] - exact[:k]) / np.abs(exact[:k]))


def rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def disjoint_union(*meshes):
    offsets = np.cumsum([0] + [m.num_vertices for m in meshes])
    vertices = np.concatenate([m.vertices + [3.0 * k, 0, 0] for k, m in enumerate(meshes)])
    faces = np.concatenate([m.faces + offsets[k] for k, m in enumerate(meshes)])
    return as_mesh(vertices, faces)


@pytest.fixture(scope='module')
def irregular_sheet():
    return sheet(25, 25, width=1.0, height=1.0, jitter=0.3, seed=0)


@pytest.fixture(scope='module')
def exact(irregular_sheet):
    return exact_affinity_spectrum(irregular_sheet, sigma=SIGMA)


@pytest.mark.parametrize('weighting', ['voronoi', 'uniform'])
def test_all_samples_give_the_exact_spectrum(irregular_sheet, exact, weighting):
    values, vectors = exact
    n = irregular_sheet.num_vertices
    descriptor = spectral_descriptor(irregular_sheet, z=n, sigma=SIGMA, weighting=weighting,
                                     return_eigenvectors=True)
    assert descriptor.num_valid == n
    assert np.allclose(descriptor.eigenvalues, values, rtol=1e-9, atol=1e-9 * values[0])
    cosines = np.abs(np.sum(descriptor.eigenvectors[:, :8] * vectors[:, :8], axis=0))
    assert np.allclose(cosines, 1.0, atol=1e-8)


def test_nystrom_top_eigenvalues_against_exact(irregular_sheet, exact):
    values, vectors = exact
    voronoi = spectral_descriptor(irregular_sheet, z=256, sigma=SIGMA, return_eigenvectors=True)
    uniform = spectral_descriptor(irregular_sheet, z=256, sigma=SIGMA, weighting='uniform')
    # Measured: 2.1 % (Voronoi) vs 4.8 % (uniform) on top-32 at z = 256 of N = 625.
    assert relative_error(voronoi.eigenvalues, values, 32) < 0.03
    assert relative_error(uniform.eigenvalues, values, 32) > relative_error(
        voronoi.eigenvalues, values, 32)
    top = spectral_descriptor(irregular_sheet, z=128, sigma=SIGMA)
    assert relative_error(top.eigenvalues, values, 16) < 0.05
    # Leading eigenvectors: unit norm and in the exact leading subspace (2 and 3 are a
    # near-degenerate pair of the square sheet, so individual vectors may mix).
    in_subspace = np.linalg.norm(vectors[:, :4].T @ voronoi.eigenvectors[:, :4], axis=0)
    assert (in_subspace > 0.98 * np.linalg.norm(voronoi.eigenvectors[:, :4], axis=0)).all()
    assert np.allclose(np.linalg.norm(voronoi.eigenvectors[:, :4], axis=0), 1.0, atol=0.05)


def test_sorted_descending_and_seeded(irregular_sheet):
    descriptor = spectral_descriptor(irregular_sheet, z=64, sigma=SIGMA, seed=3)
    assert np.all(np.diff(descriptor.eigenvalues) <= 0)
    again = spectral_descriptor(irregular_sheet, z=64, sigma=SIGMA, seed=3)
    assert np.array_equal(descriptor.eigenvalues, again.eigenvalues)


def test_invariant_to_rigid_motion(irregular_sheet):
    moved = as_mesh(irregular_sheet.vertices @ rotation(7).T + [3.0, -2.0, 10.0],
                    irregular_sheet.faces)
    a = spectral_descriptor(irregular_sheet, z=64, sigma=SIGMA)
    b = spectral_descriptor(moved, z=64, sigma=SIGMA)
    assert np.allclose(a.eigenvalues, b.eigenvalues, rtol=1e-9, atol=1e-9 * a.eigenvalues[0])


def test_nearly_invariant_to_bending_but_not_to_stretching():
    flat = sheet(30, 10, width=1.5, height=0.5)
    rolled = roll_into_cylinder(flat, radius=0.3)
    stretched = as_mesh(flat.vertices * [1.2, 1.0, 1.0], flat.faces)
    a, b, c = (spectral_descriptor(m, z=128, sigma=SIGMA).eigenvalues
               for m in (flat, rolled, stretched))
    assert relative_error(b, a, 32) < 0.03  # measured 1.5 %; straight edges become chords
    assert relative_error(c, a, 32) > 0.1


def test_normalized_descriptor_depends_little_on_resolution():
    coarse, fine = sheet(20, 20, jitter=0.2), sheet(40, 40, jitter=0.2)
    raw = [spectral_descriptor(m, z=128, sigma=SIGMA).eigenvalues for m in (coarse, fine)]
    normalized = [spectral_descriptor(m, z=128, sigma=SIGMA, normalize=True).eigenvalues
                  for m in (coarse, fine)]
    assert relative_error(raw[0], raw[1], 8) > 0.7  # 4x the vertices, ~4x the eigenvalues
    assert relative_error(normalized[0], normalized[1], 8) < 0.1


def test_fewer_vertices_than_samples_is_padded():
    small = sheet(4, 5)
    descriptor = spectral_descriptor(small, z=64, sigma=SIGMA, return_eigenvectors=True)
    values, _ = exact_affinity_spectrum(small, sigma=SIGMA)
    assert descriptor.eigenvalues.shape == (64,) and descriptor.num_valid == 20
    assert np.allclose(descriptor.eigenvalues[:20], values)
    assert np.all(descriptor.eigenvalues[20:] == 0)
    assert descriptor.eigenvectors.shape == (20, 20)


def test_disconnected_pieces_give_the_union_of_their_spectra():
    pieces = [sheet(5, 6, jitter=0.2, seed=1), sheet(4, 4, seed=2), sheet(3, 7, seed=3)]
    union = disjoint_union(*pieces)
    descriptor = spectral_descriptor(union, z=union.num_vertices, sigma=0.3)
    expected = np.sort(np.concatenate(
        [exact_affinity_spectrum(p, sigma=0.3)[0] for p in pieces]))[::-1]
    assert np.allclose(descriptor.eigenvalues, expected, atol=1e-9)
    few = spectral_descriptor(union, z=2, sigma=0.3, return_eigenvectors=True)
    assert np.isfinite(few.eigenvalues).all() and np.isfinite(few.eigenvectors).all()


def test_duplicate_vertices_and_zero_area_faces_stay_finite():
    base = sheet(6, 6, jitter=0.2)
    # Split the sheet along a seam: duplicate one column of vertices.
    vertices = np.concatenate([base.vertices, base.vertices[2::6]])
    faces = base.faces.copy()
    seam = {2 + 6 * r: 36 + r for r in range(6)}
    right_side = base.vertices[faces].mean(axis=1)[:, 0] > base.vertices[2, 0]
    faces[right_side] = np.vectorize(lambda i: seam.get(i, i))(faces[right_side])
    degenerate = np.array([[0, 0, 1], [7, 7, 7], [3, 4, 5]])  # repeated and collinear corners
    vertices[5] = (vertices[3] + vertices[4]) / 2
    mesh = as_mesh(vertices, np.concatenate([faces, degenerate]))
    descriptor = spectral_descriptor(mesh, z=16, sigma=SIGMA, return_eigenvectors=True)
    assert np.isfinite(descriptor.eigenvalues).all()
    assert np.isfinite(descriptor.eigenvectors).all()
    welded = spectral_descriptor(mesh, z=mesh.num_vertices, sigma=SIGMA)
    assert np.allclose(welded.eigenvalues, exact_affinity_spectrum(mesh, sigma=SIGMA)[0])


@pytest.mark.parametrize('scale', [1e-6, 1e-3, 1e3, 1e6])
def test_extreme_coordinate_scales(scale):
    mesh = sheet(8, 8, jitter=0.2)
    scaled = as_mesh(mesh.vertices * scale, mesh.faces)
    descriptor = spectral_descriptor(scaled, z=32, sigma=SIGMA, return_eigenvectors=True)
    assert np.isfinite(descriptor.eigenvalues).all()
    assert np.isfinite(descriptor.eigenvectors).all()
    if scale < 1:  # every affinity ~1: rank one, eigenvalue N
        assert np.isclose(descriptor.eigenvalues[0], 64, rtol=1e-3)
        assert np.abs(descriptor.eigenvalues[1:]).max() < 1e-3
    else:  # every affinity ~0 but the diagonal: A = I, and the weights keep trace(A) = N
        assert np.isclose(descriptor.eigenvalues.sum(), 64, rtol=1e-6)


def test_custom_kernel():
    mesh = sheet(10, 10)
    laplace = spectral_descriptor(mesh, z=100, kernel=lambda d: np.exp(-d / 0.2))
    values, _ = exact_affinity_spectrum(mesh, kernel=lambda d: np.exp(-d / 0.2))
    assert np.allclose(laplace.eigenvalues, values)


@pytest.mark.parametrize('kwargs, message', [
    ({'z': 0}, 'z must be >= 1'),
    ({'sigma': 0.0}, 'sigma must be a positive'),
    ({'sigma': float('nan')}, 'sigma must be a positive'),
    ({'kernel': 'cauchy'}, "kernel must be 'gaussian'"),
    ({'weighting': 'area'}, "weighting must be 'voronoi' or 'uniform'"),
    ({'kernel': lambda d: np.full_like(d, np.nan)}, 'non-finite affinities'),
])
def test_bad_arguments_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        spectral_descriptor(sheet(4, 4), **{'z': 8, **kwargs})


def test_exact_spectrum_refuses_huge_meshes():
    with pytest.raises(ValueError, match='GiB'):
        exact_affinity_spectrum(sheet(150, 150))
