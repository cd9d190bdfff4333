"""`splatbench report EXPERIMENT.toml`: write an experiment's report (docs/reports.md)."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("experiment", type=click.Path(path_type=Path, dir_okay=False))
@click.option("--results", type=click.Path(path_type=Path, file_okay=False), default=None,
              help="Results folder (default: the file's [runner] results, else ./results).")
@click.option("--out", type=click.Path(path_type=Path, file_okay=False), default=None,
              help="Report folder (default: reports/<name>).")
@click.option("--force", is_flag=True,
              help="Replace a report folder whose results.parquet holds more finished runs than the new report.")
def report(experiment: Path, results: Path | None, out: Path | None, force: bool) -> None:
    """Write reports/<name>/report.md, figures/*.png and results.parquet from the
    results of EXPERIMENT.toml, and print the report's path.

    Runs nothing: run the grid first with `splatbench run EXPERIMENT.toml`. Runs without
    a result are counted as "not run" in the report. Nothing is written, and the exit
    status is 2, when no run of the grid has finished, or when the report folder's
    results.parquet holds more finished runs than the new report would (a partial results
    folder would shrink it: --force replaces it anyway).
    """
    from splatbench.errors import InputError
    from splatbench.experiments.grid import load_experiment
    from splatbench.experiments.store import TABLE_NAME, experiment_dir
    from splatbench.reports.report import build_report, reported_done, write_report

    spec = load_experiment(experiment)
    rerun = f"splatbench run {experiment}" + (f" --results {results}" if results is not None else "")
    results = results or spec.runner.results or Path("results")
    out = out or Path("reports") / spec.name
    rep = build_report(spec, results)
    folder = experiment_dir(results, spec.name)
    if not rep.done:
        failed = f" ({rep.failed} failed)" if rep.failed else ""
        raise InputError(f"{spec.name}: no finished run of the {rep.total} in {folder}{failed}; "
                         f"run `{rerun}` first")
    before = None if force else reported_done(out)
    if before is not None and before > rep.done:
        raise InputError(f"{out / TABLE_NAME}: holds {before} finished runs, the report from {folder} would "
                         f"hold {rep.done}; run the rest with `{rerun}`, or pass --force "
                         f"to replace it")
    path = write_report(rep, out)
    click.echo(f"{spec.name}: {rep.done} done, {rep.failed} failed, {rep.total - len(rep.table)} not run "
               f"of {rep.total}")
    click.echo(str(path))
