"""A report's finished estimator measurements on disk, so that a report cut off
(a session's end, a killed job) resumes where it stopped: ``swingar report
--resume`` reads back every measurement an earlier run of the same report, in
the same workspace, stored and measures only the rest.

A measurement is stored under the SHA-256 of its identity: everything its figures
depend on that the report can name (the model file's SHA-256, the precision and
collision pass, the test split file and the sequences measured, the descriptor
settings, a fingerprint of the package's source code, the versions of its
dependencies, the machine and its torch threads). A stored file whose identity
differs is never read back, and one that cannot be read is measured again. Each
file is written whole (to a temporary file, then renamed) and records when it was
measured, which the report states for every measurement it read back.
"""

from __future__ import annotations

import hashlib
import json
import pickle
import time
from pathlib import Path

import torch

import swingar_pyg
from swingar_pyg.atomic import atomic_path
from swingar_pyg.eval.error_vs_time import MethodResult


def file_identity(path: str | Path) -> dict:
    """A file's resolved path, size and modification time: which version of it."""
    stat = Path(path).stat()
    return {"path": str(Path(path).resolve()), "bytes": stat.st_size,
            "modified_ns": stat.st_mtime_ns}


def code_fingerprint() -> str:
    """The SHA-256 of the package's Python sources: any change to the code that
    measures (inference, models, evaluation) changes it."""
    digest = hashlib.sha256()
    root = Path(swingar_pyg.__file__).parent
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


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
        ``None`` if none is stored or the stored file cannot be read."""
        path = self.path(identity)
        if not path.is_file():
            return None
        try:
            stored = torch.load(path, map_location="cpu", weights_only=True)
            if stored["identity"] != self._canonical(identity):
                return None
            return MethodResult(**stored["result"]), stored["measured_at"]
        except (pickle.UnpicklingError, RuntimeError, EOFError, KeyError, TypeError):
            return None

    def save(self, identity: dict, result: MethodResult) -> None:
        """Stores ``result`` as the measurement of ``identity``. ``result.extra``
        must hold plain values (str, int, float, bool) for the weights-only load."""
        self.folder.mkdir(parents=True, exist_ok=True)
        record = {"identity": self._canonical(identity),
                  "measured_at": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                  "result": {"name": result.name, "kind": result.kind,
                             "errors": dict(result.errors),
                             "seconds": [float(s) for s in result.seconds],
                             "extra": dict(result.extra)}}
        with atomic_path(self.path(identity)) as tmp:
            torch.save(record, tmp)

    def prune(self, keep: list[dict]) -> None:
        """Deletes every stored measurement but those of ``keep``: a finished report
        leaves only its own."""
        kept = {self.path(identity) for identity in keep}
        for path in self.folder.glob("*.pt"):
            if path not in kept:
                path.unlink()
