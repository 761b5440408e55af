"""Atomic file output: nothing half-written is left on disk after a failure."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """Yields a temporary path beside ``path``; renames it onto ``path`` when the
    block succeeds and removes it when the block raises.

    ``suffix`` ends the temporary file's name: writers that choose the format by
    the extension (USD's ``Export``) need the target's, e.g. ``".tmp.usd"``.

    The rename is atomic on POSIX (same directory, same file system), so readers
    see either the old file or the complete new one.

    >>> with atomic_path("results.json") as tmp:   # doctest: +SKIP
    ...     tmp.write_text("{}")
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.",
                                    suffix=suffix)
    os.close(handle)
    temporary = Path(name)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)  # mkstemp makes it private; a plain open() would not
    try:
        yield temporary
        os.replace(temporary, target)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
