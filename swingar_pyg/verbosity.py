"""How much the package's dependencies print: NVIDIA Warp's start-up banner is off
unless asked for.

Warp comes in through anny's skinning (and newton's VBD solver) and, on every
process that poses the body, prints "Warp 1.x initialized", its CUDA toolkit and
driver, its kernel cache and a "Module ... load on device 'cpu' took ..." line per
kernel module, plus a C-level "Could not find or load the NVIDIA CUDA driver"
warning on a machine without a GPU. :func:`init_warp` initialises Warp quietly
before anny or newton does.

**The library is quiet too, not only the command line.** The package, not the
user, brings Warp in (an implementation detail of anny's skinning), so its banner
is the package's noise: on stdout it mixes into a script's or a notebook's output.
Quiet means Warp's log level goes from its default (info) to warnings, so warnings
and errors still print; a log level the user set below the default (debug) is
left alone. To see the banner: ``swingar --verbose ...``, ``SWINGAR_VERBOSE=1`` in
the environment, or :func:`set_verbose` before the first body is built. The
setting lives in the environment so that worker processes (``make-dataset
--workers``, started with ``spawn``) inherit it.
"""

from __future__ import annotations

import os
import sys
import tempfile
from types import ModuleType

VERBOSE_ENV = "SWINGAR_VERBOSE"
"""The environment variable that keeps dependencies' start-up messages (``1``)."""

# The C-level line warp's native init prints to stderr when there is no CUDA driver.
_NO_DRIVER = "Could not find or load the NVIDIA CUDA driver"


def set_verbose(verbose: bool = True) -> None:
    """Keeps (``True``) or silences (``False``, the default) Warp's start-up banner
    in this process and the processes it starts, from Warp's next initialisation on."""
    os.environ[VERBOSE_ENV] = "1" if verbose else "0"


def is_verbose() -> bool:
    """Whether :data:`VERBOSE_ENV` asks for dependencies' start-up messages."""
    return os.environ.get(VERBOSE_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def init_warp() -> ModuleType | None:
    """Configures and initialises NVIDIA Warp, quietly unless :func:`is_verbose`;
    returns the ``warp`` module, or ``None`` when Warp is not installed.

    Quiet: ``warp.config.quiet = True`` (Warp before 1.19 reads it) and a log level
    of at least warnings (Warp 1.19 and later), set before ``warp.init()``, which
    runs with the native layer's stderr captured: the missing-CUDA-driver warning
    is dropped, anything else it printed is passed on. Calling it again, or after
    Warp was initialised elsewhere, is harmless.
    """
    try:
        import warp
    except ImportError:
        return None
    if is_verbose():
        return warp
    warp.config.quiet = True
    info, warning = getattr(warp, "LOG_INFO", 20), getattr(warp, "LOG_WARNING", 30)
    if getattr(warp.config, "log_level", None) == info:
        warp.config.log_level = warning
    _without_native_driver_warning(warp.init)
    return warp


def _without_native_driver_warning(function) -> None:
    """Runs ``function`` with file descriptor 2 redirected to a temporary file,
    then writes what it caught to stderr, less the missing-CUDA-driver line."""
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to redirect
        function()
        return
    with tempfile.TemporaryFile(mode="w+b") as caught:
        os.dup2(caught.fileno(), 2)
        try:
            function()
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            text = caught.read().decode(errors="replace")
            kept = [line for line in text.splitlines(keepends=True) if _NO_DRIVER not in line]
            if kept:
                sys.stderr.write("".join(kept))
                sys.stderr.flush()
