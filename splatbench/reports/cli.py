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
@click.option("--rebuild", is_flag=True,
              help="Rebuild the report from the report folder's own results.parquet (no results folder, nothing "
                   "rerun): after a change to how reports are written. Its runs must be the grid's.")
def report(experiment: Path, results: Path | None, out: Path | None, force: bool, rebuild: bool) -> None:
    """Write reports/<name>/report.md, figures/*.png and results.parquet from the
    results of EXPERIMENT.toml, and print the report's path.

    Runs nothing: run the grid first with `splatbench run EXPERIMENT.toml`. Runs without
    a result are counted as "not run" in the report. Nothing is written, and the exit
    status is 2, when no run of the grid has finished, or when the report folder's
    results.parquet (or check.parquet, the runs of the file's [check]) holds more finished
    runs than the new report would (a partial results folder would shrink it: --force
    replaces it anyway). --rebuild reads the report folder's own results.parquet and
    check.parquet instead of the results folder.
    """
    from splatbench.errors import InputError
    from splatbench.experiments.grid import load_experiment
    from splatbench.experiments.store import TABLE_NAME, experiment_dir
    from splatbench.reports.check import CHECK_TABLE_NAME
    from splatbench.reports.report import build_report, reported_done, write_report

    spec = load_experiment(experiment)
    if rebuild:
        out = out or Path("reports") / spec.name
        path = _rebuild(spec, out)
        click.echo(f"{spec.name}: rebuilt from {out / TABLE_NAME}")
        click.echo(str(path))
        return
    rerun = f"splatbench run {experiment}" + (f" --results {results}" if results is not None else "")
    given_results, given_out = results, out
    results = results or spec.runner.results or Path("results")
    out = out or Path("reports") / spec.name
    rep = build_report(spec, results)
    folder = experiment_dir(results, spec.name)
    if not rep.done:
        failed = f" ({rep.failed} failed)" if rep.failed else ""
        raise InputError(f"{spec.name}: no finished run of the {rep.total} in {folder}{failed}; "
                         f"run `{rerun}` first")
    checked = int((rep.check.table.status == "done").sum()) if rep.check is not None and len(rep.check.table) else 0
    for name, now in ((TABLE_NAME, rep.done), (CHECK_TABLE_NAME, checked)):
        before = None if force else reported_done(out, name)
        if before is not None and before > now:
            raise InputError(f"{out / name}: holds {before} finished runs, the report from {folder} would "
                             f"hold {now}; run the rest with `{rerun}`, or pass --force "
                             f"to replace it")
    path = write_report(rep, out, results=given_results, out_option=given_out)
    click.echo(f"{spec.name}: {rep.done} done, {rep.failed} failed, {rep.total - len(rep.table)} not run "
               f"of {rep.total}" + (f"; {rep.check.headline} ({checked} of its {rep.check.rerun.total} runs done)"
                                    if rep.check is not None else ""))
    click.echo(str(path))


def _rebuild(spec, out: Path) -> Path:
    """Rewrite the report in ``out`` from its own ``results.parquet``; one `InputError` line
    when there is none or its runs are not the grid's (the grid changed: run it again)."""
    import pandas as pd

    from splatbench.errors import InputError
    from splatbench.experiments.grid import check_runs, expand
    from splatbench.experiments.store import TABLE_NAME
    from splatbench.reports.check import CHECK_TABLE_NAME
    from splatbench.reports.report import report_from_table, write_report

    def read(path: Path):
        try:
            return pd.read_parquet(path)
        except Exception as exc:  # noqa: BLE001 - a damaged file from anywhere: one line
            raise InputError(f"--rebuild: {path}: cannot read ({type(exc).__name__}: {exc})") from None

    table_path = out / TABLE_NAME
    if not table_path.is_file():
        raise InputError(f"--rebuild: {table_path} does not exist; report from a results folder instead")
    table = read(table_path)
    runs = expand(spec)
    if "run_id" not in table.columns or list(table.run_id) != [r.run_id for r in runs]:
        raise InputError(f"--rebuild: {table_path} does not hold the runs the grid makes now (the grid or its "
                         f"defaults changed); run `splatbench run {spec.source}` and report from its results")
    checked = None
    if (out / CHECK_TABLE_NAME).is_file():
        checked = read(out / CHECK_TABLE_NAME)
        ids = {r.run_id for r in check_runs(spec)}
        if "run_id" not in checked.columns or not set(checked.run_id) <= ids:
            raise InputError(f"--rebuild: {out / CHECK_TABLE_NAME} holds runs that are not the [check]'s of the "
                             f"file now (its check or defaults changed); run `splatbench run {spec.source}` and "
                             f"report from its results")
    return write_report(report_from_table(spec, table, len(runs), checked), out)
