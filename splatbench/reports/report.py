"""`build_report` / `write_report`: an experiment's results as ``report.md`` with figures.

    spec = load_experiment("experiments/sh_degree.toml")
    report = build_report(spec, "results")            # Report: tables, findings, the run table
    path = write_report(report, "reports/sh_degree")   # report.md, figures/*.png, results.parquet

The report describes the grid *as the file now writes it*: the runs are the file's
expansion (`splatbench.experiments.expand`), read from their per-run result files,
so a report is never built from a stale table. What is written, under ``out``:

* ``report.md``: a summary (`summary_lines`: each axis's `Finding.summary`, the settling marks, the
  check's verdict), a header (runs done / failed / not run, shared settings, the protocol, run time),
  one section per axis (a table of mean ± 95 % t interval over seeds of each axis value, per
  scene; the primary metric's findings; the training curves), the check's section, the published numbers the
  file declares beside the grid's own (`splatbench.reports.published`), each Pareto figure the
  kind declares (a cost against quality, the cells on the front named), the runs' warnings
  (`RunResult.warnings`, one row each) and any failed runs; then the appendix (``## Appendix: ...``):
  each axis's other comparisons and notes (`Finding.appendix`), the run findings of `APPENDIX_FINDINGS`,
  the check's other tables and the metrics' meanings.
* ``figures/curves_<axis>.png``; the kind's Pareto figures (`KindReport.tradeoffs`):
  ``figures/time_vs_error.png`` and ``figures/gaussians_vs_error.png`` (train kind) or
  ``figures/speed_vs_error.png`` (raster kind).
* ``results.parquet``: the run table the report was built from (the engine's columns:
  ``run_id, scene, seed, status, ..., axis.*, config.*, metric.*, warnings, curves``).
* ``check.parquet``: the runs of the experiment's ``[check]`` that have a result, in the same
  columns (the section "Headline at the 7K protocol", `splatbench.reports.check`); absent when
  none has.
"""

from __future__ import annotations

import json
import math
import shutil
import dataclasses
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import pandas as pd

from splatbench.errors import InputError
from splatbench.experiments.grid import expand
from splatbench.experiments.kind_report import Tradeoff
from splatbench.experiments.kinds import RunKind
from splatbench.experiments.spec import ExperimentSpec
from splatbench.experiments.store import TABLE_NAME, build_table, experiment_dir, read_records
from splatbench.plotting import pareto_figure
from splatbench.metrics.spec import MetricSpec
from splatbench.report_files import markdown_table, write_parquet, write_text
from splatbench.reports.check import APPENDIX_TITLE as CHECK_APPENDIX
from splatbench.reports.check import (CHECK_TABLE_NAME, CheckResult, check_appendix_lines, check_lines, check_result,
                                      check_table, header_line)
from splatbench.reports.figures import cell_means, curves_figure
from splatbench.reports.findings import Finding, axis_finding, bytes_differ, load_recorded, usable_runs
from splatbench.reports.published import published_lines
from splatbench.reports.ranks import quick_table, rank_finding
from splatbench.reports.settling import settling_finding
from splatbench.reports.tables import AxisTable, axis_table, cell_labels, display, loaded_runs, metric_specs

REPORT_NAME = "report.md"
FIGURES = "figures"

def interval_note(max_seeds: int) -> str:
    """How a table's cells are written, for the number of seeds its cells have."""
    if max_seeds < 2:
        return ("Mean over seeds; one seed per cell, so no interval can be computed (n = 1): differences between "
                "rows cannot be told from seed-to-seed noise")
    return ("Mean ± half-width of the 95 % Student's t interval over seeds (n − 1 degrees of freedom; a seed's "
            "runs are averaged first); a cell with one seed shows its mean alone, and \"(no spread)\" marks a cell "
            "whose seeds did not vary it at the precision shown (no interval: see the protocol above for what a "
            "seed varies); where mean ± half-width would cross the metric's range (SSIM ≤ 1; PSNR, LPIPS, counts "
            "and times ≥ 0), the cell prints the interval cut at the bound, `0.9981 [0.9952, 1.0000]`, and so "
            "does every difference or mean in the findings")


