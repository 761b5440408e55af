"""Procedural meshes: rectangular sheets as regular or irregular triangulations."""

from __future__ import annotations

import numpy as np

from swingar_pyg.geometry.mesh import Mesh, as_mesh


def sheet(rows: int, cols: int, width: float = 1.0, height: float = 1.0,
          jitter: float = 0.0, seed: int = 0) -> Mesh:
    """A flat ``width × height`` sheet in the ``z = 0`` plane, ``rows × cols``
    vertices, each grid cell split into two triangles.

    Args:
        jitter: moves interior vertices by up to this fraction of a cell and
            flips the diagonal of random cells, for an irregular triangulation
            with the same vertex count.
        seed: seed of the jitter.
    """
    if rows < 2 or cols < 2:
        raise ValueError(f"a sheet needs at least 2 x 2 vertices, got {rows} x {cols}")
    if not 0.0 <= jitter < 0.5:
        raise ValueError(f"jitter must be in [0, 0.5), got {jitter}")
    u, v = np.meshgrid(np.linspace(0.0, width, cols), np.linspace(0.0, height, rows))
    vertices = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    index = np.arange(rows * cols).reshape(rows, cols)
    corners = (index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1])
    flip = np.zeros(corners[0].shape, dtype=bool)
    if jitter > 0:
        rng = np.random.default_rng(seed)
        interior = np.zeros((rows, cols), dtype=bool)
        interior[1:-1, 1:-1] = True
        cell = np.array([width / (cols - 1), height / (rows - 1)])
        offsets = rng.uniform(-jitter, jitter, size=(interior.sum(), 2)) * cell
        vertices[interior.ravel(), :2] += offsets
        flip = rng.random(flip.shape) < 0.5
    return as_mesh(vertices, split_quads(*corners, flip))


def split_quads(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                flip: np.ndarray) -> np.ndarray:
    """Two triangles per quad ``(a, b, c, d)`` (corner index arrays of one shape, in
    order around the quad): split along ``a-c``, or along ``b-d`` where ``flip``.
    Returns ``(2 * quads, 3)`` faces keeping the quads' orientation."""
    a, b, c, d, flip = (np.ravel(x) for x in (a, b, c, d, flip))
    first = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    second = np.where(flip[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1))
    return np.concatenate([first, second])


def roll_into_cylinder(mesh: Mesh, radius: float) -> Mesh:
    """Bends a sheet lying in ``z = 0`` around the ``y`` axis: ``x`` becomes arc
    length on a cylinder of ``radius``. Lengths along the surface are kept
    (an isometry of the continuous sheet; straight edges become chords)."""
    x, y = mesh.vertices[:, 0], mesh.vertices[:, 1]
    angle = x / radius
    vertices = np.stack([radius * np.sin(angle), y, radius * (1.0 - np.cos(angle))], axis=1)
    return as_mesh(vertices, mesh.faces)
