"""``swingar predict --ckpt … --garment … --motion …``: a trained estimator
animates any garment mesh on any motion, and the frames are exported.

The garment need not come from the training data: any mesh dressed on the
body's rest pose (metres, +Z up) gets its graph, normals, fit attribute,
transferred skinning and descriptor here, then the motion is streamed through
:class:`~swingar_pyg.inference.SwinGarStream` one frame at a time.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.geometry import BodySurface, load_mesh
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.inference.export import (
    check_writers,
    parse_formats,
    write_obj,
    write_pc2,
    write_usd,
)
from swingar_pyg.inference.scene import Scene, compile_scene
from swingar_pyg.inference.streaming import SwinGarStream
from swingar_pyg.models import BodySDF, GarmentWindow, SwinGarEstimator
from swingar_pyg.models.garment_window import garment_graph_features
from swingar_pyg.viz.preview import render_sequence
from swingar_pyg.world.body import AnnyBody
from swingar_pyg.world.garment import garment_on_body
from swingar_pyg.world.garment_assets import fit_shipped_garment, shipped_garments
from swingar_pyg.world.motion_library import make_motion


def garment_graph(garment, num_joints: int, descriptor_size: int | None,
                  sigma: float = DESCRIPTOR_SIGMA, seed: int = 0) -> GarmentWindow:
    """The estimator's garment inputs (:meth:`GarmentWindow.from_garment`) for a
    :class:`~swingar_pyg.world.garment.Garment`, its features computed as the
    datamodule's feature cache computes them."""
    features = garment_graph_features(garment.mesh, descriptor_size, sigma, seed)
    return GarmentWindow.from_garment(garment, num_joints, features)


def animate(estimator: SwinGarEstimator, graph: GarmentWindow, body_shape: torch.Tensor,
            rotations: torch.Tensor, translation: torch.Tensor, joint_transforms: torch.Tensor,
            joint_positions: torch.Tensor, fps: float,
            progress: bool = True) -> tuple[torch.Tensor, np.ndarray]:
    """Streams a posed motion; returns the garment ``(T, N, 3)`` and the
    seconds each frame took."""
    stream = SwinGarStream(estimator, graph, body_shape, fps)
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


def _load_garment(source: str, body, shape):
    if source in shipped_garments():
        return fit_shipped_garment(source, body, shape)
    if not Path(source).is_file():
        raise ValueError(f"--garment {source!r} is neither a file nor a shipped garment "
                         f"({', '.join(shipped_garments())})")
    return garment_on_body(Path(source).stem, load_mesh(source), body, shape)


def inside_counts(before: torch.Tensor, after: torch.Tensor, posed, body_faces: torch.Tensor,
                  progress: bool = True) -> dict:
    """Garment vertices inside the posed body (exact SDF) before and after the
    collision pass, over all frames ``(T, N, 3)``."""
    frames = range(len(before))
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, desc="inside counts (exact SDF)", unit="frame")
    counts = {"inside_before": 0, "inside_after": 0}
    for t in frames:
        surface = BodySurface(posed.vertices[t].double().numpy(), body_faces.numpy())
        for key, vertices in (("inside_before", before), ("inside_after", after)):
            counts[key] += int((surface.signed_distance(vertices[t].double().numpy())[0] > 0).sum())
    return counts