@dataclass
class Report:
    """An experiment's report before it is written.

    spec: the experiment; kind: its run kind (what it declares of its reports); table: one row
    per run of the grid that has a result (grid order; `splatbench.experiments.store` columns);
    total: runs in the grid;
    metrics: the metrics shown; axes: one `AxisTable` per axis; findings: axis name (or
    "parity") -> `Finding`; fronts: Pareto figure stem -> scene -> Pareto-optimal cell
    labels, cheapest first (filled when written); check: the experiment's ``[check]``, its
    headline at another protocol (None: the file declares none).
    """

    spec: ExperimentSpec
    kind: RunKind
    table: pd.DataFrame
    total: int
    metrics: tuple[MetricSpec, ...]
    axes: list[AxisTable]
    findings: dict[str, Finding]
    fronts: dict[str, dict[str, list[str]]] = field(default_factory=dict)
    check: CheckResult | None = None

    @property
    def done(self) -> int:
        return int((self.table.status == "done").sum()) if len(self.table) else 0

    @property
    def failed(self) -> int:
        return int((self.table.status == "failed").sum()) if len(self.table) else 0


def grid_table(spec: ExperimentSpec, results_dir: str | Path) -> tuple[pd.DataFrame, int]:
    """(The table of the grid's runs that have a result file, in grid order; runs in the grid)."""
    runs = expand(spec)
    records = read_records(experiment_dir(results_dir, spec.name))
    return build_table([records[r.run_id] for r in runs if r.run_id in records]), len(runs)


def build_report(spec: ExperimentSpec, results_dir: str | Path) -> Report:
    """Tables and findings of ``spec``'s results under ``results_dir`` (nothing written), and
    its check's (`splatbench.reports.check`)."""
    table, total = grid_table(spec, results_dir)
    return report_from_table(spec, table, total, check_table(spec, results_dir))


def report_from_table(spec: ExperimentSpec, table: pd.DataFrame, total: int,
                      checked: pd.DataFrame | None = None) -> Report:
    """Tables and findings of a run table (`grid_table`'s, or a report's ``results.parquet``
    read back) of ``spec``'s grid of ``total`` runs; ``checked``: the runs of its ``[check]``
    that have a result (`check_table`, or a report's ``check.parquet``; None: none). The minimum effects: the
    kind's, those that depend on how the runs measured (`KindReport.min_effects`), the file's own over both."""
    kind = spec.run_kind
    if kind.report is not None and kind.report.min_effects is not None:  # e.g. LPIPS on the runs' net's scale
        spec = dataclasses.replace(spec, min_effect={**kind.report.min_effects(table), **spec.min_effect})
    metrics = metric_specs(kind, table)
    axes = [axis_table(spec, kind, axis, table, metrics) for axis in spec.dimensions]
    findings: dict[str, Finding] = {}
    for t in axes:
        f = axis_finding(t, kind, table, spec.min_effect, spec)
        if f is not None:
            findings[t.axis] = f
    hooks = kind.report.run_findings if kind.report is not None else ()
    quick, quick_path = quick_table(spec)
    for f in (settling_finding(table, kind, spec.min_effect), *(make(table, spec.min_effect) for make in hooks),
              rank_finding(spec, kind, table, quick, quick_path)):
        if f is not None:  # a run finding: its own section, named by its axis
            findings[f.axis] = f
    return Report(spec, kind, table, total, metrics, axes, findings, check=check_result(spec, kind, table, checked))


def reported_done(out: str | Path, name: str = TABLE_NAME) -> int | None:
    """Runs with status ``done`` in the report folder ``out``'s ``results.parquet`` (``name``:
    ``check.parquet``, its check's); None when ``out`` holds no such table (what `splatbench
    report` compares before it replaces a report, so that a partial results folder cannot
    shrink a baseline)."""
    path = Path(out) / name
    if not path.is_file():
        return None
    try:
        status = pd.read_parquet(path, columns=["status"]).status
    except Exception as exc:  # noqa: BLE001 - any unreadable table is one line, not a traceback
        raise InputError(f"{path}: cannot be read as a report table ({type(exc).__name__}); "
                         f"pass --force to replace the report") from None
    return int((status == "done").sum())


def write_report(report: Report, out: str | Path, *, results: str | Path | None = None,
                 out_option: str | Path | None = None, check_results: str | Path | None = None) -> Path:
    """Write ``report.md``, ``figures/*.png`` and ``results.parquet`` under ``out``; the
    report's path. Figures of an earlier report in ``out/figures`` are removed first.
    ``results`` / ``out_option``: the ``--results`` / ``--out`` the report was made with,
    where not the defaults, so that the commands the report names are the ones that made it;
    ``check_results``: the ``--results`` of ``--rebuild --results`` (the check's runs read from
    there, the grid's from ``out``), named as such in the report's command line."""
    out = Path(out)
    figures = out / FIGURES
    if figures.is_dir():
        shutil.rmtree(figures)
    figures.mkdir(parents=True, exist_ok=True)
    table = report.table
    write_parquet(out / TABLE_NAME, table)
    checked = report.check.table if report.check is not None else None
    if checked is not None and len(checked):
        write_parquet(out / CHECK_TABLE_NAME, checked)
    else:  # the folder describes this report: no check runs, no check table
        (out / CHECK_TABLE_NAME).unlink(missing_ok=True)

    curve_paths: dict[str, Path] = {}
    for t in report.axes:
        path = curves_figure(t, table, figures / f"curves_{_slug(t.axis)}.png")
        if path is not None:
            curve_paths[t.axis] = path
    drawn: list[tuple[Tradeoff, Path | None]] = []
    specs = {m.name: m for m in report.metrics}
    # points labelled without the axes' shared prefix (legible); the text names the cells in full
    short, full = cell_labels(report.spec, table, short=True), cell_labels(report.spec, table)
    to_full = dict(zip(short, full))
    for tradeoff in drawable_tradeoffs(report):
        trusted, _ = timed_runs(report, tradeoff)
        if not len(trusted):
            report.fronts[tradeoff.stem] = {}
            drawn.append((tradeoff, None))
            continue
        tradeoff, trusted, cost = sized_tradeoff(report, tradeoff, trusted)
        means = cell_means(trusted, short, tradeoff.cost, tradeoff.quality)
        path = figures / f"{tradeoff.stem}.png"
        fronts = pareto_figure(means, list(report.spec.scenes), cost, specs[tradeoff.quality], path, tradeoff.title)
        report.fronts[tradeoff.stem] = {scene: [to_full[c] for c in cells] for scene, cells in fronts.items()}
        drawn.append((tradeoff, path))
    run_options = "" if results is None else f" --results {results}"
    options = (run_options if check_results is None else f" --rebuild --results {check_results}") \
        + ("" if out_option is None else f" --out {out_option}")
    text = render_markdown(report, curve_paths, drawn, out, options, run_options)
    write_text(out / REPORT_NAME, text)
    return out / REPORT_NAME


#: The size axis of a Pareto figure where the cells' bytes per Gaussian differ (`sized_tradeoff`).
MODEL_MB = MetricSpec("model_mb", "Model size (MB, float32 parameters)", ".2f", "MB", "lower",
                      bounds=(0.0, math.inf))


def sized_tradeoff(report: Report, tradeoff: Tradeoff, runs: pd.DataFrame
                   ) -> tuple[Tradeoff, pd.DataFrame, MetricSpec]:
    """(The figure as drawn, its runs, its cost's `MetricSpec`): where the cost is the kind's size
    metric (`FindingRules.size`, the Gaussian count) and the runs' bytes per Gaussian differ
    (`findings.bytes_differ`: an SH axis, 14 floats a Gaussian at degree 0, 59 at 3), the size is the
    model's megabytes (`KindReport.model_bytes`, column ``metric.model_mb``), as the findings judge
    size; else the figure as declared."""
    declared = report.kind.report
    rules = declared.rules if declared is not None else None
    specs = {m.name: m for m in report.metrics}
    if rules is None or rules.size != tradeoff.cost or declared.model_bytes is None \
            or not bytes_differ(runs, declared.model_bytes, tradeoff.cost):
        return tradeoff, runs, specs[tradeoff.cost]
    runs = runs.assign(**{f"metric.{MODEL_MB.name}": declared.model_bytes(runs) / 1e6})
    quality = specs[tradeoff.quality]
    title = (f"Model size (MB of float32 parameters, not the Gaussian count: the cells' bytes per Gaussian "
             f"differ) against {quality.label.split(' (')[0]} per cell (mean over seeds)")
    return (dataclasses.replace(tradeoff, cost=MODEL_MB.name, title=title, cheaper="smaller (fewer bytes)",
                                order="smallest first"), runs, MODEL_MB)


