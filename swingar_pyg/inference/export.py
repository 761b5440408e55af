"""Animated garments out to DCC tools: OBJ frames, Blender's PC2 point cache and USD.

Every writer takes frames ``(T, N, 3)`` in the package's frame (metres, +Z up, the
body facing -Y; docs/design.md §1), checks them first (a ``ValueError`` names what
is wrong: shapes, NaN or inf, face indices) and writes atomically: a temporary file
beside the target, renamed onto it only when complete, so a failure leaves nothing
half-written (:func:`swingar_pyg.atomic.atomic_path`).

- **OBJ** (:func:`write_obj`): one file per frame, text, 1 µm resolution.
- **PC2** (:func:`write_pc2`): one binary file of every frame, read by Blender's
  Mesh Cache modifier (and 3ds Max's Point Cache), applied to a mesh of the same
  vertex order: the garment's rest OBJ.
- **USD** (:func:`write_usd`): one stage holding the garment and the body as meshes
  with time-sampled points, one time code per frame. Needs Pixar's ``usd-core``
  (module ``pxr``: ``pip install 'swingar-pyg[usd]'``), imported only here.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from swingar_pyg.atomic import atomic_path

FORMATS = ("obj", "pc2", "usd")
"""What ``swingar predict --format`` writes: OBJ frames (the default), PC2, USD."""

PC2_SIGNATURE = b"POINTCACHE2\0"
PC2_HEADER = struct.Struct("<12siiffi")
"""signature, file version (1), points, start frame, sample rate, samples: 32 bytes."""

USD_EXTENSIONS = (".usd", ".usda", ".usdc")


def parse_formats(values: str | Iterable[str]) -> tuple[str, ...]:
    """``"usd,pc2"``, or a list of such strings (``--format`` repeated), as the
    formats named, each once, in the order given; ``ValueError`` for an unknown one."""
    if isinstance(values, str):
        values = [values]
    formats: list[str] = []
    for value in values:
        for name in str(value).split(","):
            name = name.strip().lower()
            if not name:
                continue
            if name not in FORMATS:
                raise ValueError(f"unknown export format {name!r}: choose from "
                                 f"{', '.join(FORMATS)} (comma-separated or repeated)")
            if name not in formats:
                formats.append(name)
    if not formats:
        raise ValueError(f"no export format given: choose from {', '.join(FORMATS)}")
    return tuple(formats)


def check_writers(formats: Iterable[str]) -> None:
    """Raises before any work is done if a format's writer cannot run: an
    ``ImportError`` naming the extra when USD is asked for without ``usd-core``."""
    if "usd" in formats:
        _import_usd()


def check_frames(frames, name: str = "frames", dtype=np.float32) -> np.ndarray:
    """``frames`` as a contiguous ``(T, N, 3)`` array of ``dtype``, T and N at least 1,
    every value finite (also once in float32); otherwise ``ValueError``."""
    array = np.asarray(frames)
    if array.ndim != 3 or array.shape[2] != 3 or 0 in array.shape:
        raise ValueError(f"{name} must have shape (T, N, 3) with T, N >= 1, "
                         f"got {tuple(array.shape)}")
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise ValueError(f"{name} must be numbers, got dtype {array.dtype}")
    with np.errstate(over="ignore"):
        bad = ~np.isfinite(array.astype(np.float32)).all(axis=(1, 2))
    if bad.any():
        raise ValueError(f"{name} must be finite (in float32): {int(bad.sum())} of "
                         f"{len(array)} frames hold NaN or inf, the first is frame "
                         f"{int(bad.argmax())}")
    return np.ascontiguousarray(array, dtype=dtype)


def check_faces(faces, num_vertices: int, name: str = "faces") -> np.ndarray:
    """``faces`` as an int32 ``(F, 3)`` array of vertex indices in ``[0,
    num_vertices)``, F at least 1; otherwise ``ValueError``."""
    array = np.asarray(faces)
    if array.ndim != 2 or array.shape[1] != 3 or len(array) == 0:
        raise ValueError(f"{name} must have shape (F, 3) with F >= 1 (triangles), "
                         f"got {tuple(array.shape)}")
    if not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f"{name} must be integer vertex indices, got dtype {array.dtype}")
    if array.min() < 0 or array.max() >= num_vertices:
        raise ValueError(f"{name} must index vertices in [0, {num_vertices}), "
                         f"got [{int(array.min())}, {int(array.max())}]")
    return np.ascontiguousarray(array, dtype=np.int32)


def write_obj(path: str | Path, vertices, faces) -> None:
    """A Wavefront OBJ of one frame ``(N, 3)`` with triangle ``faces`` ``(F, 3)``
    (0-based here, 1-based in the file), written atomically."""
    vertices = np.asarray(vertices)
    if vertices.ndim != 2:
        raise ValueError(f"vertices must have shape (N, 3), got {tuple(vertices.shape)}")
    vertices = check_frames(vertices[None], "vertices", np.float64)[0]
    faces = check_faces(faces, len(vertices))
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def write_pc2(path: str | Path, frames, start_frame: float = 0.0,
              sample_rate: float = 1.0) -> None:
    """Every frame ``(T, N, 3)`` in one PC2 point cache, written atomically.

    The layout (little-endian): the 12-byte signature ``b"POINTCACHE2\\0"``, int32
    file version 1, int32 number of points N, float32 start frame, float32 sample
    rate (frames between samples: 1.0 is one sample per frame; PC2 stores no frames
    per second, so set the scene's frame rate to the motion's), int32 number of
    samples T, then T × N × 3 float32.

    The points are in the package's frame: metres, +Z up, the body facing -Y.
    Blender is Z up too, so nothing is converted: apply the cache with a Mesh Cache
    modifier (format PC2, its axes left at +Y forward and +Z up) to a mesh of the
    same vertex order, e.g. the garment's rest OBJ imported with Up Axis Z and
    Forward Axis Y (Blender's OBJ importer otherwise turns a Y-up file to Z up).
    Blender's scene unit is the metre, as here.
    """
    frames = check_frames(frames)
    if not (np.isfinite(start_frame) and np.isfinite(sample_rate) and sample_rate > 0):
        raise ValueError(f"start_frame must be finite and sample_rate finite and > 0, got "
                         f"{start_frame} and {sample_rate}")
    samples, points, _ = frames.shape
    header = PC2_HEADER.pack(PC2_SIGNATURE, 1, points, start_frame, sample_rate, samples)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(header)
            handle.write(frames.astype("<f4", copy=False).tobytes())


def _import_usd():
    try:
        from pxr import Usd, UsdGeom, Vt
    except ImportError as error:
        raise ImportError("writing USD needs Pixar's usd-core (module pxr): "
                          "pip install 'swingar-pyg[usd]'") from error
    return Usd, UsdGeom, Vt


def write_usd(path: str | Path, frames, faces, fps: float, body_frames=None,
              body_faces=None, start_time_code: float = 0.0,
              garment_name: str = "garment") -> None:
    """The garment ``frames`` ``(T, N, 3)`` with its triangle ``faces``, and the body
    ``body_frames`` ``(T, V, 3)`` with ``body_faces`` if given, as one USD stage
    written atomically (``.usd``: binary crate, ``.usda``: text, ``.usdc``).

    The stage: metres (``metersPerUnit`` 1), +Z up, ``timeCodesPerSecond`` and
    ``framesPerSecond`` both ``fps``, frame ``t`` at time code ``start_time_code +
    t``, from ``startTimeCode`` to ``endTimeCode``. Under the default prim
    ``/Scene`` (an Xform): ``/Scene/Garment`` and ``/Scene/Body``, ``UsdGeom.Mesh``
    prims with triangle topology (``subdivisionScheme`` none: they are not
    subdivision cages), time-sampled ``points`` and ``extent``, and the first frame
    as the points' default value. The garment is double-sided (cloth is seen from
    both sides) and carries its name in ``customData["swingar:garment"]``.
    """
    frames = check_frames(frames)
    faces = check_faces(faces, frames.shape[1])
    if (body_frames is None) != (body_faces is None):
        raise ValueError("give both body_frames and body_faces, or neither")
    if body_frames is not None:
        body_frames = check_frames(body_frames, "body_frames")
        body_faces = check_faces(body_faces, body_frames.shape[1], "body_faces")
        if len(body_frames) != len(frames):
            raise ValueError(f"body_frames must have the garment's {len(frames)} frames, "
                             f"got {len(body_frames)}")
    if not (np.isfinite(fps) and fps > 0) or not np.isfinite(start_time_code):
        raise ValueError(f"fps must be finite and > 0 and start_time_code finite, got {fps} "
                         f"and {start_time_code}")
    suffix = Path(path).suffix.lower()
    if suffix not in USD_EXTENSIONS:
        raise ValueError(f"a USD file ends in {', '.join(USD_EXTENSIONS)}, got {str(path)!r}")
    Usd, UsdGeom, Vt = _import_usd()

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetTimeCodesPerSecond(float(fps))
    stage.SetFramesPerSecond(float(fps))
    stage.SetStartTimeCode(float(start_time_code))
    stage.SetEndTimeCode(float(start_time_code + len(frames) - 1))
    scene = UsdGeom.Xform.Define(stage, "/Scene")
    stage.SetDefaultPrim(scene.GetPrim())

    def mesh(prim_path: str, points: np.ndarray, triangles: np.ndarray, colour, double_sided):
        geometry = UsdGeom.Mesh.Define(stage, prim_path)
        geometry.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        geometry.CreateDoubleSidedAttr(double_sided)
        geometry.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(
            np.full(len(triangles), 3, dtype=np.int32)))
        geometry.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(triangles.reshape(-1)))
        geometry.CreateDisplayColorAttr([colour])
        points_attribute = geometry.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points[0]))
        extent_attribute = geometry.CreateExtentAttr()
        for t, frame in enumerate(points):
            time = Usd.TimeCode(start_time_code + t)
            points_attribute.Set(Vt.Vec3fArray.FromNumpy(frame), time)
            extent_attribute.Set(Vt.Vec3fArray.FromNumpy(
                np.stack([frame.min(axis=0), frame.max(axis=0)])), time)
        return geometry

    garment = mesh("/Scene/Garment", frames, faces, (0.80, 0.35, 0.30), True)
    garment.GetPrim().SetCustomDataByKey("swingar:garment", str(garment_name))
    if body_frames is not None:
        mesh("/Scene/Body", body_frames, body_faces, (0.75, 0.75, 0.75), False)
    with atomic_path(path, suffix=".tmp" + suffix) as tmp:
        if not stage.GetRootLayer().Export(str(tmp)):
            raise OSError(f"USD could not write {tmp}")
