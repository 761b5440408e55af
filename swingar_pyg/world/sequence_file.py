"""Simulated sequences in HDF5 (docs/design.md §7), written atomically.

Layout::

    /                 attrs: what the writer adds (a dataset part: its recipe, JSON)
    /garments/<name>/ rest_vertices (N,3) faces (F,3) pinned (P,) skin_indices (N,K)
                      skin_weights (N,K) fit (N,) [signed distance to the rest body]
    /sequences/<id>/  garment_vertices (T,N,3) [chunked by frame, gzip]
                      rigid_vertices (T,N,3) rotations (T,J,3,3) translation (T,3)
                      body_shape (S,) seconds_per_frame max_stretch mean_stretch
                      penetration (T,) [simulator's own nearest-vertex test]
                      substeps_per_frame (T,) [absent in files older than it]
                      penetration_exact (T,) [ray parity; absent when not measured]
                      attrs: garment, motion, fps, joint_names, settings (JSON),
                             simulator_revision (absent in files older than it)

Body vertices are not stored: the body model recomputes them from shape and pose.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from swingar_pyg.atomic import atomic_path
from swingar_pyg.geometry import as_mesh
from swingar_pyg.sim import SIMULATOR_REVISION
from swingar_pyg.world.garment import Garment
from swingar_pyg.world.sequence import SimulatedSequence

_COMPRESSION = {"compression": "gzip", "compression_opts": 4}


def write_sequences(path: str | Path, sequences: list[SimulatedSequence],
                    ids: list[str] | None = None, attrs: dict[str, str] | None = None) -> Path:
    """Writes ``sequences`` (and each garment once) to a new HDF5 file at ``path``,
    as ``/sequences/<id>`` (default ids: ``000000``, ``000001``, ...), with ``attrs``
    on the file's root."""
    import h5py

    path = Path(path)
    ids = ids or [f"{index:06d}" for index in range(len(sequences))]
    if len(ids) != len(sequences) or len(set(ids)) != len(ids):
        raise ValueError("give one distinct id per sequence")
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as file:
            file.attrs.update(attrs or {})
            for sequence_id, sequence in zip(ids, sequences):
                garment = sequence.garment
                if garment.name not in file.get("garments", {}):
                    group = file.create_group(f"garments/{garment.name}")
                    group["rest_vertices"] = garment.mesh.vertices.astype(np.float32)
                    group["faces"] = garment.mesh.faces.astype(np.int32)
                    group["pinned"] = garment.pinned.astype(np.int32)
                    group["skin_indices"] = garment.skin_indices.astype(np.int16)
                    group["skin_weights"] = garment.skin_weights.astype(np.float32)
                    group["fit"] = garment.fit.astype(np.float32)
                group = file.create_group(f"sequences/{sequence_id}")
                result = sequence.result
                frames, vertices = result.positions.shape[:2]
                group.create_dataset("garment_vertices", data=result.positions.numpy(),
                                     chunks=(1, vertices, 3), **_COMPRESSION)
                group.create_dataset("rigid_vertices", data=sequence.rigid.numpy(),
                                     chunks=(1, vertices, 3), **_COMPRESSION)
                group["rotations"] = sequence.motion.rotations.numpy()
                group["translation"] = sequence.motion.translation.numpy()
                group["body_shape"] = sequence.body_shape.numpy()
                for name in ("seconds_per_frame", "max_stretch", "mean_stretch", "penetration",
                             "substeps_per_frame"):
                    group[name] = getattr(result, name)
                if sequence.penetration_exact is not None:
                    group["penetration_exact"] = sequence.penetration_exact
                group.attrs["garment"] = garment.name
                group.attrs["motion"] = sequence.motion.name
                group.attrs["fps"] = sequence.motion.fps
                group.attrs["joint_names"] = json.dumps(list(sequence.motion.joint_names))
                group.attrs["settings"] = json.dumps(result.settings)
                group.attrs["simulator_revision"] = SIMULATOR_REVISION
    return path


def merge_sequence_files(parts: list[Path], path: str | Path) -> Path:
    """Copies the sequences and garments of ``parts`` into one new file at ``path``
    (garments once each; sequence ids must not repeat)."""
    import h5py

    path = Path(path)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as merged:
            for part in parts:
                with h5py.File(part, "r") as source:
                    for name in source.get("garments", {}):
                        if name not in merged.get("garments", {}):
                            source.copy(source[f"garments/{name}"], merged, f"garments/{name}")
                    for name in source.get("sequences", {}):
                        if name in merged.get("sequences", {}):
                            raise ValueError(f"sequence {name} is in more than one part")
                        source.copy(source[f"sequences/{name}"], merged, f"sequences/{name}")
    return path


def sequence_ids(path: str | Path) -> list[str]:
    """The ids of a file's sequences, sorted."""
    import h5py

    with h5py.File(path, "r") as file:
        return sorted(file["sequences"])


def read_sequence(path: str | Path, sequence_id: str) -> dict:
    """One sequence of a file as arrays: ``garment_vertices``, ``rigid_vertices``,
    ``rotations``, ``translation``, ``body_shape``, ``faces`` (the garment's), and
    the attributes (``garment``, ``motion``, ``fps``, ``joint_names``, and the
    simulator's ``settings`` as a dict)."""
    import h5py

    with h5py.File(path, "r") as file:
        if sequence_id not in file.get("sequences", {}):
            available = ", ".join(list(file.get("sequences", {}))[:8])
            raise ValueError(f"{path} has no sequence {sequence_id!r} (it has {available}, ...)")
        group = file[f"sequences/{sequence_id}"]
        out = {name: group[name][:] for name in ("garment_vertices", "rigid_vertices",
                                                 "rotations", "translation", "body_shape")}
        out.update(garment=group.attrs["garment"], motion=group.attrs["motion"],
                   fps=float(group.attrs["fps"]),
                   joint_names=tuple(json.loads(group.attrs["joint_names"])),
                   settings=json.loads(group.attrs["settings"]),
                   faces=file[f"garments/{group.attrs['garment']}/faces"][:])
    return out


def read_garment(path: str | Path, name: str) -> Garment:
    """A garment stored in a sequence file, as the simulator was given it."""
    import h5py

    with h5py.File(path, "r") as file:
        if name not in file.get("garments", {}):
            raise ValueError(f"{path} has no garment {name!r}")
        stored = file[f"garments/{name}"]
        return Garment(name, as_mesh(stored["rest_vertices"][:].astype(np.float64),
                                     stored["faces"][:]),
                       stored["pinned"][:].astype(np.int64),
                       stored["skin_indices"][:].astype(np.int64),
                       stored["skin_weights"][:], stored["fit"][:])


def simulator_revisions(path: str | Path) -> set[int]:
    """The simulator revisions that made the sequences of a file (0 for
    sequences written before revisions were recorded)."""
    import h5py

    with h5py.File(path, "r") as file:
        return {int(group.attrs.get("simulator_revision", 0))
                for group in file.get("sequences", {}).values()}
