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
def report(experiment: Path, results: Path | None, out: Path | None) -> None:
    """Write reports/<name>/report.md, figures/*.png and results.parquet from the
    results of EXPERIMENT.toml, and print the report's path.

    Runs nothing: run the grid first with `splatbench run EXPERIMENT.toml`. Runs without
    a result are counted as "not run" in the report.
    """
    from splatbench.experiments.grid import load_experiment
    from splatbench.reports.report import build_report, write_report

    spec = load_experiment(experiment)
    results = results or spec.runner.results or Path("results")
    out = out or Path("reports") / spec.name
    rep = build_report(spec, results)
    path = write_report(rep, out)
    click.echo(f"{spec.name}: {rep.done} done, {rep.failed} failed, {rep.total - len(rep.table)} not run "
               f"of {rep.total}")
    click.echo(str(path))
