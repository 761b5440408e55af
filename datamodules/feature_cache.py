"""Per-garment and per-sequence features computed once and stored beside the
dataset's HDF5 split file, one cache file per :class:`FeatureSettings`:
``<split file name>.features-<key>.h5``, where ``key`` hashes the settings and
the cache format. Runs with different settings (an ablation's descriptor sizes,
side by side) share one split file and never rewrite it; each finds its own
cache. Runs that need the same cache at once compute it once: the first takes a
lock (``<cache>.lock``), the others wait and read what it wrote.

Layout of a cache file::

    /                        attrs: settings (JSON of FeatureSettings and the format),
                                    source (JSON: the split file's device, inode,
                                    bytes and mtime)
    /garments/<name>/        edge_index (2,E) normals (N,3) [descriptor (z,)]
    /sequences/<id>/         joint_transforms (T,J,3,4) joint_positions (T,J,3)
                             body_points body_normals (P,3)
                             body_skin_indices body_skin_weights (P,K)

A cache is current while its settings match and the split file is the one it was
computed from (same file, size and modification time); otherwise, or when it
cannot be read, it is computed again. A copy of the data folder is a new file:
its caches are computed again.
The descriptor is :func:`~swingar_pyg.geometry.spectral_descriptor` with
``normalize=True`` (eigenvalues of ``A / N``, which depend little on mesh
resolution). Body points are a farthest-point sample of the rest body's
vertices with their normals and skinning: posing them with a frame's joint
transforms gives the body surface the collision loss needs, without storing
the posed body.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.geometry import as_mesh, vertex_normals
from swingar_pyg.geometry.spectral import DESCRIPTOR_SIGMA
from swingar_pyg.models.garment_window import garment_graph_features
from swingar_pyg.world.body import AnnyBody

# Raised whenever what a cache holds, or how it is computed, changes: old caches
# then no longer match and are computed again.
CACHE_FORMAT = 1


@dataclass(frozen=True)
class FeatureSettings:
    """What the cache depends on; a change recomputes it.

    Args:
        descriptor_size: descriptor length ``z``, or ``None`` for none.
        sigma: Gaussian kernel width of the descriptor (m).
        weighting: Nyström quadrature, ``"voronoi"`` or ``"uniform"``.
        seed: first farthest-point sample.
        body_points: body surface samples for the collision loss.
    """

    descriptor_size: int | None = 256
    sigma: float = DESCRIPTOR_SIGMA
    weighting: str = "voronoi"
    seed: int = 0
    body_points: int = 1024

    def __post_init__(self):
        if self.descriptor_size is not None and self.descriptor_size < 1:
            raise ValueError(f"descriptor_size must be >= 1 or None, got {self.descriptor_size}")
        if self.body_points < 1:
            raise ValueError(f"body_points must be >= 1, got {self.body_points}")

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)


def _cache_key(settings: FeatureSettings) -> str:
    return json.dumps({"format": CACHE_FORMAT, "settings": json.loads(settings.to_json())},
                      sort_keys=True)


def feature_cache_path(path: str | Path, settings: FeatureSettings) -> Path:
    """Where the cache of split file ``path`` for ``settings`` lives."""
    path = Path(path)
    key = hashlib.sha256(_cache_key(settings).encode()).hexdigest()[:12]
    return path.with_name(f"{path.name}.features-{key}.h5")


def _source_identity(path: Path) -> str:
    stat = path.stat()
    return json.dumps({"device": stat.st_dev, "inode": stat.st_ino, "bytes": stat.st_size,
                       "modified_ns": stat.st_mtime_ns})


def current_feature_cache(path: str | Path, settings: FeatureSettings) -> Path | None:
    """The cache file of ``path`` for ``settings`` if it exists, can be read and
    was computed from ``path`` as it is now, else ``None``."""
    import h5py

    cache = feature_cache_path(path, settings)
    if not cache.is_file():
        return None
    try:
        with h5py.File(cache, "r") as file:
            current = (file.attrs.get("settings") == _cache_key(settings)
                       and file.attrs.get("source") == _source_identity(Path(path)))
    except OSError:  # truncated or not HDF5: computed again
        return None
    return cache if current else None


def farthest_points(points: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` points spread by greedy farthest-point sampling in
    Euclidean space, starting from point 0."""
    count = min(count, len(points))
    chosen = np.zeros(count, dtype=np.int64)
    distance = np.linalg.norm(points - points[0], axis=1)
    for k in range(1, count):
        chosen[k] = int(np.argmax(distance))
        distance = np.minimum(distance, np.linalg.norm(points - points[chosen[k]], axis=1))
    return chosen


