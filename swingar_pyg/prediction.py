"""``swingar predict --ckpt … --garment … --motion …``: a trained estimator
animates any garment mesh on any motion, and the frames are exported.

The garment need not come from the training data: any mesh dressed on the
body's rest pose (metres, +Z up) gets its graph, normals, fit attribute,
transferred skinning and descriptor here, then the motion is streamed through
:class:`~swingar_pyg.models.SwinGarStream` one frame at a time.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.models import GarmentWindow, SwinGarEstimator
from swingar_pyg.models.garment_window import dense_skinning_weights, garment_graph_features


def garment_graph(garment, num_joints: int, descriptor_size: int | None,
                  sigma: float = 0.1, seed: int = 0) -> GarmentWindow:
    """The estimator's garment inputs (``rest``, ``normal``, ``fit``,
    ``prior_weights``, ``edge_index``, ``descriptor``) for a
    :class:`~swingar_pyg.world.garment.Garment`, computed as the datamodule's
    feature cache computes them."""
    mesh = garment.mesh
    features = garment_graph_features(mesh, descriptor_size, sigma, seed)
    graph = GarmentWindow(
        rest=torch.as_tensor(mesh.vertices, dtype=torch.float32), normal=features["normal"],
        fit=torch.as_tensor(garment.fit, dtype=torch.float32),
        prior_weights=dense_skinning_weights(garment.skin_indices, garment.skin_weights,
                                             num_joints),
        edge_index=features["edge_index"], num_nodes=mesh.num_vertices)
    if "descriptor" in features:
        graph.descriptor = features["descriptor"][None]
    return graph


def animate(estimator: SwinGarEstimator, graph: GarmentWindow, body_shape: torch.Tensor,
            rotations: torch.Tensor, translation: torch.Tensor, joint_transforms: torch.Tensor,
            joint_positions: torch.Tensor, fps: float,
            progress: bool = True) -> tuple[torch.Tensor, np.ndarray]:
    """Streams a posed motion; returns the garment ``(T, N, 3)`` and the
    seconds each frame took."""
    stream = estimator.stream(graph, body_shape, fps)
    frames = range(len(rotations))
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, desc="estimator", unit="frame")
    out, seconds = [], []
    for t in frames:
        start = time.perf_counter()
        out.append(stream.step(rotations[t], translation[t], joint_transforms[t],
                               joint_positions[t]))
        seconds.append(time.perf_counter() - start)
    return torch.stack(out), np.asarray(seconds)


def load_estimator(checkpoint: str | Path) -> tuple[SwinGarEstimator, dict]:
    """The estimator of a ``swingar fit`` checkpoint (in eval mode), and the
    hyperparameters of the datamodule it was trained with (descriptor settings)."""
    from swingar_pyg.training import SwinGarModule

    if not Path(checkpoint).is_file():
        raise ValueError(f"no checkpoint at {checkpoint}")
    saved = torch.load(checkpoint, map_location="cpu", weights_only=False)
    module = SwinGarModule.load_from_checkpoint(checkpoint, map_location="cpu")
    return module.estimator.eval(), saved.get("datamodule_hyper_parameters", {})


def _load_garment(source: str, body, shape):
    from swingar_pyg.geometry import load_mesh
    from swingar_pyg.world.garment import garment_on_body
    from swingar_pyg.world.garment_assets import fit_shipped_garment, shipped_garments

    if source in shipped_garments():
        return fit_shipped_garment(source, body, shape)
    if not Path(source).is_file():
        raise ValueError(f"--garment {source!r} is neither a file nor a shipped garment "
                         f"({', '.join(shipped_garments())})")
    return garment_on_body(Path(source).stem, load_mesh(source), body, shape)


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A Wavefront OBJ of one frame, written atomically."""
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def correct_collisions(vertices: np.ndarray, edge_index: torch.Tensor, posed,
                       body_faces: torch.Tensor, neural=None,
                       progress: bool = True) -> tuple[np.ndarray, dict]:
    """Moves garment vertices out of the posed body (a
    :class:`~swingar_pyg.world.body.PosedBody`), frame by frame, with
    :func:`~swingar_pyg.collision.resolve_collisions`: through the neural body
    SDF if ``neural`` (:class:`~swingar_pyg.collision.NeuralCollisions`) is
    given, else the exact one. Returns the corrected frames and counts of
    vertices inside before and after (by the exact SDF) and of those moved."""
    from swingar_pyg.collision import exact_signed_distance, resolve_collisions

    frames = range(len(vertices))
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, desc="collisions", unit="frame")
    out, moved, before, after, seconds = vertices.copy(), 0, 0, 0, []
    for t in frames:
        exact = exact_signed_distance(posed.vertices[t], body_faces)
        x = torch.as_tensor(vertices[t], dtype=torch.float64)
        before += int((exact(x)[0] > 0).sum())
        start = time.perf_counter()
        if neural is None:
            result = resolve_collisions(x, edge_index, exact)
        else:
            result = neural.correct(x.float(), edge_index, posed.joint_transforms[t],
                                    posed.joint_positions[t])
        seconds.append(time.perf_counter() - start)
        corrected = result.vertices.double()
        after += int((exact(corrected)[0] > 0).sum())
        moved += int(result.moved.sum())
        out[t] = corrected.numpy()
    return out, {"sdf": "exact" if neural is None else "neural", "inside_before": before,
                 "inside_after": after, "moved": moved,
                 "vertex_frames": int(vertices.shape[0] * vertices.shape[1]),
                 "ms_per_frame_median": 1e3 * float(np.median(seconds))}