def timed_runs(report: Report, tradeoff: Tradeoff) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(The runs a Pareto figure may use, the done runs it leaves out): a run marked ``loaded``
    (raster) never, and for a cost the kind declares timed, never a run timed while other processes
    loaded the machine (``metric.time_loaded``): its time is not evidence (docs/reports.md)."""
    done = report.table[report.table.status == "done"] if len(report.table) else report.table
    usable = usable_runs(report.table, report.kind)
    declared = report.kind.report
    if declared is not None and tradeoff.cost in declared.timed:
        usable = usable[~loaded_runs(usable, report.kind)]
    return usable, done[~done.run_id.isin(set(usable.run_id))]


def drawable_tradeoffs(report: Report) -> list[Tradeoff]:
    """The kind's Pareto figures whose two metrics the report shows (its results hold
    them), when at least one run is done: any grid of the kind whose results have, say,
    a Gaussian count gets that figure."""
    declared = report.kind.report
    if declared is None or not report.done:
        return []
    shown = {m.name for m in report.metrics}
    return [t for t in declared.tradeoffs if t.cost in shown and t.quality in shown]


# --------------------------------------------------------------------------- markdown
def render_markdown(report: Report, curve_paths: dict[str, Path], tradeoffs: list[tuple[Tradeoff, Path | None]],
                    out: Path, options: str = "", run_options: str = "") -> str:
    """The report's text; ``tradeoffs``: each Pareto figure drawn, with its file; ``options`` /
    ``run_options``: the report's / the run command's options beyond the experiment file
    (`write_report`); a figure's file is None where every run was left out (`timed_runs`)."""
    spec, kind, table = report.spec, report.kind, report.table
    missing = report.total - len(table)
    dims = ", ".join(f"`{d}`" for d in spec.dimensions) or "no axes"
    extra = [f"`{d} = {lab}`" + (f" ({', '.join(at)} only)" if (at := spec.extra_scenes.get(d, {}).get(lab)) else "")
             for d, labs in spec.extra.items() for lab in labs]  # cells outside the grid, and where they run
    if extra:
        dims += (f", and {len(extra)} extra cell{'s' if len(extra) > 1 else ''} outside it ({', '.join(extra)}: the "
                 f"base and the fields each `[extra]` cell sets, crossed with nothing)")
    lines = [f"# {spec.name}", ""]
    for note in kind.report.title_notes if kind.report is not None else ():  # the first line, e.g. a smoke test
        more = note(table)
        if more:
            lines += [*more, ""]
    if spec.description:
        lines += [f"> {spec.description}", ""]
    recorded = run_warnings(spec, table)  # the section "Warnings" lists them all
    warned = [w for w in recorded if is_warning(w[4])]  # the Summary's count and quotes, the header's line
    lines += summary_lines(report, source_path(spec) + run_options, warned)
    lines += [
        "## Protocol and runs", "",
        f"Generated by `splatbench report {source_path(spec)}{options}`: {report.total} runs of kind `{spec.kind}` "
        f"({report.done} done, {report.failed} failed, {missing} not run); scenes "
        f"{', '.join(spec.scenes)}; seeds {', '.join(map(str, spec.seeds))}; grid `{spec.grid}` over {dims}. "
        f"Every number below is computed from `{TABLE_NAME}` beside this file (one row per run: `axis.*`, "
        f"`config.*` and `metric.*` columns, `curves` as JSON).",
        "",
    ]
    if spec.base:
        lines += ["Shared settings: " + ", ".join(f"`{k} = {display(v)}`" for k, v in spec.base.items()) + ".", ""]
    if spec.scene_tables:  # dataset folders and teacher models: where their data comes from, as the file says
        lines += ["Scenes from files (paths relative to the experiment file; run ids hash their content): " + "; ".join(
            f"`{name}` " + ", ".join(f"{k} `{display(v)}`" for k, v in src.items())
            for name, src in spec.scene_tables.items())
            + " (a scene's own keys win over the shared `data.*`; `data` keys of another scene type do not apply "
              "to it).", ""]
    for note in kind.report.header_notes if kind.report is not None else ():
        more = note(table)
        if more:
            lines += [*more, ""]
    checked = report.check.table if report.check is not None else None
    timing = " ".join(t for t in (run_time(table), load_facts(table, kind), code_facts(table, checked),
                                  reuse_facts(table)) if t)
    if timing:
        lines += [timing, ""]
    if warned:
        lines += [f"**Warnings:** {len({w[0] for w in warned})} run(s) warned of something their numbers below do "
                  f"not show; see \"Warnings\".", ""]

    how = ("each value pools every run with that value (all other axes' values, all seeds)"
           if spec.grid == "product" else "each value alone on top of the base")
    for t in report.axes:
        note = interval_note(t.max_seeds) if t.max_seeds < 2 else \
            f"Mean over seeds ± the half-width of its 95 % t interval (how a cell is written: \"{_in_full(t.axis)}\")"
        lines += [f"## {t.axis}", "", f"{note}; {how}.", "", t.markdown(), ""]
        if t.axis in report.findings:
            found = report.findings[t.axis]
            lines += ["**Findings** (computed from the table; the primary metric's here, the other metrics' "
                      f"comparisons and notes in \"{_in_full(t.axis)}\"):", "", found.markdown(), ""]
        if t.axis in curve_paths:
            rel = curve_paths[t.axis].relative_to(out).as_posix()
            lines += [f"![training curves by {t.axis}]({rel})", ""]

    axes = {t.axis for t in report.axes}
    for name in (n for n in report.findings if n not in axes and n not in APPENDIX_FINDINGS):  # run findings
        lines += [f"## {name.capitalize()}", "", report.findings[name].markdown(), ""]

    check_more = check_appendix_lines(report.check) if report.check is not None else []  # the appendix's
    if report.check is not None:
        lines += check_lines(report.check, f"splatbench run {source_path(spec)}{run_options}", bool(check_more))
    # "Beside published numbers" ([] without [report] published); a difference of the check's cells also
    # from the check's runs
    lines += published_lines(spec, kind, table, report.check.table if report.check is not None else None)

    specs = {m.name: m for m in report.metrics}
    declared = kind.report
    for tradeoff, path in tradeoffs:
        cost, quality = specs.get(tradeoff.cost, MODEL_MB), specs[tradeoff.quality]  # `sized_tradeoff`
        lines += [f"## {cost.label} against {quality.label}", ""]
        trusted, left = timed_runs(report, tradeoff)
        shown = cell_labels(spec, trusted) if len(trusted) else pd.Series([], dtype=object)
        is_time = declared is not None and tradeoff.cost in declared.timed
        if path is None:
            lines += [f"Not drawn: all {len(left)} done runs were timed while other processes loaded the machine; "
                      f"their times are no evidence (rerun on a quiet machine: docs/reports.md, \"Quiet numbers\").",
                      ""]
            continue
        lines += [f"{tradeoff.title}; bars are 95 % t intervals over seeds (none with one seed); ringed points are "
                  f"Pareto-optimal on the means (no other cell is both {tradeoff.cheaper} and better).", "",
                  f"![{tradeoff.stem}]({path.relative_to(out).as_posix()})", ""]
        if len(left):
            labels = cell_labels(spec, table)
            cells = ", ".join(dict.fromkeys(f"{sc} `{labels[i]}`" for i, sc in left.scene.items()))
            lines.append(f"- Left out of this figure and its front: {len(left)} run(s) timed while other processes "
                         f"loaded the machine ({cells}); a cell none of whose runs is left has no point.")
        if is_time and not load_recorded(table, kind):
            lines.append("- These runs did not record the machine's load (run before it was recorded): their times "
                         "may come from a loaded machine, so this front is no evidence of speed.")
        for scene, front in report.fronts.get(tradeoff.stem, {}).items():
            cells = set(shown[trusted.scene == scene]) if len(trusted) else set()
            if len(cells) == 1 and len(left):
                lines.append(f"- On {scene} only `{next(iter(cells))}` has a trusted time: no front.")
            elif front:
                lines.append(f"- Pareto front on {scene}, {tradeoff.order}: " + " → ".join(f"`{c}`" for c in front))
        lines.append("")

    if recorded:
        noted = len(recorded) - len(warned)
        lines += ["## Warnings", "", "What each run's own tool warned of (the run's file keeps it too)"
                  + (f"; {noted} entr{'y' if noted == 1 else 'ies'} without \"warning:\" "
                     f"{NOTE_WORDS[noted == 1]} (e.g. the budget strategy's prune in its last "
                     f"refinement) that runs made before the training loop told the two apart (2026-12-07) "
                     f"recorded among their warnings; not counted as warnings above" if noted else "") + ".", "",
                  markdown_table(["run", "scene", "cell", "seed", "warning"],
                                 ([f"`{rid}`", scene, cell, seed, text] for rid, scene, cell, seed, text in recorded)),
                  ""]
    failed = table[table.status == "failed"] if len(table) else table
    if len(failed):
        lines += ["## Failed runs", "",
                  markdown_table(["run", "scene", "seed", "error"],
                                 ([f"`{r.run_id}`", r.scene, r.seed, r.error] for _, r in failed.iterrows())), ""]

    # the appendix: every other number, by section
    for t in report.axes:
        found = report.findings.get(t.axis)
        lines += [f"## {_in_full(t.axis)}", "", f"{interval_note(t.max_seeds)}; {how}.", ""]
        if found is not None and found.appendix:
            lines += [found.appendix_markdown(), ""]
    for name in (n for n in APPENDIX_FINDINGS if n in report.findings):
        lines += [f"## Appendix: {name.capitalize()}", "", report.findings[name].markdown(), ""]
    if check_more:
        lines += [f"## {CHECK_APPENDIX}", "", *check_more]
    if declared is not None:  # what each metric shown means, as the kind's result declares it
        lines += ["## Appendix: Metrics", ""]
        lines += [f"- `{m.label}` (`metric.{m.name}`): {m.meaning}" for m in report.metrics]
        for note in declared.metric_notes:
            lines += note(table)
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


