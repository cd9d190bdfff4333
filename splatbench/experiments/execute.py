"""The worker side of the runner: `execute_run` runs one `RunSpec` and writes its result.

The executors (`splatbench.experiments.executors`) submit this top-level function to
worker processes; it writes the run's result file atomically before returning its
record, so a killed parent loses nothing that finished (see `runner`).
"""

from __future__ import annotations

import time
import traceback
from datetime import datetime
from typing import Any

from splatbench.errors import one_line
from splatbench.experiments.configs import plain
from splatbench.experiments.grid import RunSpec
from splatbench.experiments.kinds import check_output, get_kind
from splatbench.experiments.store import WORK_DIR, RunRecord, experiment_dir, worker_name, write_record
from splatbench.experiments.workers import die_with_runner


def execute_run(run: RunSpec, results_dir: str, runner: str = "") -> dict[str, Any]:
    """Run ``run`` in this process, write its result file atomically, return the record
    (as a dict). A failing kind gives a ``failed`` record with a one-line error.
    ``runner``: the runner's ``host:pid:start`` this process must die with
    (`die_with_runner`; "" for none)."""
    die_with_runner(runner)
    started, t0 = datetime.now().astimezone(), time.perf_counter()
    workdir = experiment_dir(results_dir, run.experiment) / WORK_DIR / run.run_id
    record = RunRecord(run_id=run.run_id, experiment=run.experiment, kind=run.kind, scene=run.scene, seed=run.seed,
                       status="done", config=plain(run.config), labels=dict(run.labels), worker=worker_name(),
                       started=started.isoformat(timespec="seconds"))
    try:
        workdir.mkdir(parents=True, exist_ok=True)
        kind = get_kind(run.kind)
        output = check_output(kind.run(plain(run.config), workdir), run.kind)
        record.metrics, record.curves = dict(output.metrics), output.curves
    except Exception as exc:  # noqa: BLE001 - every failure of a run is recorded, not raised
        record.status, record.error = "failed", one_line(exc)
        record.traceback = traceback.format_exc()
    record.seconds = round(time.perf_counter() - t0, 6)
    record.finished = datetime.now().astimezone().isoformat(timespec="seconds")
    write_record(results_dir, record)
    return record.to_dict()