def predict_to_folder(checkpoint: str, garment: str, motion: str, out: str | Path,
                      body_shape: list[float] | None = None, seconds: float | None = None,
                      preview: bool = True, progress: bool = True,
                      collisions: bool = True, body_sdf: str | None = None) -> dict:
    """Animates ``garment`` (a mesh file or a shipped garment name) on ``motion``
    (a procedural family, a shipped clip or a ``.bvh`` path) and writes to
    ``out``: ``frames/frame_0000.obj`` …, ``garment.npz`` (all frames, faces,
    body shape, per-frame seconds), ``preview.gif`` and ``summary.json``. With
    ``collisions``, vertices inside the body are moved out: by the neural body
    SDF of the checkpoint ``body_sdf`` if given, else by the exact one."""
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.motion_library import make_motion

    estimator, data_settings = load_estimator(checkpoint)
    body = AnnyBody()
    shape = body.default_shape() if body_shape is None else torch.tensor(body_shape)
    fitted = _load_garment(garment, body, shape)
    clip = make_motion(motion, body, shape, seconds=seconds)
    posed = body.pose(shape, clip.rotations, clip.translation)
    graph = garment_graph(fitted, len(body.joint_names), estimator.descriptor_size,
                          sigma=data_settings.get("sigma", 0.1), seed=data_settings.get("seed", 0))
    vertices, frame_seconds = animate(estimator, graph, shape, clip.rotations, clip.translation,
                                      posed.joint_transforms, posed.joint_positions, clip.fps,
                                      progress)
    vertices = vertices.numpy()
    if not np.isfinite(vertices).all():
        raise ValueError("the estimator produced non-finite vertices; the checkpoint or the "
                         "inputs are broken")
    collision_counts = None
    if collisions:
        neural = None
        if body_sdf is not None:
            from swingar_pyg.collision import NeuralCollisions

            neural = NeuralCollisions.from_checkpoint(body_sdf, body, shape)
        vertices, collision_counts = correct_collisions(vertices, graph.edge_index, posed,
                                                        body.faces, neural, progress)
    out = Path(out)
    faces = fitted.mesh.faces
    for t, frame in enumerate(vertices):
        write_obj(out / "frames" / f"frame_{t:04d}.obj", frame, faces)
    with atomic_path(out / "garment.npz") as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, vertices=vertices, faces=faces,
                                body_shape=shape.numpy(), seconds_per_frame=frame_seconds,
                                fps=clip.fps)
    if preview:
        from swingar_pyg.viz.preview import render_sequence

        render_sequence(out / "preview.gif", posed.vertices.numpy(), body.faces.numpy(),
                        vertices, faces, fps=clip.fps, title=f"{fitted.name} / {clip.name}")
    summary = {"garment": fitted.name, "vertices": int(fitted.mesh.num_vertices),
               "motion": clip.name, "frames": int(len(vertices)),
               "ms_per_frame_median": 1e3 * float(np.median(frame_seconds[1:]))
               if len(frame_seconds) > 1 else 1e3 * float(frame_seconds[0]),
               "checkpoint": str(checkpoint), "collisions": collision_counts}
    with atomic_path(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary
