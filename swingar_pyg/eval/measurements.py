"""A report's finished estimator measurements on disk, so that a report cut off
(a session's end, a killed job) resumes where it stopped: ``swingar report
--resume`` reads back every measurement an earlier run of the same report
stored and measures only the rest.

A measurement is stored under the SHA-256 of its identity: everything its figures
depend on that the report can name (the model's source file and its hash, the
precision and collision pass, the test split file and the sequences measured, the
descriptor settings, the package and torch versions). A stored file whose identity
differs is never read back; a changed estimator, split or setting is measured anew.
Each file is written whole (to a temporary file, then renamed) and records when it
was measured, which the report states for every measurement it read back.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.eval.error_vs_time import MethodResult


def file_identity(path: str | Path) -> dict:
    """A file's resolved path, size and modification time: which version of it."""
    stat = Path(path).stat()
    return {"path": str(Path(path).resolve()), "bytes": stat.st_size,
            "modified_ns": stat.st_mtime_ns}


class MeasurementStore:
    """Finished :class:`~swingar_pyg.eval.error_vs_time.MethodResult` s in ``folder``,
    one ``<key>.pt`` per identity (a JSON-serialisable dict)."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)

    @staticmethod
    def _canonical(identity: dict) -> str:
        return json.dumps(identity, sort_keys=True)

    def path(self, identity: dict) -> Path:
        key = hashlib.sha256(self._canonical(identity).encode()).hexdigest()[:32]
        return self.folder / f"{key}.pt"

    def load(self, identity: dict) -> tuple[MethodResult, str] | None:
        """The stored result of ``identity`` and when it was measured (UTC), or
        ``None`` if none is stored."""
        path = self.path(identity)
        if not path.is_file():
            return None
        stored = torch.load(path, map_location="cpu", weights_only=True)
        if stored.get("identity") != self._canonical(identity):
            return None
        return MethodResult(**stored["result"]), stored["measured_at"]

    def save(self, identity: dict, result: MethodResult) -> None:
        """Stores ``result`` as the measurement of ``identity``."""
        self.folder.mkdir(parents=True, exist_ok=True)
        record = {"identity": self._canonical(identity),
                  "measured_at": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                  "result": {"name": result.name, "kind": result.kind,
                             "errors": dict(result.errors),
                             "seconds": [float(s) for s in result.seconds],
                             "extra": dict(result.extra)}}
        with atomic_path(self.path(identity)) as tmp:
            torch.save(record, tmp)
