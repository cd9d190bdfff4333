"""The runner: execute an experiment's pending runs in parallel, resumably.

`run_experiment` expands the grid (every config checked before anything runs) and,
after the grid's runs, the runs of the experiment's ``[check]`` (its headline at another
protocol, `splatbench.experiments.grid.check_runs`; ``check=False`` leaves them out),
skips the runs whose result file already says ``done``, and submits the rest to
an executor, interleaved (`execution_order`: seed by seed, and within a seed scene by
scene, every cell in turn), so that runs one after another belong to different cells and
a machine that drifts (another process's load, the time of day) spreads over every cell
instead of landing on whichever cell ran then; the results table keeps `expand`'s order.
Failed runs are *not* skipped: they run again on the next invocation (delete nothing; a
new result replaces the old file).

Both executors share one code path: the parent submits the top-level function
`execute_run(run, results_dir, context)`, which runs the kind in a worker process and writes
that run's result file itself, atomically, before returning its record. A parent
killed at any point therefore loses nothing that finished, and the next
invocation resumes from the files. After every finished run the parent rewrites
the table (``results.parquet``) from the records, so it is in step with the files.

Runners sharing an experiment (two ``splatbench run`` at once, on one host or on
hosts sharing the results folder) split its grid: each run is claimed before it is
submitted (`splatbench.experiments.claims`) and the table is rewritten from the
files on disk (`store.save_table`), so every run is done once and the table holds
one row per run. Workers die with their runner (`splatbench.experiments.workers`);
a runner stopped by SIGTERM / SIGINT stops its workers and releases its claims
before it raises `splatbench.interrupt.Interrupted`.

Executors:
    local  `concurrent.futures.ProcessPoolExecutor` (``spawn``), ``workers`` processes.
           At most ``workers`` runs are in flight, so when a worker process dies
           (a crash in native code) the runs it may have held are known: each is
           retried alone, and the one that kills its worker again is recorded as
           failed.
    dask   `dask.distributed`: the client of ``scheduler`` (``tcp://HOST:PORT``), or a
           `LocalCluster` of ``workers`` single-threaded worker processes bound to
           127.0.0.1 (no dashboard). With a remote scheduler, ``results_dir`` should be
           a folder every worker sees (a shared file system); where it is not, the
           parent writes the returned record itself.

Each run reaches its worker with a `RunContext` (`splatbench.experiments.one_run`):
the worker's Dr.Jit thread budget, max(1, CPUs // workers), so that parallel runs
do not oversubscribe the machine (a remote scheduler's workers keep their own), and
what the kind's ``prepare`` returned in the parent (e.g. the train kind's datasets
folder). The runner sets no environment variable for its workers.
"""

from __future__ import annotations

import sys
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Any

from splatbench.errors import InputError, one_line
from splatbench.experiments.claims import HEARTBEAT_EVERY, RunClaim, held, remove_stale_claim_temps, try_claim
from splatbench.experiments.configs import plain
from splatbench.experiments.executors import DaskExecutor, LocalExecutor
from splatbench.experiments.grid import RunSpec, check_runs, expand
from splatbench.experiments.kinds import get_kind
from splatbench.experiments.spec import EXECUTORS, ExperimentSpec, check_scheduler
from splatbench.experiments.store import (RunRecord, experiment_dir, read_record, read_records, remove_stale_temps,
                                          result_path, save_table, write_record)
from splatbench.interrupt import Interrupted, deferred
from splatbench.metrics.load import usable_cores



@dataclass(frozen=True)
class RunSummary:
    """What one invocation did: ``done`` ran and succeeded now, ``skipped`` were
    already done (by an earlier invocation or, meanwhile, by another runner),
    ``failed`` ran and failed now, ``claimed`` were held by another live runner
    (see `splatbench.experiments.claims`); the four add up to ``total``."""

    done: int
    skipped: int
    failed: int
    total: int
    folder: Path
    claimed: int = 0
    warned: int = 0  # of ``done``, runs that warned of something (`RunResult.warnings`)
    reused: int = 0  # of ``skipped``, runs copied from another experiment's folder (`reuse_finished`)

    def line(self) -> str:
        warned = f" ({self.warned} warned: see their report's \"Warnings\")" if self.warned else ""
        reused = f", {self.reused} of them reused from another experiment" if self.reused else ""
        return (f"done {self.done}{warned}, skipped {self.skipped} (finished{reused}), {self.claimed} claimed by "
                f"another runner, failed {self.failed} of {self.total}")


class WarningTally:
    """The distinct warnings of an invocation's runs (`RunRecord.warnings`), in the order first
    seen, each with the number of runs that gave it: a run's warning is shown in full the first
    time any run gives it (`first_seen`); identical ones after it are counted, not repeated, and
    `summary` lists each warning that several runs gave with its count (``x 57``)."""

    def __init__(self) -> None:
        self.runs: dict[str, int] = {}  # warning -> runs that gave it, in the order first seen

    def first_seen(self, warnings: list[str]) -> list[str]:
        """Count a run's ``warnings`` (each once per run); return those no earlier run gave, in order."""
        new = [w for w in dict.fromkeys(warnings) if w not in self.runs]
        for w in dict.fromkeys(warnings):
            self.runs[w] = self.runs.get(w, 0) + 1
        return new

    def summary(self, name: str) -> list[str]:
        """One line per warning that more than one run gave (``NAME: x 57 runs warned: TEXT``),
        after a header line; [] when every warning came from one run (each was shown with it)."""
        repeated = [(w, n) for w, n in self.runs.items() if n > 1]
        if not repeated:
            return []
        return [f"{name}: {len(self.runs)} distinct warnings from this invocation's runs, each shown above with "
                f"the first run that gave it; given by several runs:",
                *(f"{name}: x {n} runs warned: {w}" for w, n in repeated)]


# --------------------------------------------------------------------------- parent side
def run_experiment(spec: ExperimentSpec, *, workers: int | None = None, executor: str = "local",
                   scheduler: str | None = None, results_dir: str | Path, progress: bool = True,
                   known_scenes: Callable[[], set[str]] | None = None, check: bool = True,
                   check_only: bool = False, reuse: bool = True) -> RunSummary:
    """Run every pending run of ``spec``; return the counts.

    workers: parallel runs (None: one per CPU); executor: "local" or "dask";
    scheduler: Dask scheduler address (dask only; None: a loopback LocalCluster);
    results_dir: folder holding ``<experiment>/``; progress: a tqdm bar on stderr;
    check: also run the experiment's ``[check]`` (after the grid's runs, in the same folder,
    each under its own run id; counted in the summary). The grid and the check are expanded
    and checked before any executor starts (`InputError`). Runs are submitted interleaved
    (`execution_order`), the grid's and then the check's; the table is in `expand`'s order.
    check_only: run the check's runs alone (the same run ids; the grid's are neither run nor
    counted, and the folder's table still lists those of them that have a result): to add the
    check to a report whose grid ran elsewhere (docs/reports.md, "The protocol check"). One
    `InputError` line for a file without a ``[check]``, or with ``check=False``.
    reuse: first copy into this folder the runs that another experiment in ``results_dir`` finished
    under the same run id and config (`reuse_finished`; only for a kind that is ``reusable``); they
    count as skipped.
    """
    if check_only:
        check_only_problem(spec, check)
    if executor not in EXECUTORS:
        raise InputError(f"executor: expected one of {', '.join(EXECUTORS)}, got {executor!r}")
    if scheduler is not None:
        if executor != "dask":
            raise InputError(f"scheduler: only with executor 'dask', got executor {executor!r}")
        check_scheduler(scheduler)
    cpus = usable_cores()  # the cores this process may run on (`taskset -c 0 splatbench run` gets one)
    workers = cpus if workers is None else workers
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise InputError(f"workers: expected an int >= 1, got {workers!r}")

    grid = expand(spec, known_scenes=known_scenes)
    checks = check_runs(spec) if check else []
    check_inputs(spec, [*grid, *checks])
    table_ids = [r.run_id for r in (*grid, *checks)]  # the folder's table: every run this folder may hold
    if check_only:
        grid = []
    runs = [*grid, *checks]  # the table's order
    order = [*execution_order(grid), *execution_order(checks)]  # the order they are submitted in
    results_dir = Path(results_dir).absolute()  # workers may run elsewhere (another cwd, a Dask host)
    folder = experiment_dir(results_dir, spec.name)
    folder.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(folder)
    remove_stale_claim_temps(folder)
    ids = [r.run_id for r in runs]
    damaged: list[tuple[Path, str]] = []
    records = {rid: rec for rid, rec in read_records(folder, damaged).items() if rid in set(ids)}
    pending = [r for r in order if r.run_id not in records or records[r.run_id].status != "done"]
    reused: list[RunRecord] = []
    if reuse and pending and get_kind(spec.kind).reusable:
        reused = reuse_finished(results_dir, spec, pending)
        records.update((r.run_id, r) for r in reused)
        pending = [r for r in pending if r.run_id not in records or records[r.run_id].status != "done"]
    skipped = len(runs) - len(pending)

    copied = {r.run_id: r.reused_from for r in reused}
    for path, reason in damaged:  # the run was pending: a copy or its new result replaces the file
        again = (f"copied again from {copied[path.stem]}" if path.stem in copied else "redone")
        _log(f"{spec.name}: damaged result file {path.name} ({reason}); its run is {again}")
    save_table(folder, table_ids)
    of_check = (f" (the check's at {spec.check.protocol} only; the grid's left out)" if check_only else
                f" ({len(checks)} of them the check at {spec.check.protocol})" if checks else
                f" (the check at {spec.check.protocol} left out)" if spec.check is not None else "")
    of_reused = ""
    if reused:
        sources = sorted({r.reused_from for r in reused})
        of_reused = (f" ({len(reused)} of them reused: the same run id and config finished for "
                     f"{', '.join(sources)} in {results_dir})")
    _log(f"{spec.name}: {len(runs)} runs{of_check}, {skipped} already done{of_reused}, {len(pending)} to run "
        f"({executor}, {workers} worker{'s' * (workers != 1)}); results in {folder}")
    if not pending:
        return RunSummary(done=0, skipped=skipped, failed=0, total=len(runs), folder=folder, reused=len(reused))

    kind = get_kind(spec.kind)
    prepared = None if kind.prepare is None else kind.prepare([plain(r.config) for r in pending])

    threads = max(1, cpus // workers)
    done = failed = claimed = warned = 0
    tally = WarningTally()
    claims: dict[str, RunClaim] = {}
    bar = _progress_bar(len(pending), spec.name, progress)

    share = reuse and get_kind(spec.kind).reusable

    def admit(run: RunSpec) -> bool:
        """Claim ``run`` before it is submitted; False when another runner holds it or finished it
        meanwhile, this experiment's or, for a run of the same id, another experiment's in
        ``results_dir`` (then the finished one is copied and the held one left to its runner, which
        the next invocation copies). Claimed first, then looked at, so that two runners never both
        run it: each holds its own experiment's claim while it looks at the other's."""
        nonlocal skipped, claimed
        claim = try_claim(folder, run.run_id)
        if claim is None:
            claimed += 1
        else:
            record = read_record(result_path(results_dir, spec.name, run.run_id))
            if record is not None and record.status == "done":
                skipped += 1
            elif share and any(held(other, run.run_id) for other in _other_folders(results_dir, spec)):
                claimed += 1
            elif share and (source := find_reusable(results_dir, spec, [run]).get(run.run_id)) is not None:
                copy = _copy_held(results_dir, spec, run, source[1])
                if copy is not None:
                    reused.append(copy)
                save_table(folder, table_ids)
                skipped += 1
            else:
                claims[run.run_id] = claim
                return True
            claim.release()
        if bar is not None:
            bar.update(1)
        return False

    def heartbeat() -> None:
        for claim in list(claims.values()):
            claim.touch()

    def say(line: str) -> None:
        """A run's failure or warning, on stderr as it finishes (above the bar, when there is one)."""
        if bar is not None:
            bar.write(line)
        else:
            print(line, file=sys.stderr, flush=True)

    def finish(record: RunRecord) -> None:
        nonlocal done, failed, warned
        with deferred():  # a record and its claim change together
            on_disk = read_record(result_path(results_dir, spec.name, record.run_id))
            if on_disk is None or on_disk.to_dict() != record.to_dict():
                # a failure the parent recorded, or a remote worker without a shared results folder
                write_record(results_dir, record)
            claim = claims.pop(record.run_id, None)
            if claim is not None:
                claim.release()
            save_table(folder, table_ids)
        if record.status == "done":
            done += 1
            if record.warnings:
                warned += 1
                new = tally.first_seen(record.warnings)  # each distinct warning once, in full; repeats counted
                for warning in new:
                    say(f"{spec.name}: run {record.run_id} ({record.scene}, seed {record.seed}) warned: {warning}")
        else:
            failed += 1
            say(f"{spec.name}: run {record.run_id} ({record.scene}, seed {record.seed}) failed: {record.error}")
        if bar is not None:
            bar.set_postfix(failed=failed, refresh=False)
            bar.update(1)

    pool = None
    try:
        pool = LocalExecutor(workers, threads, prepared) if executor == "local" else \
            DaskExecutor(workers, threads, scheduler, prepared)
        _drive(pool, pending, str(results_dir), finish, admit=admit, heartbeat=heartbeat)
    except BaseException as exc:
        with deferred():
            if pool is not None:  # an executor that fails to start closes what it started itself
                pool.close(cancel=True)
            stopped = len(claims)
            for claim in claims.values():
                claim.release()
            claims.clear()
        if isinstance(exc, Interrupted):
            raise Interrupted(exc.signum, f"kept {done} runs finished now in {folder}; {stopped} in flight "
                                          f"stopped (they run again next time)") from None
        raise
    else:
        pool.close()
    finally:
        if bar is not None:
            bar.close()
        for line in tally.summary(spec.name):  # interrupted too: what the finished runs warned of
            _log(line)
    return RunSummary(done=done, skipped=skipped, failed=failed, total=len(runs), folder=folder, claimed=claimed,
                      warned=warned, reused=len(reused))


def reuse_finished(results_dir: Path, spec: ExperimentSpec, runs: list[RunSpec]) -> list[RunRecord]:
    """Copy into ``spec``'s folder each of ``runs`` that another experiment's folder in
    ``results_dir`` holds finished: a done record of the same run id whose kind, scene, seed
    and resolved config are this run's. A run id hashes the resolved config (a train run's
    dataset by its content), so it is the same run; the copy takes this experiment's name and
    axis labels and ``reused_from`` = the experiment it ran for (the first one, through copies
    of copies); its metrics, curves, times and code are the original's. A run another runner
    of this experiment holds (`splatbench.experiments.claims`) is left to it. Returns the
    records written."""
    folder = experiment_dir(results_dir, spec.name)
    written: list[RunRecord] = []
    for run, source in find_reusable(results_dir, spec, runs).values():
        claim = try_claim(folder, run.run_id)
        if claim is None:
            continue
        try:
            record = _copy_held(results_dir, spec, run, source)
        finally:
            claim.release()
        if record is not None:
            written.append(record)
    return written


def _copy_held(results_dir: Path, spec: ExperimentSpec, run: RunSpec, source: RunRecord) -> RunRecord | None:
    """Write ``source`` (another experiment's done record of ``run``) as ``spec``'s record of it, the
    caller holding ``spec``'s claim on it; None, writing nothing, where ``spec``'s folder holds a done
    record of it already (finished by a runner of this experiment since the caller looked: never
    overwritten by a copy)."""
    own = read_record(result_path(results_dir, spec.name, run.run_id))
    if own is not None and own.status == "done":
        return None
    with deferred():
        record = replace(source, experiment=spec.name, labels=dict(run.labels),
                         reused_from=source.reused_from or source.experiment)
        write_record(results_dir, record)
    return record


def find_reusable(results_dir: Path, spec: ExperimentSpec,
                  runs: list[RunSpec]) -> dict[str, tuple[RunSpec, RunRecord]]:
    """Run id -> (run, the record to copy) for each of ``runs`` that another experiment's folder in ``results_dir`` holds finished (the
    first such folder by name): a done record of the same run id whose kind, scene, seed and
    resolved config are the run's (`reuse_finished`, which copies them; ``--dry-run`` lists them).
    Nothing is written."""
    others = _other_folders(results_dir, spec)
    found: dict[str, tuple[RunSpec, RunRecord]] = {}
    for run in runs:
        for other in others:
            source = read_record(other / f"{run.run_id}.json")
            if (source is not None and source.status == "done" and source.kind == spec.kind
                    and source.scene == run.scene and source.seed == run.seed and source.config == plain(run.config)):
                found[run.run_id] = (run, source)
                break
    return found


def _other_folders(results_dir: Path, spec: ExperimentSpec) -> list[Path]:
    """The other experiments' folders in ``results_dir``, by name."""
    results_dir = Path(results_dir)
    return sorted(p for p in results_dir.iterdir() if p.is_dir() and p.name != spec.name) \
        if results_dir.is_dir() else []


def check_inputs(spec: ExperimentSpec, runs: list[RunSpec]) -> list[str]:
    """The kind's cheap checks of what ``runs`` will read (`RunKind.check_inputs`: the train
    kind's dataset folders, from file names and image headers): one `InputError` line
    ``SOURCE: scenes.NAME: problem and fix`` before anything runs (and in ``--dry-run``);
    else the kind's line per input checked ([] for a kind without the check)."""
    kind = get_kind(spec.kind)
    if kind.check_inputs is None or not runs:
        return []
    try:
        return kind.check_inputs([plain(r.config) for r in runs])
    except InputError as exc:
        raise InputError(f"{spec.source}: {exc}") from None


def check_only_problem(spec: ExperimentSpec, check: bool = True) -> None:
    """One `InputError` line where ``--check-only`` cannot run: a file without a ``[check]``,
    or with the check left out (``--no-check``)."""
    if not check:
        raise InputError("--check-only: runs only the file's [check], --no-check leaves it out; give one of the two")
    if spec.check is None:
        raise InputError(f"{spec.source}: --check-only: the file has no [check] table, so there is nothing to run "
                         f"(add one: docs/reports.md, \"The protocol check\"; or run the grid with `splatbench run "
                         f"{spec.source}`)")


def execution_order(runs: list[RunSpec]) -> list[RunSpec]:
    """``runs`` (in `expand`'s order: scene, then cell, then seed) reordered seed-major: for
    each seed, for each scene, every cell in turn (cells in their order in ``runs``).
    Seeds and scenes rank by where they first appear in ``runs``; the sort is stable, so
    within one seed and scene the cells keep their order. The same runs, none dropped."""
    seed_rank: dict[int, int] = {}
    scene_rank: dict[str, int] = {}
    for run in runs:
        seed_rank.setdefault(run.seed, len(seed_rank))
        scene_rank.setdefault(run.scene, len(scene_rank))
    return sorted(runs, key=lambda run: (seed_rank[run.seed], scene_rank[run.scene]))


def _drive(pool, pending: list[RunSpec], results_dir: str, finish: Callable[[RunRecord], None], *,
           admit: Callable[[RunSpec], bool] = lambda run: True, heartbeat: Callable[[], None] = lambda: None) -> None:
    """Submit runs (at most ``pool.capacity`` in flight, each only once ``admit`` says
    so), collect them, recover from a broken local pool: suspects (runs in flight when
    a worker died) are retried one at a time; a suspect that breaks the pool alone is
    recorded as failed. ``heartbeat`` is called at least every `HEARTBEAT_EVERY` s."""
    queue: deque[RunSpec] = deque(pending)
    ready: deque[RunSpec] = deque()  # admitted, not yet submitted (the pool broke at submission)
    suspects: deque[RunSpec] = deque()
    inflight: dict[Any, RunSpec] = {}
    isolating = False

    def submit(run: RunSpec, back: deque[RunSpec]) -> bool:
        try:
            inflight[pool.submit(run, results_dir)] = run
            return True
        except Exception as exc:  # a worker died since the last wait: the pool refuses new work
            if not pool.broken(exc):
                raise
            back.appendleft(run)
            return False

    while queue or ready or suspects or inflight:
        if not inflight:
            isolating = bool(suspects)
        broke = False
        if isolating:
            if not inflight and suspects:
                broke = not submit(suspects.popleft(), suspects)
        else:
            while (ready or queue) and len(inflight) < pool.capacity and not broke:
                if ready:
                    broke = not submit(ready.popleft(), ready)
                else:
                    run = queue.popleft()
                    if admit(run):
                        broke = not submit(run, ready)
        if broke and not inflight:
            pool.restart()
            continue
        if not inflight:
            continue
        heartbeat()
        for fut in pool.wait(inflight, timeout=HEARTBEAT_EVERY):
            run = inflight.pop(fut)
            exc = fut.exception()
            if exc is None:
                finish(RunRecord.from_dict(fut.result()))
            elif pool.broken(exc):
                broke = True
                if isolating:
                    finish(_failed(run, "worker process died while running it (a crash, or killed)"))
                else:
                    suspects.append(run)
            else:
                finish(_failed(run, one_line(exc)))
        broke = broke or getattr(pool, "stalled", False)  # a dead worker the pool missed (executors.py)
        if broke:
            suspects.extend(inflight.values())  # empty when isolating
            inflight.clear()
            pool.restart()
            _collect_written(suspects, results_dir, finish)


def _collect_written(suspects: deque[RunSpec], results_dir: str, finish) -> None:
    """Suspects whose ``done`` result file was written before the pool broke are finished
    (a pending run had no ``done`` file when the invocation started)."""
    for run in list(suspects):
        record = read_record(result_path(results_dir, run.experiment, run.run_id))
        if record is not None and record.status == "done":
            suspects.remove(run)
            finish(record)


def _failed(run: RunSpec, error: str) -> RunRecord:
    now = datetime.now().astimezone().isoformat(timespec="seconds")
    return RunRecord(run_id=run.run_id, experiment=run.experiment, kind=run.kind, scene=run.scene, seed=run.seed,
                     status="failed", config=plain(run.config), labels=dict(run.labels), error=error,
                     started=now, finished=now, worker="")


def _progress_bar(total: int, name: str, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=name, unit="run", file=sys.stderr, dynamic_ncols=True)


def _log(line: str) -> None:
    """One of the runner's one-line notes on stderr (what it will run, what it reused, a damaged
    file), with or without a progress bar: ``progress`` turns off the bar, not what a user must know."""
    print(line, file=sys.stderr, flush=True)


__all__ = ["RunSummary", "WarningTally", "check_inputs", "execution_order", "find_reusable", "reuse_finished", "run_experiment"]
