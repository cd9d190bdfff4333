"""The runner's executors: a local spawn process pool and a Dask client, one interface.

Both submit `splatbench.experiments.one_run.execute_run` with a `RunContext` (the
worker's thread budget, what the kind prepared) and expose ``capacity``
(runs in flight at most), ``submit``, ``wait``, ``broken``, ``restart`` and
``close``; `splatbench.experiments.runner` drives them (the module docstring there
says how each behaves when a worker dies).
"""

from __future__ import annotations

import concurrent.futures as cf
import gc
import logging
import multiprocessing
import os
import sys
import time
from typing import Any

from splatbench.experiments.one_run import RunContext, execute_run
from splatbench.experiments.grid import RunSpec
from splatbench.experiments.workers import init_worker, runner_id
from splatbench.interrupt import children_spared_sigint, deferred, start_quiet_resource_tracker


#: How often `LocalExecutor.wait` looks for dead workers, and how long one may lie dead before the
#: pool counts as broken (a death the pool notices breaks it within milliseconds).
DEAD_WORKER_POLL = 1.0
DEAD_WORKER_GRACE = 10.0


class LocalExecutor:
    """A spawn process pool with at most ``workers`` runs in flight, each worker with
    ``threads`` Dr.Jit threads; ``prepared``: what the kind's ``prepare`` returned."""

    name = "local"

    def __init__(self, workers: int, threads: int, prepared: Any = None):
        self.workers = workers
        self.context = RunContext(threads=threads, prepared=prepared)
        self._dead_since: float | None = None
        self.stalled = False  # set by `wait`, cleared by `restart`
        self.pool = self._new_pool()

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        start_quiet_resource_tracker()  # before the pool's queues register their semaphores with it
        return cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                      initializer=init_worker, initargs=(runner_id(),))

    @property
    def capacity(self) -> int:
        return self.workers

    def submit(self, run: RunSpec, results_dir: str):
        """Submit ``run``. The pool starts its workers here: they leave Ctrl-C to the runner from
        their start, and a stop signal waits until the pool is whole again (one that cut a worker's
        start in half left a worker printing a traceback and the pool's semaphores behind)."""
        with deferred(), children_spared_sigint():
            return self.pool.submit(execute_run, run, results_dir, self.context)

    def wait(self, futures, timeout: float | None = None) -> set:
        """The futures done within ``timeout`` s (at least one, unless it runs out, or the pool
        `stalled`: a worker found dead for `DEAD_WORKER_GRACE` s that the pool has not noticed --
        CPython's pool can miss a worker SIGKILLed while it held one of the pool's queue locks, and
        then waits forever; the runner then treats the pool as broken and restarts it)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            step = DEAD_WORKER_POLL if deadline is None else max(0.0, min(DEAD_WORKER_POLL, deadline - time.monotonic()))
            done, _ = cf.wait(futures, timeout=step, return_when=cf.FIRST_COMPLETED)
            if done or (deadline is not None and time.monotonic() >= deadline):
                return done
            if self._dead_worker_unnoticed():
                self.stalled = True  # the futures are the pool's to finish: never set them here (it races)
                return set()

    def _dead_worker_unnoticed(self) -> bool:
        dead = [p for p in (getattr(self.pool, "_processes", None) or {}).values() if p.exitcode is not None]
        if not dead:
            self._dead_since = None
            return False
        now = time.monotonic()
        self._dead_since = self._dead_since or now
        return now - self._dead_since >= DEAD_WORKER_GRACE

    @staticmethod
    def broken(exc: BaseException) -> bool:
        from concurrent.futures.process import BrokenProcessPool

        return isinstance(exc, BrokenProcessPool)

    def _shutdown(self, **kwargs) -> None:
        """``pool.shutdown``; a pool broken by a killed worker may have closed its wake-up pipe
        already ("handle is closed"): then there is nothing left to wake, and the error (which the
        CLI would print as a file-system fault instead of the signal that stopped the runner) is
        dropped. Workers are still terminated and joined by `close`."""
        try:
            self.pool.shutdown(**kwargs)
        except OSError:
            pass

    def restart(self) -> None:
        """A new pool. The old one's workers are stopped, as CPython stops them when it notices a
        broken pool itself (one may be blocked on a lock a killed worker held, and would otherwise
        outlive the runner); its manager thread is not waited for."""
        for proc in list((getattr(self.pool, "_processes", None) or {}).values()):
            if proc.is_alive():
                proc.kill()
        self._shutdown(wait=False, cancel_futures=True)
        self._dead_since, self.stalled = None, False
        self.pool = self._new_pool()

    def close(self, cancel: bool = False) -> None:
        """Shut the pool down; with ``cancel``, stop the running workers too (SIGTERM,
        then SIGKILL after 5 s), so that none outlives an interrupted runner."""
        processes = list((getattr(self.pool, "_processes", None) or {}).values()) if cancel else []
        for proc in processes:
            proc.terminate()
        self._shutdown(wait=not cancel, cancel_futures=cancel)
        deadline = time.monotonic() + 5.0
        for proc in processes:
            proc.join(max(0.0, deadline - time.monotonic()))
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
        if cancel:  # the workers are gone: let the pool's manager thread end and free its semaphores
            self._shutdown(wait=True)
            self.pool = None
            gc.collect()


class DaskExecutor:
    """A `distributed.Client` on ``scheduler``, or on a loopback `LocalCluster` whose
    workers get ``threads`` Dr.Jit threads each and die with this runner (a remote
    scheduler's workers keep their own); ``prepared``: what the kind's ``prepare`` returned."""

    name = "dask"

    def __init__(self, workers: int, threads: int, scheduler: str | None, prepared: Any = None):
        self.cluster = self.client = None
        self.workers = workers
        try:
            if scheduler is None:
                self.context = RunContext(runner=runner_id(), threads=threads, prepared=prepared)
                # Dask's threads (some start as it is imported) and the worker processes they start,
                # now or on a restart, leave Ctrl-C to the runner, which closes the cluster; a stop
                # signal is held until the cluster is whole, so that no half-started part is left.
                # Its logs stay quiet: the runner reports every run's failure in one line, and a
                # worker closed mid-heartbeat would log a traceback. No dashboard; the scheduler's
                # own HTTP routes (health, metrics) take a free port on 127.0.0.1, not 8787, which
                # another cluster may hold (Dask then warns on stderr).
                with deferred(), children_spared_sigint():
                    from distributed import Client, LocalCluster

                    self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                host="127.0.0.1", dashboard_address=None,
                                                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                                silence_logs=logging.CRITICAL)
                    self.client = Client(self.cluster)
            else:
                from distributed import Client

                self.context = RunContext(prepared=prepared)
                self.client = Client(scheduler)
        except BaseException:  # a stop signal (delivered as the block ends) or a failed start: nothing left behind
            with deferred():
                self.close(cancel=True)
            raise

    @property
    def capacity(self) -> int:
        return sys.maxsize  # the scheduler queues; a dying worker costs only its own task

    def submit(self, run: RunSpec, results_dir: str):
        return self.client.submit(execute_run, run, results_dir, self.context, key=f"run-{run.run_id}-{os.urandom(4).hex()}",
                                  pure=False)

    def wait(self, futures, timeout: float | None = None) -> set:
        from distributed import wait

        try:
            done, _ = wait(list(futures), timeout=timeout, return_when="FIRST_COMPLETED")
        except TimeoutError:  # asyncio's, the builtin since Python 3.11
            return set()
        return set(done)

    @staticmethod
    def broken(exc: BaseException) -> bool:
        return False

    def restart(self) -> None:  # pragma: no cover - never broken
        pass

    def close(self, cancel: bool = False) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
