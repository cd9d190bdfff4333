"""`splatbench run EXPERIMENT.toml`: run an experiment's grid (docs/experiments.md)."""

from __future__ import annotations

import sys
from pathlib import Path

import click


@click.command()
@click.argument("experiment", type=click.Path(path_type=Path, dir_okay=False))
@click.option("--workers", type=int, default=None,
              help="Parallel runs (default: [runner] workers, else one per CPU).")
@click.option("--executor", type=click.Choice(["local", "dask"]), default=None,
              help="local: a process pool; dask: a Dask cluster (default: [runner] executor, else local).")
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
              help="Dask scheduler (with --executor dask; default: a LocalCluster on 127.0.0.1).")
@click.option("--results", type=click.Path(path_type=Path, file_okay=False), default=None,
              help="Results folder (default: [runner] results, else ./results).")
@click.option("--dry-run", is_flag=True, help="Check the runs' dataset folders (file names and image headers), list the "
                                             "runs and whether each is done; run nothing.")
@click.option("--check/--no-check", default=True, show_default=True,
              help="Also run the file's [check] (its headline at another protocol, after the grid's runs).")
@click.option("--check-only", is_flag=True,
              help="Run only the file's [check] (same run ids, resumable), not the grid's runs: to add the check to "
                   "a report whose grid ran elsewhere; then `splatbench report EXPERIMENT.toml --rebuild --results "
                   "DIR`.")
@click.option("--reuse/--no-reuse", default=True, show_default=True,
              help="Copy the runs another experiment in the results folder finished under the same run id and "
                   "config instead of running them again (training runs; each copy names its experiment in "
                   "reused_from; --dry-run marks them 'reusable'). --no-reuse runs the ones not yet copied; a copy "
                   "already made stays (delete its file to run it here).")
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
def run(experiment: Path, workers: int | None, executor: str | None, scheduler: str | None, results: Path | None,
        dry_run: bool, check: bool, check_only: bool, reuse: bool, progress: bool) -> None:
    """Run every pending run of EXPERIMENT.toml and print "done D, skipped S (finished),
    C claimed by another runner, failed F of T".

    Runs whose result says done are skipped, so an interrupted sweep resumes where it
    stopped; failed runs are tried again; runs another live runner holds are left to
    it. A file with a [check] table also runs the check's runs (its headline comparison
    at another protocol; docs/reports.md, "The protocol check") after the grid's, unless
    --no-check; --check-only runs the check's runs alone (to add the check to a committed
    report: `splatbench report EXPERIMENT.toml --rebuild --results DIR` then puts them
    beside the report's own grid runs). A training run that another experiment in the same
    results folder finished (the same run id: the same resolved config) is copied, not run
    again, unless --no-reuse. Exits with status 1 when a run failed.
    """
    from splatbench.experiments.runner import check_only_problem, run_experiment
    from splatbench.experiments.grid import load_experiment

    spec = load_experiment(experiment)
    if check_only:
        check_only_problem(spec, check)
    executor = executor or spec.runner.executor or "local"
    scheduler = scheduler or (spec.runner.scheduler if executor == "dask" else None)
    results = results or spec.runner.results or Path("results")
    workers = workers if workers is not None else spec.runner.workers
    if dry_run:
        _dry_run(spec, results, check, check_only, reuse)
        return
    summary = run_experiment(spec, workers=workers, executor=executor, scheduler=scheduler, results_dir=results,
                             progress=progress, check=check, check_only=check_only, reuse=reuse)
    click.echo(summary.line())
    if summary.failed:
        sys.exit(1)


def _dry_run(spec, results: Path, check: bool, check_only: bool = False, reuse: bool = True) -> None:
    from splatbench.experiments.grid import check_runs, expand
    from splatbench.experiments.store import experiment_dir, read_records

    runs = expand(spec)
    checks = check_runs(spec) if check else []
    if check_only:
        runs = []
    from splatbench.experiments.kinds import get_kind
    from splatbench.experiments.runner import check_inputs, find_reusable

    inputs = check_inputs(spec, [*runs, *checks])  # one line and nothing listed when a run cannot read its data
    records = read_records(experiment_dir(results, spec.name))
    pending = [r for r in (*runs, *checks) if r.run_id not in records or records[r.run_id].status != "done"]
    reusable = find_reusable(Path(results), spec, pending) if reuse and get_kind(spec.kind).reusable else {}
    for r, tag in [*((r, "") for r in runs), *((r, f"  check: protocol={spec.check.protocol}") for r in checks)]:
        status = records[r.run_id].status if r.run_id in records else "pending"
        if status == "done" and records[r.run_id].reused_from:
            tag += f"  (reused from {records[r.run_id].reused_from})"
        elif r.run_id in reusable:
            status = "reusable"
            source = reusable[r.run_id][1]
            tag += f"  (from {source.reused_from or source.experiment})"
        labels = " ".join(f"{k}={v}" for k, v in r.labels.items())
        click.echo(f"{r.run_id}  {status:<8}  {r.scene}  seed={r.seed}  {labels}{tag}".rstrip())
    for line in inputs:
        click.echo(line)
    total = len(runs) + len(checks)
    click.echo(f"{total} run{'' if total == 1 else 's'} in {experiment_dir(results, spec.name)}"
               + (" (the check's only; the grid's left out)" if check_only else
                  f" ({len(checks)} of them the check)" if checks else ""))


if __name__ == "__main__":  # python -m splatbench.experiments.cli EXPERIMENT.toml ...
    from splatbench.cli import main

    main(["run", *sys.argv[1:]], prog_name="splatbench")
