"""The result store: one JSON file per run and a consolidated parquet table.

Layout, under a results folder::

    <experiment>/<run_id>.json      one `RunRecord` per run (done or failed)
    <experiment>/results.parquet    the table: one row per run of the grid, grid order (then its check's)
    <experiment>/work/<run_id>/     the run's own working folder (kinds' artifacts)

Every file is written atomically (`splatbench.report_files`, through `splatbench.fsutil.atomic_write`): a temporary
file ``.<name>.<pid>.<random>.tmp`` in the same folder, flushed and fsync'd, then `os.replace`d onto its name (and the
folder fsync'd). A reader lists only names ``<16 hex>.json``, so it never sees a
temporary file, and a ``<run_id>.json`` is always whole: a process killed
mid-write leaves at most a stray temporary file (removed by the next run when
its process is gone), never a half-written result.

Table columns: ``run_id, experiment, kind, scene, seed, status, error`` (the
deterministic core), ``seconds, started, finished, worker, code, reused_from`` (`VOLATILE_COLUMNS`:
when, where, at which commit and for which experiment it ran), then ``axis.<name>`` (the run's axis labels),
``config.<dotted.path>`` (every resolved config field but scene and seed),
``metric.<name>``, ``notes`` (JSON list, None for none; only when a record has notes), ``warnings`` (JSON list, None
for none) and ``curves`` (JSON text). A column whose values mix types
(``sh_degree`` 0..3 and ``"auto"``) holds their JSON text; lists and tables too.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import socket
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from splatbench.experiments.claims import pid_alive
from splatbench.experiments.configs import flatten
from splatbench.report_files import write_parquet, write_text

#: Version of the per-run file layout.
RECORD_FORMAT = 1
TABLE_NAME = "results.parquet"
WORK_DIR = "work"
STATUSES = ("done", "failed")
CORE_COLUMNS = ("run_id", "experiment", "kind", "scene", "seed", "status", "error")
VOLATILE_COLUMNS = ("seconds", "started", "finished", "worker", "code", "reused_from")

_RESULT_NAME = re.compile(r"^[0-9a-f]{16}\.json$")
_TEMP_NAME = re.compile(  # `splatbench.fsutil.atomic_write`'s temporary files
    r"^\..+\.(\d+)\.[0-9a-f]+\.tmp$")


@dataclass
class RunRecord:
    """The result of one run, as stored in ``<run_id>.json``.

    status: "done" or "failed"; error: one line (``ExcType: message``) when failed;
    traceback: the full traceback of a failure (file only, not in the table);
    config: the resolved nested config; labels: axis name -> label;
    metrics: name -> scalar; curves: JSON value; warnings: the run's one-line warnings
    (`RunResult.warnings`; absent from files written before them); seconds: run time in the worker;
    started, finished: ISO-8601 local times; worker: ``host:pid``; code: the code the run ran
    (`splatbench.versions.code_version`: ``git:<commit>``, ``+dirty`` with local changes; "" in
    files written before runs recorded it); reused_from: the experiment this run ran for when this
    record is a copy of the same run finished there ("" for a run made for this experiment: the
    runner's reuse, `splatbench.experiments.runner.reuse_finished`); notes: the run's one-line notes
    of how it read its inputs (`RunResult.notes`: a train run's loader notes, e.g. "images_8/ read and
    reduced by 3.125", undistortion, masks, the split rule, the SfM start's points); absent from files
    written before them and from a record without notes (written only when there are some, so a record
    without them is byte for byte the earlier format).
    """

    run_id: str
    experiment: str
    kind: str
    scene: str
    seed: int
    status: str
    config: dict[str, Any]
    labels: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    curves: Any = None
    warnings: list[str] = field(default_factory=list)
    error: str | None = None
    traceback: str | None = None
    seconds: float = 0.0
    started: str = ""
    finished: str = ""
    worker: str = ""
    code: str = ""
    reused_from: str = ""
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        data = {"format": RECORD_FORMAT, **asdict(self)}
        if not self.notes:
            del data["notes"]
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RunRecord:
        values = {k: v for k, v in data.items() if k != "format"}
        return cls(**values)

    def row(self) -> dict[str, Any]:
        """This record as one table row (see the module doc for the columns)."""
        row: dict[str, Any] = {c: getattr(self, c) for c in (*CORE_COLUMNS, *VOLATILE_COLUMNS)}
        row.update({f"axis.{k}": v for k, v in self.labels.items()})
        row.update({f"config.{k}": v for k, v in flatten(self.config).items() if k not in ("scene", "seed")}
                   if self.config else {})
        row.update({f"metric.{k}": v for k, v in self.metrics.items()})
        if self.notes:
            row["notes"] = json.dumps(self.notes)
        row["warnings"] = json.dumps(self.warnings) if self.warnings else None
        row["curves"] = None if self.curves is None else json.dumps(self.curves, sort_keys=True)
        return row


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


# --------------------------------------------------------------------------- files
def experiment_dir(results_dir: str | Path, experiment: str) -> Path:
    return Path(results_dir) / experiment


def result_path(results_dir: str | Path, experiment: str, run_id: str) -> Path:
    return experiment_dir(results_dir, experiment) / f"{run_id}.json"


def write_record(results_dir: str | Path, record: RunRecord) -> Path:
    """Write ``record`` to ``<results>/<experiment>/<run_id>.json`` atomically."""
    text = json.dumps(record.to_dict(), indent=1, sort_keys=True)
    path = result_path(results_dir, record.experiment, record.run_id)
    return write_text(path, text)


#: Field types of a stored record (`check_record`); None allowed where the default is None.
_FIELD_TYPES: dict[str, tuple[type, ...]] = {
    "run_id": (str,), "experiment": (str,), "kind": (str,), "scene": (str,), "seed": (int,), "status": (str,),
    "config": (dict,), "labels": (dict,), "metrics": (dict,), "warnings": (list,), "error": (str, type(None)),
    "traceback": (str, type(None)), "seconds": (int, float), "started": (str,), "finished": (str,),
    "worker": (str,), "code": (str,), "reused_from": (str,), "notes": (list,)}


def check_record(data: Any, name: str) -> RunRecord:
    """The `RunRecord` in the parsed JSON ``data`` of the file ``name``; `ValueError` (one
    line naming the field) when a field is missing, extra, of the wrong type, or the
    record cannot become a table row."""
    if not isinstance(data, dict):
        raise ValueError(f"expected a JSON object, got {type(data).__name__}")
    if data.get("format", RECORD_FORMAT) != RECORD_FORMAT:
        raise ValueError(f"format: expected {RECORD_FORMAT}, got {data.get('format')!r}")
    extra = sorted(set(data) - set(_FIELD_TYPES) - {"format", "curves"})
    if extra:
        raise ValueError(f"unknown fields {extra}")
    for key, types in _FIELD_TYPES.items():
        if key not in data:
            if key in ("run_id", "experiment", "kind", "scene", "seed", "status", "config"):
                raise ValueError(f"{key}: missing")
            continue
        value = data[key]
        if not isinstance(value, types) or isinstance(value, bool):
            raise ValueError(f"{key}: expected {' or '.join(t.__name__ for t in types)}, got {value!r:.60}")
    for key in ("warnings", "notes"):
        if not all(isinstance(w, str) for w in data.get(key, [])):
            raise ValueError(f"{key}: expected a list of strings, got {data[key]!r:.60}")
    record = RunRecord.from_dict(data)
    if record.status not in STATUSES:
        raise ValueError(f"status: expected one of {', '.join(STATUSES)}, got {record.status!r:.60}")
    if f"{record.run_id}.json" != name:
        raise ValueError(f"run_id: {record.run_id!r:.40} is not the file's name")
    try:
        record.row()
    except (ValueError, TypeError, AttributeError) as exc:  # InputError is a ValueError
        raise ValueError(f"not a table row ({exc})") from None
    return record


def read_record(path: str | Path, damaged: list[tuple[Path, str]] | None = None) -> RunRecord | None:
    """The record in ``path``, or None when it is missing or not a valid record (then, for
    a file that exists, ``(path, reason)`` is appended to ``damaged``: the run is redone)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        reason = f"unreadable ({type(exc).__name__})"
    else:
        try:
            return check_record(json.loads(text), path.name)
        except (ValueError, TypeError, RecursionError) as exc:  # JSONDecodeError is a ValueError
            reason = " ".join(str(exc).split())[:200] or type(exc).__name__
    if damaged is not None:
        damaged.append((path, reason))
    return None


def read_records(folder: str | Path, damaged: list[tuple[Path, str]] | None = None) -> dict[str, RunRecord]:
    """Every valid record in an experiment folder, by run id; temporary files are never
    read. A damaged result file is skipped (its run is not done) and, given ``damaged``,
    listed there as ``(path, reason)``."""
    folder = Path(folder)
    if not folder.is_dir():
        return {}
    records = {}
    for entry in sorted(os.scandir(folder), key=lambda e: e.name):
        if _RESULT_NAME.match(entry.name) and entry.is_file():
            record = read_record(entry.path, damaged)
            if record is not None:
                records[record.run_id] = record
    return records


def remove_stale_temps(folder: str | Path) -> int:
    """Delete temporary files left by processes of this host that no longer exist."""
    folder = Path(folder)
    if not folder.is_dir():
        return 0
    removed = 0
    for entry in os.scandir(folder):
        m = _TEMP_NAME.match(entry.name)
        if m and not pid_alive(int(m.group(1))):
            Path(entry.path).unlink(missing_ok=True)
            removed += 1
    return removed


# --------------------------------------------------------------------------- table
def build_table(records: Iterable[RunRecord]) -> pd.DataFrame:
    """One row per record, in the given order (module doc: columns)."""
    rows = [r.row() for r in records]
    fixed = [*CORE_COLUMNS, *VOLATILE_COLUMNS]
    extra = sorted({k for row in rows for k in row} - set(fixed) - {"notes", "warnings", "curves"},
                   key=lambda c: (("axis.", "config.", "metric.").index(c[:c.index(".") + 1]), c))
    notes = ["notes"] if any("notes" in row for row in rows) else []  # absent from tables of records without
    columns = [*fixed, *extra, *notes, "warnings", "curves"]
    frame = pd.DataFrame({c: _column([row.get(c) for row in rows]) for c in columns}, columns=columns)
    return frame


def _column(values: list[Any]) -> pd.Series:
    """A column parquet can hold: one scalar type (ints, floats, bools or strings),
    else every non-null value as JSON text."""
    present = [v for v in values if v is not None]
    kinds = {bool if isinstance(v, bool) else (float if isinstance(v, (int, float)) else type(v)) for v in present}
    if kinds <= {bool}:
        return pd.Series(values, dtype="boolean" if present else object)
    if kinds == {float}:
        if all(isinstance(v, int) for v in present):
            return pd.Series(values, dtype="Int64")
        return pd.Series([float("nan") if v is None else float(v) for v in values], dtype="float64")
    if kinds == {str}:
        return pd.Series(values, dtype=object)
    return pd.Series([None if v is None else json.dumps(v, sort_keys=True) for v in values], dtype=object)


def write_table(folder: str | Path, records: Iterable[RunRecord]) -> Path:
    """Build the table of ``records`` and write ``<folder>/results.parquet`` atomically."""
    frame = build_table(records)
    return write_parquet(Path(folder) / TABLE_NAME, frame)


def save_table(folder: str | Path, ids: list[str] | None = None) -> Path:
    """Rewrite ``results.parquet`` from the result files on disk: one row per run of the
    grid ``ids`` that has a record, in grid order (None: the runs of the table as it is, read
    under the lock: records rewritten in place, e.g. by tools/backfill_view_psnr.py). Runners
    sharing the experiment serialise this on ``.table.lock`` (flock), so the last table written
    holds every record written before it."""
    folder = Path(folder)
    with open(folder / ".table.lock", "a+b") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if ids is None:
            ids = [str(i) for i in read_table(folder).run_id]
        records = read_records(folder)
        return write_table(folder, [records[i] for i in ids if i in records])


def read_table(folder: str | Path) -> pd.DataFrame:
    """``<folder>/results.parquet`` as a DataFrame."""
    return pd.read_parquet(Path(folder) / TABLE_NAME)


__all__ = ["RunRecord", "RECORD_FORMAT", "TABLE_NAME", "WORK_DIR", "STATUSES", "CORE_COLUMNS", "VOLATILE_COLUMNS",
           "experiment_dir", "result_path", "write_record", "check_record", "read_record", "read_records",
           "remove_stale_temps", "build_table", "write_table", "save_table", "read_table", "worker_name"]
