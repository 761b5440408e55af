"""A job run in a spawned process that ends with its parent.

A report trains each missing run in a process of its own (a finished fit keeps its
datamodule referenced, so runs trained one after another in one process add up).
That child must not outlive the report: a scheduler's stop or ``kill PID`` sends
SIGTERM to the parent alone, whose default action ends it at once and leaves the
child training as an orphan.
"""

from __future__ import annotations

import multiprocessing
import signal
import threading
from collections.abc import Callable
from types import FrameType

#: Seconds a child is given to stop after SIGTERM (Lightning finishes its current
#: batch and tears down) before it is killed.
STOP_GRACE_SECONDS = 60.0


def run_in_child(target: Callable, args: tuple) -> int:
    """Run ``target(*args)`` in a spawned process and return its exit code.

    While the child runs, a SIGTERM sent to the parent raises :class:`SystemExit`
    (in the main thread, where Python delivers signals; elsewhere the handler is
    left alone). Whatever ends the wait (that, Ctrl-C, any exception), the child is
    sent SIGTERM, given :data:`STOP_GRACE_SECONDS` to stop, and killed if it has not.
    The previous SIGTERM handler is restored before that, so a repeated signal
    during the wait for the child acts as it did before the call."""
    process = multiprocessing.get_context("spawn").Process(target=target, args=args)
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGTERM)
    if in_main_thread:
        signal.signal(signal.SIGTERM, _exit_on_signal)
    try:
        process.start()
        process.join()
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
        if process.is_alive():
            process.terminate()
            process.join(STOP_GRACE_SECONDS)
            if process.is_alive():
                process.kill()
                process.join()
    return process.exitcode


def _exit_on_signal(signum: int, frame: FrameType | None) -> None:
    """A signal handler that exits with the shell's code for the signal."""
    raise SystemExit(128 + signum)