def predict_to_folder(estimator: SwinGarEstimator, garment: str, motion: str, out: str | Path,
                      body_shape: list[float] | None = None, seconds: float | None = None,
                      preview: bool = True, progress: bool = True, collisions: bool = True,
                      body_sdf: BodySDF | None = None, data_settings: dict | None = None,
                      checkpoint: str | None = None,
                      formats: str | Sequence[str] = ("obj",)) -> dict:
    """Animates ``garment`` (a mesh file or a shipped garment name) on ``motion``
    (a procedural family, a shipped clip or a ``.bvh`` path) and writes to
    ``out``: ``garment.npz`` (all frames, faces, body shape, fps), ``preview.gif``,
    ``summary.json`` (with what each stage of the
    :class:`~swingar_pyg.inference.scene.Scene` pipeline cost) and, per format of
    ``formats`` (:mod:`swingar_pyg.inference.export`): ``obj``
    ``frames/frame_0000.obj`` …; ``pc2`` ``garment.pc2`` and the rest mesh it
    applies to, ``garment_rest.obj``; ``usd`` ``garment.usd``, the garment and the
    posed body. With ``collisions``, vertices inside the body are moved out: by the
    neural ``body_sdf`` if given, else by the exact SDF. ``data_settings``: the
    descriptor's ``sigma`` and ``seed`` the estimator was trained with;
    ``checkpoint``: where it came from, for the summary.

    Unknown formats, or USD without ``usd-core``, fail before any work; every file
    is written atomically."""
    formats = parse_formats(formats)
    check_writers(formats)
    data_settings = data_settings or {}
    body = AnnyBody()
    shape = body.default_shape() if body_shape is None else torch.tensor(body_shape)
    fitted = _load_garment(garment, body, shape)
    clip = make_motion(motion, body, shape, seconds=seconds)
    scene = Scene([fitted], body, shape, clip, collisions=collisions, body_sdf=body_sdf)
    result = compile_scene(scene, estimator, sigma=data_settings.get("sigma", DESCRIPTOR_SIGMA),
                           seed=data_settings.get("seed", 0)).run(progress)
    if not torch.isfinite(result.vertices[0]).all():
        raise ValueError("the estimator produced non-finite vertices; the checkpoint or the "
                         "inputs are broken")
    vertices = result.vertices[0].numpy()
    posed = body.pose(shape, clip.rotations, clip.translation)
    collision_counts = None
    if collisions:
        stage = result.stage("collisions: SDF + correction")
        collision_counts = {"sdf": "exact" if body_sdf is None else "neural",
                            "moved": stage.moved, "ran_on_frames": stage.calls,
                            "vertex_frames": int(vertices.shape[0] * vertices.shape[1]),
                            **inside_counts(result.before_collisions[0], result.vertices[0],
                                            posed, body.faces, progress)}
    out = Path(out)
    faces = fitted.mesh.faces
    exported = {}
    if "obj" in formats:
        for t, frame in enumerate(vertices):
            write_obj(out / "frames" / f"frame_{t:04d}.obj", frame, faces)
        exported["obj"] = ["frames/"]
    if "pc2" in formats:
        write_pc2(out / "garment.pc2", vertices)
        write_obj(out / "garment_rest.obj", fitted.mesh.vertices, faces)
        exported["pc2"] = ["garment.pc2", "garment_rest.obj"]
    if "usd" in formats:
        write_usd(out / "garment.usd", vertices, faces, clip.fps,
                  body_frames=posed.vertices.numpy(), body_faces=body.faces.numpy(),
                  garment_name=fitted.name)
        exported["usd"] = ["garment.usd"]
    with atomic_path(out / "garment.npz") as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, vertices=vertices, faces=faces,
                                body_shape=shape.numpy(), fps=clip.fps)
    if preview:
        render_sequence(out / "preview.gif", posed.vertices.numpy(), body.faces.numpy(),
                        vertices, faces, fps=clip.fps, title=f"{fitted.name} / {clip.name}")
    network = ("motion code", "skinning (E, P, LBS)", "detail (M_d)")
    summary = {"garment": fitted.name, "vertices": int(fitted.mesh.num_vertices),
               "motion": clip.name, "frames": int(len(vertices)), "fps": float(clip.fps),
               "exported": exported,
               "estimator_ms_per_frame": 1e3 * sum(result.stage(n).seconds for n in network) /
               len(vertices), "checkpoint": checkpoint,
               "clearance_gate": {
                   "clearance_scale": estimator.clearance_scale,
                   "contact_clearance": estimator.contact_clearance,
                   "anchor_scale": estimator.anchor_scale}
               if estimator.clearance_scale or estimator.anchor_scale else None,
               "collisions": collision_counts,
               "stages": [dataclasses.asdict(stage) for stage in result.stages]}
    with atomic_path(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary
