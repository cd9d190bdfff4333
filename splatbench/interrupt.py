"""Stopping cleanly on SIGTERM and SIGINT (docs/robustness.md).

Batch systems stop a job with SIGTERM (``timeout``, SLURM, ``docker stop``,
``kill``) and a person with Ctrl-C (SIGINT). The CLI installs `stop_on_signals`
around every command: either signal raises `Interrupted` in the main thread, which
unwinds through ``finally`` blocks (so the training loop writes its last checkpoint,
the runner stops its workers) and is printed by the CLI as one line naming what
was kept, with exit status 128 + the signal number (143 for SIGTERM, 130 for SIGINT).

A section that must not be cut in half (one training step, writing a checkpoint)
runs inside `deferred`: a signal that arrives there is remembered and raised when
the section ends.

pycolmap installs glog's failure handler for SIGTERM when imported; that handler
prints a native stack and can deadlock (it runs inside ``free``). `import_pycolmap`
is the one way splatbench imports pycolmap: it puts Python's handlers back.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType

#: The signals that stop a command.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT)


class Interrupted(BaseException):
    """A stop signal arrived. ``kept`` names what survived (a checkpoint, a folder).

    A `BaseException` (like `KeyboardInterrupt`), so that ``except Exception``
    blocks -- a run recorded as failed, a fallback path -- never swallow it.
    """

    def __init__(self, signum: int, kept: str = "") -> None:
        super().__init__(signum, kept)
        self.signum = int(signum)
        self.kept = kept

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_status(self) -> int:
        return 128 + self.signum

    def line(self) -> str:
        """One line for the CLI: ``interrupted by SIGTERM; kept ...``."""
        return f"interrupted by {self.name}; {self.kept or 'nothing kept'}"


class _State(threading.local):
    def __init__(self) -> None:
        self.depth = 0                  # nesting of `deferred`
        self.pending: int | None = None  # a signal that arrived inside `deferred`


_state = _State()


def _handler(signum: int, frame) -> None:
    if _state.depth > 0:
        if _state.pending is None:
            _state.pending = signum
        return
    raise Interrupted(signum)


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Raise `Interrupted` on SIGTERM / SIGINT while the block runs (main thread only;
    elsewhere a no-op), then restore the previous handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    for s in STOP_SIGNALS:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold a stop signal that arrives inside the block; raise it when the block ends."""
    _state.depth += 1
    try:
        yield
    finally:
        _state.depth -= 1
    if _state.depth == 0 and _state.pending is not None:
        signum, _state.pending = _state.pending, None
        raise Interrupted(signum)


@contextmanager
def children_spared_sigint() -> Iterator[None]:
    """Block SIGINT in this thread while the block runs: the processes it starts (and
    the threads, which start the processes Dask starts) inherit the blocked signal
    across fork and exec, so a Ctrl-C sent to the whole process group (a terminal)
    reaches this process alone, which stops them; none prints a ``KeyboardInterrupt``
    traceback of its own, even in the middle of its imports. A SIGINT that arrives in
    the block is delivered when it ends. Main thread only; elsewhere a no-op.

    The standard library starts multiprocessing's resource tracker the same way, but
    then *unblocks* SIGINT in the thread that started it, so the tracker is started
    first, here, and a child started later from another thread keeps the mask."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    start_quiet_resource_tracker()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


#: The warning filter the resource tracker is started with (`start_quiet_resource_tracker`).
TRACKER_WARNINGS = "ignore::UserWarning:multiprocessing.resource_tracker"


def start_quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker, if it is not running, with its own warnings
    ignored. After a stop signal the runner exits fast; a worker stopped between unlinking one
    of its semaphores (tqdm's lock, a queue's) and telling the tracker so leaves the tracker to
    find it "leaked" and fail to unlink it again, and it printed two warnings after the
    runner's one line (about 1 interrupted run in 100 under load). The tracker still cleans up
    what is really left; only its messages, which name nothing a user can act on, go. The
    tracker takes its ``-W`` options from ``sys.warnoptions`` as it starts
    (`subprocess._args_from_interpreter_flags`); they are this process's again afterwards."""
    from multiprocessing import resource_tracker

    saved = list(sys.warnoptions)
    sys.warnoptions.append(TRACKER_WARNINGS)
    try:
        resource_tracker.ensure_running()
    finally:
        sys.warnoptions[:] = saved


def pending() -> int | None:
    """The signal held by an enclosing `deferred` block, if one arrived."""
    return _state.pending


def restore_python_handlers() -> None:
    """Reinstall, at the C level, the handlers Python believes are set for the stop
    signals (a native library may have replaced them behind Python's back)."""
    if threading.current_thread() is not threading.main_thread():
        return
    for s in STOP_SIGNALS:
        handler = signal.getsignal(s)
        signal.signal(s, handler if handler is not None else signal.SIG_DFL)


def import_pycolmap() -> ModuleType:
    """``import pycolmap`` without glog's SIGTERM/SIGINT handlers (module doc)."""
    import pycolmap

    restore_python_handlers()
    return pycolmap


__all__ = ["Interrupted", "STOP_SIGNALS", "stop_on_signals", "deferred", "children_spared_sigint", "pending",
           "restore_python_handlers", "import_pycolmap"]
