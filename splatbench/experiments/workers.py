"""The runner's worker processes: their thread budget and a life tied to the runner's.

The runner hands each worker what it needs with every run (`one_run.RunContext`):
nothing reaches a worker through environment variables the runner sets.

A worker must never outlive its runner: a runner killed with SIGKILL (or stopped by
SIGTERM) would otherwise leave workers that keep computing, adopted by init, and a
prompt rerun would start the same runs beside them. `die_with_runner` arranges it.
"""

from __future__ import annotations

import atexit
import os
import signal
import socket
import sys
import threading
import time

from splatbench.experiments.claims import pid_alive, process_start


def init_worker(runner: str = "") -> None:
    """Pool initializer: tie the worker's life to the runner's (`die_with_runner`),
    leave Ctrl-C to the runner (which stops its workers), and make the worker leave
    with `os._exit` once the pool shuts it down: its results are on disk already, and
    the interpreter's teardown of torch and Dr.Jit costs seconds per worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_runner(runner)
    atexit.register(fast_exit)  # registered last, so it runs first


_watched: str | None = None


def die_with_runner(runner: str) -> None:
    """Kill this process (SIGKILL) when the runner ``host:pid:start`` dies, however it
    dies: the kernel's parent-death signal where the runner is the parent (Linux
    prctl), and a watchdog thread polling the runner's pid each second (a Dask
    worker's parent is its nanny, not the runner). A no-op for a runner on another
    host, or without ``runner``; idempotent."""
    global _watched
    if not runner or _watched == runner:
        return
    host, pid, start = runner.rsplit(":", 2)
    if host != socket.gethostname():
        return
    _watched, pid = runner, int(pid)
    if sys.platform.startswith("linux") and os.getppid() == pid:
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover - no libc prctl
            pass

    def watch() -> None:
        while pid_alive(pid, start or None):
            time.sleep(1.0)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="splatbench-runner-watchdog", daemon=True).start()
    if not pid_alive(pid, start or None):  # the runner died before the watchdog started
        os.kill(os.getpid(), signal.SIGKILL)


def runner_id() -> str:
    """``host:pid:start`` of this process (the runner), for `die_with_runner`."""
    pid = os.getpid()
    return f"{socket.gethostname()}:{pid}:{process_start(pid) or ''}"


def fast_exit() -> None:
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def bound_threads(threads: int | None) -> None:
    """Give Dr.Jit's thread pool in this worker ``threads`` threads (None: leave it), so
    parallel runs share the cores."""
    if threads is not None:
        import drjit as dr

        if dr.thread_count() != threads:
            dr.set_thread_count(threads)


__all__ = ["init_worker", "die_with_runner", "runner_id", "fast_exit", "bound_threads"]
