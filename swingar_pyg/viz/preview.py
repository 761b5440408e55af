"""Preview images of a body and garment sequence (matplotlib, no OpenGL needed).

Triangles are projected orthographically, sorted back to front (painter's
algorithm) and shaded by their normal, which draws a 30k-triangle body in a
fraction of a second, where matplotlib's 3D axes would take many.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from swingar_pyg.atomic import atomic_path

_BODY_COLOUR = np.array([0.80, 0.72, 0.65])
_GARMENT_COLOUR = np.array([0.25, 0.45, 0.80])


def _view_rotation(azimuth_degrees: float) -> np.ndarray:
    """World (+Z up, body facing -Y) to view (x right, y up, z towards the viewer);
    azimuth 0 looks at the body's front."""
    a = math.radians(azimuth_degrees)
    turn = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                     [0.0, 0.0, 1.0]])
    to_view = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    return to_view @ turn


def _draw(axis, meshes: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
          rotation: np.ndarray) -> None:
    from matplotlib.collections import PolyCollection

    polygons, depths, colours = [], [], []
    light = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    for vertices, faces, colour in meshes:
        view = vertices @ rotation.T
        triangles = view[faces]
        normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True).clip(1e-12)
        shade = 0.35 + 0.65 * np.abs(normals @ light)  # two-sided: cloth has no inside
        polygons.append(triangles[:, :, :2])
        depths.append(triangles[:, :, 2].mean(axis=1))
        colours.append(shade[:, None] * colour[None, :])
    polygons, depths, colours = (np.concatenate(p) for p in (polygons, depths, colours))
    order = np.argsort(depths)
    axis.add_collection(PolyCollection(polygons[order], facecolors=colours[order],
                                       edgecolors="none", antialiased=False))


def render_sequence(path: str | Path, body_vertices: np.ndarray, body_faces: np.ndarray,
                    garment_vertices: np.ndarray, garment_faces: np.ndarray,
                    fps: float = 30.0, every: int = 2, azimuths: tuple[float, ...] = (0.0, 90.0),
                    title: str = "") -> Path:
    """Writes a GIF (or, for a ``.png`` path, one image of the first frame) of a
    body and garment sequence seen from ``azimuths`` side by side.

    Args:
        body_vertices: ``(T, V, 3)``; garment_vertices: ``(T, N, 3)``.
        every: draw every n-th frame (the GIF plays at ``fps / every``).
    """
    # A figure of its own on an Agg canvas: pyplot's global backend (a notebook's
    # inline one) is left as it is.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from PIL import Image

    body_vertices = np.asarray(body_vertices)
    garment_vertices = np.asarray(garment_vertices)
    if body_vertices.shape[0] != garment_vertices.shape[0]:
        raise ValueError(f"body has {body_vertices.shape[0]} frames, garment "
                         f"{garment_vertices.shape[0]}")
    path = Path(path)
    # Each frame is centred on the body (a walk leaves the first frame's view);
    # the scale is the largest single-frame extent, so the size does not jump.
    centres = body_vertices.mean(axis=1)
    half = 0.55 * max(np.ptp(np.concatenate([b, g]), axis=0).max()
                      for b, g in zip(body_vertices, garment_vertices))
    rotations = [_view_rotation(a) for a in azimuths]
    frames = list(range(0, body_vertices.shape[0], max(1, every)))
    if path.suffix.lower() == ".png":
        frames = frames[:1]
    images = []
    for t in frames:
        figure = Figure(figsize=(3.2 * len(azimuths), 4.2), dpi=80)
        FigureCanvasAgg(figure)
        axes = np.atleast_1d(figure.subplots(1, len(azimuths)))
        for axis, rotation, azimuth in zip(axes, rotations, azimuths):
            meshes = [(body_vertices[t] - centres[t], body_faces, _BODY_COLOUR),
                      (garment_vertices[t] - centres[t], garment_faces, _GARMENT_COLOUR)]
            _draw(axis, meshes, rotation)
            axis.set_xlim(-half, half)
            axis.set_ylim(-half, half)
            axis.set_aspect("equal")
            axis.axis("off")
            axis.set_title(f"{azimuth:.0f}°", fontsize=8)
        figure.suptitle(f"{title}  frame {t} ({t / fps:.2f} s)", fontsize=9)
        figure.canvas.draw()
        images.append(Image.fromarray(np.asarray(figure.canvas.buffer_rgba())[..., :3]))
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".png":
            images[0].save(tmp, format="PNG")
        else:
            images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                           duration=int(1000 * every / fps), loop=0)
    return path
