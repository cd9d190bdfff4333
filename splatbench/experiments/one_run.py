"""The worker side of the runner: `execute_run` runs one `RunSpec` and writes its result.

The executors (`splatbench.experiments.executors`) submit this top-level function to
worker processes, with a `RunContext`: everything the worker needs from the runner
besides the run itself travels there, never through environment variables. It writes
the run's result file atomically before returning its record, so a killed parent loses
nothing that finished (see `runner`).
"""

from __future__ import annotations

import inspect
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from splatbench.errors import one_line
from splatbench.experiments.configs import plain
from splatbench.experiments.grid import RunSpec
from splatbench.experiments.kinds import check_output, get_kind, metric_values
from splatbench.experiments.store import WORK_DIR, RunRecord, experiment_dir, worker_name, write_record
from splatbench.experiments.workers import bound_threads, die_with_runner
from splatbench.versions import code_version


@dataclass(frozen=True)
class RunContext:
    """What the runner hands a worker with every run of one invocation (never part of a run id).

    runner: the runner's ``host:pid:start`` the worker must die with (`die_with_runner`;
        "" for none); threads: the worker's Dr.Jit thread budget (None: leave it);
    prepared: what the kind's ``prepare`` returned in the runner (plain, picklable data,
        e.g. where the rendered datasets are; None without one), passed on to its ``run``.
    """

    runner: str = ""
    threads: int | None = None
    prepared: Any = None


def call_run(run: Callable[..., Any], config: dict[str, Any], workdir: Path, prepared: Any) -> Any:
    """``run(config, workdir, prepared)``; a kind written before ``prepared`` existed (two
    parameters) is called as ``run(config, workdir)``, so a user's kind keeps working."""
    try:
        params = inspect.signature(run).parameters.values()
    except (TypeError, ValueError):  # no signature to read: call as documented
        return run(config, workdir, prepared)
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if len(positional) == 2 and not any(p.kind == p.VAR_POSITIONAL for p in params):
        return run(config, workdir)
    return run(config, workdir, prepared)


def execute_run(run: RunSpec, results_dir: str, context: RunContext = RunContext()) -> dict[str, Any]:
    """Run ``run`` in this process, write its result file atomically, return the record
    (as a dict). A failing kind gives a ``failed`` record with a one-line error."""
    die_with_runner(context.runner)
    started, t0 = datetime.now().astimezone(), time.perf_counter()
    workdir = experiment_dir(results_dir, run.experiment) / WORK_DIR / run.run_id
    record = RunRecord(run_id=run.run_id, experiment=run.experiment, kind=run.kind, scene=run.scene, seed=run.seed,
                       status="done", config=plain(run.config), labels=dict(run.labels), worker=worker_name(),
                       started=started.isoformat(timespec="seconds"), code=code_version())
    try:
        workdir.mkdir(parents=True, exist_ok=True)
        kind = get_kind(run.kind)
        bound_threads(context.threads)
        output = check_output(call_run(kind.run, plain(run.config), workdir, context.prepared), kind)
        record.metrics, record.curves = metric_values(output), output.curves
        record.warnings, record.notes = list(output.warnings), list(output.notes)
    except Exception as exc:  # noqa: BLE001 - every failure of a run is recorded, not raised
        record.status, record.error = "failed", one_line(exc)
        record.traceback = traceback.format_exc()
    record.seconds = round(time.perf_counter() - t0, 6)
    record.finished = datetime.now().astimezone().isoformat(timespec="seconds")
    write_record(results_dir, record)
    return record.to_dict()