def ensure_feature_cache(path: str | Path, settings: FeatureSettings, body_model=None,
                         progress: bool = True) -> bool:
    """Computes the cache of ``path`` for ``settings`` unless it is current
    (:func:`current_feature_cache`). The split file is only read; the cache is
    written to a temporary file and renamed into place, so a failure leaves no
    half-written cache. Under the cache's lock: a second process asking for the
    same cache waits and reuses it, and temporary files a killed process left
    behind are removed. Returns whether anything was computed.

    Args:
        path: a dataset split file.
        settings: what to compute.
        body_model: a :class:`~swingar_pyg.world.body.BodyModel` of the rig the
            sequences were made for (default: the anny body, built on first need).
        progress: show a progress bar.
    """
    import h5py

    path = Path(path)
    if current_feature_cache(path, settings) is not None:
        return False
    target = feature_cache_path(path, settings)
    with open(target.with_name(target.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if current_feature_cache(path, settings) is not None:  # another process made it
            return False
        for leftover in target.parent.glob(f".{target.name}.*.tmp"):
            leftover.unlink(missing_ok=True)
        if body_model is None:
            body_model = AnnyBody()
        source_identity = _source_identity(path)
        with atomic_path(target) as tmp:
            with h5py.File(path, "r") as source, h5py.File(tmp, "w") as cache:
                _cache_garments(source, cache, settings, progress)
                _cache_sequences(source, cache, settings, body_model, progress)
                cache.attrs["settings"] = _cache_key(settings)
                cache.attrs["source"] = source_identity
    return True


def _bar(items, description: str, progress: bool):
    if not progress:
        return items
    from tqdm import tqdm

    return tqdm(items, desc=description, unit="item", leave=False)


def _cache_garments(file, cache, settings: FeatureSettings, progress: bool) -> None:
    for name in _bar(list(file["garments"]), "garment features", progress):
        source = file[f"garments/{name}"]
        mesh = as_mesh(source["rest_vertices"][:].astype(np.float64), source["faces"][:])
        features = garment_graph_features(mesh, settings.descriptor_size, settings.sigma,
                                          settings.seed, settings.weighting)
        group = cache.create_group(f"garments/{name}")
        group["edge_index"] = features["edge_index"].numpy().astype(np.int64)
        group["normals"] = features["normal"].numpy()
        if "descriptor" in features:
            group["descriptor"] = features["descriptor"].numpy()
            group.attrs["valid_eigenvalues"] = features["num_valid"]


def _cache_sequences(file, cache, settings: FeatureSettings, body_model,
                     progress: bool) -> None:
    indices, weights = body_model.skinning()
    faces = body_model.faces
    bodies: dict[tuple, tuple] = {}
    for sequence_id in _bar(list(file["sequences"]), "body poses", progress):
        source = file[f"sequences/{sequence_id}"]
        shape = torch.as_tensor(source["body_shape"][:])
        names = tuple(json.loads(source.attrs["joint_names"]))
        if names != tuple(body_model.joint_names):
            raise ValueError(f"sequence {sequence_id} was made for another rig than the "
                             f"body model's ({len(names)} joints, starting {names[:3]})")
        key = tuple(shape.tolist())
        if key not in bodies:
            rest = body_model.rest_vertices(shape)
            chosen = torch.as_tensor(farthest_points(rest.numpy(), settings.body_points))
            normals = vertex_normals(rest, faces)
            bodies[key] = (rest[chosen], normals[chosen], indices[chosen], weights[chosen])
        posed = body_model.pose(shape, torch.as_tensor(source["rotations"][:]),
                                torch.as_tensor(source["translation"][:]))
        group = cache.create_group(f"sequences/{sequence_id}")
        group["joint_transforms"] = posed.joint_transforms[..., :3, :].numpy().astype(np.float32)
        group["joint_positions"] = posed.joint_positions.numpy().astype(np.float32)
        points, normals, skin_indices, skin_weights = bodies[key]
        group["body_points"] = points.numpy().astype(np.float32)
        group["body_normals"] = normals.numpy().astype(np.float32)
        group["body_skin_indices"] = skin_indices.numpy().astype(np.int16)
        group["body_skin_weights"] = skin_weights.numpy().astype(np.float32)