#: The run findings (`report_from_table`) a report puts in its appendix, in this order; the others
#: (the raster kind's parity) keep a section of their own in the body.
APPENDIX_FINDINGS = ("settling", "outlier test views", "ranks")


def _in_full(axis: str) -> str:
    """The title of an axis's appendix section (`Finding.appendix`)."""
    return f"Appendix: {axis} in full"


#: How much of each of the first two distinct run warnings the Summary quotes (characters).
SUMMARY_WARNING = 120


def summary_lines(report: Report, run_args: str, warned: list[tuple[str, str, str, int, str]]) -> list[str]:
    """The report's "Summary" section: the runs not done yet; per axis, each row's primary difference
    against the reference and the best (`Finding.summary`); the settling marks; the runs' warnings; the
    check's verdict (or that none is declared). Every number in it is repeated from the sections below;
    ``run_args``: the experiment file and options of the ``splatbench run`` that resumes the grid;
    ``warned``: the runs' warnings (`run_warnings`)."""
    spec, kind = report.spec, report.kind
    lines = ["## Summary", ""]
    missing = report.total - len(report.table)
    if missing:
        lines += [f"**Incomplete:** {missing} run(s) have no result yet; run `splatbench run {run_args}` "
                  f"(it resumes) and report again.", ""]
    summed = [t for t in report.axes if t.axis in report.findings and report.findings[t.axis].summary]
    if summed:
        lines += ["Each cell's primary metric against its axis's reference, paired over seeds, with its 95 % interval "
                  "and how it reads against the minimum effect (each axis's findings below give the whole; every other "
                  "metric is in the Appendix).", ""]
    for t in summed:
        lines += [f"**{t.axis}**:", "", *report.findings[t.axis].summary, ""]
    marks = [line for name, f in report.findings.items() if name not in {t.axis for t in report.axes}
             for line in f.summary]
    if marks:
        lines += [*marks, ""]
    if warned:  # a warning can change what the numbers mean (e.g. a strategy that never refined)
        distinct = list(dict.fromkeys(w[4] for w in warned))
        shown = "; ".join(f"\"{w if len(w) <= SUMMARY_WARNING else w[:SUMMARY_WARNING].rstrip() + '…'}\""
                          for w in distinct[:2])
        lines += [f"**Warnings**: {len({w[0] for w in warned})} of {len(report.table)} runs warned ({len(distinct)} "
                  f"distinct: {shown}{'; …' if len(distinct) > 2 else ''}); each in full in \"Warnings\".", ""]
    if spec.notes:  # the author's, beside the computed lines: said to be so
        lines += ["**Notes from the experiment file** (its author's, on the data; not computed from the runs):", "",
                  *(f"- {n}" for n in spec.notes), ""]
    if report.check is not None:
        lines += [header_line(report.check), ""]
    elif spec.check is None and kind.protocols is not None:
        lines += ["**7K check: none declared** (the experiment file has no `[check]`: its headline is not rerun at "
                  "graphdeco's 7K protocol; docs/reports.md, \"The protocol check\").", ""]
    return lines if len(lines) > 2 else []


#: An entry of a run's warnings that is not one, in words: plural, singular (`render_markdown`'s Warnings).
NOTE_WORDS = ("are strategies' notes", "is a strategy's note")


def is_warning(text: str) -> bool:
    """A run's warning starts with "warning:" (`splatbench.train.loop`: a strategy's outcome that does not
    is a note)."""
    return text.startswith("warning:")


def run_warnings(spec: ExperimentSpec, table: pd.DataFrame) -> list[tuple[str, str, str, int, str]]:
    """``(run_id, scene, cell, seed, warning)`` for each warning of each run, in grid order
    (the table's ``warnings`` column; a table from before that column has none); the cell as
    `cell_labels` names it."""
    if "warnings" not in table.columns or not len(table):
        return []
    out = []
    for (_, r), cell in zip(table.iterrows(), cell_labels(spec, table)):
        if isinstance(r.warnings, str):
            out += [(r.run_id, r.scene, f"`{cell}`", int(r.seed), " ".join(str(w).split()))
                    for w in json.loads(r.warnings)]
    return out


def source_path(spec: ExperimentSpec) -> str:
    """The experiment file as written in the report: relative to the current folder
    when it lies below it (no machine-specific absolute paths in committed reports)."""
    try:
        return Path(spec.source).resolve().relative_to(Path.cwd().resolve()).as_posix()
    except (ValueError, OSError):
        return spec.source


def run_time(table: pd.DataFrame) -> str:
    """"Run time: ..." from the done runs' worker seconds and start / finish times (the runs made for
    this experiment: a reused run's are its original's, `reuse_facts`)."""
    done = table[table.status == "done"] if len(table) else table
    if "reused_from" in done.columns:  # a copy's times are its original's, for another experiment (`reuse_facts`)
        done = done[done.reused_from.fillna("").astype(str) == ""]
    if not len(done):
        return ""
    worker = float(pd.to_numeric(done.seconds, errors="coerce").sum())
    try:
        start = min(datetime.fromisoformat(s) for s in done.started if s)
        end = max(datetime.fromisoformat(s) for s in done.finished if s)
        span = f"; {duration((end - start).total_seconds())} from the first start to the last finish"
    except ValueError:
        span = ""
    return (f"Run time: {duration(worker)} of worker time over {len(done)} runs "
            f"(mean {duration(worker / len(done))} per run){span}.")


def reuse_facts(table: pd.DataFrame) -> str:
    """"Reused: ..." -- how many done runs are copies of the same run finished for another
    experiment (their record's ``reused_from``: `splatbench.experiments.runner.reuse_finished`),
    by experiment; their times above are those of the original runs. "" when none is (or the
    table is from before records named it)."""
    if not len(table) or "reused_from" not in table.columns:
        return ""
    sources = table.loc[table.status == "done", "reused_from"].fillna("").astype(str)
    counts = sources[sources != ""].value_counts()
    if not len(counts):
        return ""
    named = ", ".join(f"{n} from `{name}`" for name, n in sorted(counts.items()))
    return (f"Reused: {int(counts.sum())} of the {len(sources)} runs ran for another experiment under the same run id "
            f"(the same resolved config) and were copied, not rerun ({named}); the run time above leaves them out.")


def _done_codes(table: pd.DataFrame | None) -> pd.Series:
    """The ``code`` of each done run of ``table`` ("" where not recorded: a table from before
    runs recorded it has no column)."""
    if table is None or not len(table):
        return pd.Series([], dtype=object)
    done = table[table.status == "done"]
    if "code" not in done.columns:
        return pd.Series([""] * len(done), dtype=object)
    return done.code.fillna("").astype(str)


def _listed(codes: pd.Series) -> str:
    counts = codes[codes != ""].value_counts()
    return ", ".join(f"`{c}` ({n} run{'s' if n != 1 else ''})" for c, n in sorted(counts.items()))


def code_facts(table: pd.DataFrame, checked: pd.DataFrame | None = None) -> str:
    """"Code: ..." -- the commits the done runs ran at (their record's ``code``), with how many
    runs each; a report whose cells ran at more than one says so, since a change of code between
    runs is a confound the grid does not see. "" for a table of grids run before runs recorded it.
    ``checked``: the ``[check]``'s runs (`CheckResult.table`); with a done one among them, the line
    covers them too and names the grid's and the check's commits apart (a check added to a
    committed report later ran at another commit than its grid: `splatbench report --rebuild
    --results`)."""
    grid, check = _done_codes(table), _done_codes(checked)
    if not len(check):
        if not len(grid) or not (grid != "").any():
            return ""
        missing = int((grid == "").sum())
        unknown = f"; {missing} run(s) ran before runs recorded it" if missing else ""
        if grid[grid != ""].nunique() == 1 and not missing:
            return f"Code: every run at {_listed(grid)}."
        return (f"Code: the runs ran at more than one commit: {_listed(grid)}{unknown}; a difference between cells "
                f"run at different commits is also a difference of code.")
    known = set(grid[grid != ""]) | set(check[check != ""])
    if not known:
        return ""
    missing = int((grid == "").sum() + (check == "").sum())
    if len(known) == 1 and not missing:
        return (f"Code: every run at `{next(iter(known))}` ({len(grid) + len(check)} runs: the grid's {len(grid)} "
                f"and the check's {len(check)}).")

    def side(name: str, codes: pd.Series) -> str:
        unknown = int((codes == "").sum())
        before = f"{unknown} ran before runs recorded it" if unknown else ""
        if not (codes != "").any():
            return f"the {name} {len(codes)} runs ran before runs recorded it"
        return f"the {name} runs at {_listed(codes)}" + (f", {before}" if before else "")

    spans = ("the runs ran at more than one commit" if len(known) > 1 else
             f"the runs may span more than one commit (not every run recorded its own; those that did ran at "
             f"`{next(iter(known))}`)")
    sides = side("grid's", grid) + "; " + side("check's", check)
    return (f"Code: {spans}: {sides}; "
            f"a difference between runs at different commits is also a difference of code (the check's verdict "
            f"compares its runs' difference with the grid's).")


def load_facts(table: pd.DataFrame, kind: RunKind) -> str:
    """"Load: ..." -- how many done runs were timed while other processes loaded the
    machine (the kind's mark, `KindReport.load`: ``metric.time_loaded``, train;
    ``metric.loaded``, raster) and the range of the others' estimated load (the mark's
    ``other`` over its ``cores``); "" for a kind without a mark, or a table of grids run
    before load was recorded."""
    done = table[table.status == "done"] if len(table) else table
    load = kind.report.load if kind.report is not None else None
    flag = f"metric.{load.flag}" if load is not None else None
    if not len(done) or flag not in done.columns:
        return ""
    marked = int((pd.to_numeric(done[flag], errors="coerce").fillna(0) != 0).sum())
    what = ("their times are left out of the time comparisons, their quality kept" if load.scope == "timed"
            else "left out of every finding")
    text = (f"Load: {marked} of {len(done)} runs timed while other processes loaded the machine "
            f"(`{flag}`: {what})")

    def column(name: str) -> pd.Series:
        return pd.to_numeric(done[name], errors="coerce").dropna() if name in done.columns else pd.Series([])

    other, cores = column(f"metric.{load.other}"), column(f"metric.{load.cores}")
    if len(other):
        on = f" on {int(cores.max())} cores" if len(cores) and cores.min() == cores.max() else ""
        text += f"; others' estimated load {other.min():.2f}–{other.max():.2f}{on}"
    return text + "."


def duration(seconds: float) -> str:
    """``"42 s"``, ``"12 min 5 s"``, ``"3 h 20 min"``."""
    if not math.isfinite(seconds):
        return "n/a"
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60} s"
    return f"{s // 3600} h {(s % 3600) // 60} min"


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in text)


__all__ = ["Report", "build_report", "write_report", "reported_done", "grid_table", "render_markdown",
           "drawable_tradeoffs", "timed_runs", "load_recorded", "run_time", "load_facts", "duration", "REPORT_NAME",
           "FIGURES"]
