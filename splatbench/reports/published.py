"""Beside published numbers: the grid's own result set beside each number the field published.

An experiment file's ``[[report.published]]`` entries (`splatbench.experiments.PublishedSpec`)
each name a published number with its source and its protocol:

* a **difference** between two cells of the grid (``cells = [A, B]``, ``value`` = A − B as
  published): on every scene of the grid, this grid's A − B paired over seeds with its 95 % t
  interval (`splatbench.reports.findings.paired`, written by `fmt_interval`: the findings' own
  statistics);
* an **absolute** value of one cell on one scene (``cell``, ``scene``, ``value``): the cell's
  mean over seeds on that scene with its 95 % t interval (`splatbench.metrics.stats.t_interval`).

A published difference between the two cells of the file's ``[check]`` gets one more row: the check's
runs, at the check's protocol and scene (e.g. a 30K check beside a number published at 30K), from the
check's run table.

Each row says where the published value lies against that interval (`VERDICTS`): inside, above or
below it, judged at the precision the report writes the bounds (a bound printed ``+0.11`` holds a
published 0.11); no verdict where there is no interval (one seed, or seeds that did not vary the
result at that precision, `findings.no_spread`) or no result yet. Then one sentence names what
differs between this grid and the published number (protocol, scenes): a published value inside an
interval is not a replication when the two were measured differently.

The runs used are those the findings use (`findings.usable_runs`; a time metric of the kind's
`KindReport.timed` also leaves out runs timed under load, as the findings do). A grid whose file
declares no entry gets one line saying so (`NONE_DECLARED`), no section.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from splatbench.experiments.grid import RunSpec, check_cells, published_runs, reported_metrics
from splatbench.experiments.kind_report import Comparison
from splatbench.experiments.kinds import RunKind
from splatbench.experiments.spec import ExperimentSpec, PublishedSpec
from splatbench.metrics.spec import MetricSpec
from splatbench.metrics.stats import Interval, t_interval
from splatbench.report_files import markdown_table
from splatbench.reports.check import check_name
from splatbench.reports.findings import fmt_interval, fmt_number, no_spread, paired, usable_runs
from splatbench.reports.tables import cell_labels, loaded_runs, seed_values

#: What a row can say of the published value against this grid's interval (module doc).
VERDICTS = ("inside", "above", "below", "no interval", "no result")
#: The section's title.
TITLE = "Beside published numbers"
#: The line of a report whose file declares no published number.
NONE_DECLARED = (f"**{TITLE}**: none declared (the experiment file has no `[[report.published]]`): no number here is "
                 f"set beside a published one.")


@dataclass(frozen=True)
class PublishedRow:
    """One scene's row of an entry: this grid's interval (a paired A − B, or a cell's mean), how it is
    written, and where the published value lies against it (`VERDICTS`)."""

    scene: str
    interval: Interval
    text: str
    verdict: str
    seeds: int  # the seeds the grid has (``interval.n`` of them had a result on both sides)


@dataclass(frozen=True)
class PublishedResult:
    """One ``[report] published`` entry beside this grid: its metric, its cells' labels (A first),
    one row per scene (and the check's row, last, where its cells are the check's), and the protocol(s) the
    grid's runs of its cells recorded ("" when the kind's configs name none)."""

    entry: PublishedSpec
    metric: MetricSpec
    labels: tuple[str, ...]
    rows: tuple[PublishedRow, ...]
    grid_protocol: str
    check_protocol: str = ""  # the check's protocol where a row is the check's (its last), else ""


def headline_metric(kind: RunKind) -> str:
    """The metric an entry without ``metric`` is of: the kind's findings' primary metric, else (a kind
    without declared rules) its first numeric metric, as `findings.rules_for` compares."""
    if kind.report is not None and kind.report.rules is not None:
        return kind.report.rules.primary
    return reported_metrics(kind)[0]


def placement(iv: Interval, value: float, metric: MetricSpec) -> str:
    """Where ``value`` lies against ``iv`` (`VERDICTS`), the bounds taken as written (``metric.fmt``)."""
    if iv.n == 0:
        return "no result"
    if not iv.defined or no_spread(iv, "diff", metric):
        return "no interval"
    low, high = float(format(iv.low, metric.fmt)), float(format(iv.high, metric.fmt))
    return "inside" if low <= value <= high else "above" if value > high else "below"


def published_results(spec: ExperimentSpec, kind: RunKind, table: pd.DataFrame,
                      checked: pd.DataFrame | None = None) -> list[PublishedResult]:
    """Each ``[report] published`` entry of ``spec`` beside the grid's run table ``table`` and, for a
    difference of the check's two cells, the check's run table ``checked`` (`check.check_table`; None:
    the row says no result) (module doc); [] without entries."""
    if not spec.published:
        return []
    timed = set(kind.report.timed) if kind.report is not None else set()
    usable = usable_runs(table, kind) if len(table) else table  # each table's usable runs once, not per row
    check_pool = checked if checked is not None else pd.DataFrame(columns=["run_id", "scene", "status"])
    check_usable = usable_runs(check_pool, kind) if len(check_pool) else check_pool
    out = []
    for entry in spec.published:
        cells = published_runs(spec, entry)  # first: a metric the kind does not report is one line here
        name = entry.metric or headline_metric(kind)
        metric = kind.specs[name]
        labels = tuple(cell_labels(spec, pd.DataFrame([{f"axis.{k}": v for k, v in cell[0].labels.items()}
                                                        for cell in cells])))

        def row(usable: pd.DataFrame, runs: Sequence[Sequence[RunSpec]], scene: str, label: str) -> PublishedRow:
            pool = usable[~loaded_runs(usable, kind)] if name in timed and len(usable) else usable
            values = []
            for cell in runs:
                ids = {r.run_id for r in cell if r.scene == scene}
                sel = pool[(pool.scene == scene) & pool.run_id.isin(ids)] if len(pool) else pool
                values.append(seed_values(sel, name) if len(sel) and f"metric.{name}" in sel.columns else {})
            if entry.is_difference:  # A − B: B is the reference, as `paired(a, b)` gives b − a
                iv, _ = paired(values[1], values[0], Comparison(name, "diff"))
                how = "diff"
            else:
                iv, how = t_interval(list(values[0].values())), "mean"
            text = fmt_interval(iv, how, metric, None) if iv.n else "–"
            return PublishedRow(label, iv, text, placement(iv, entry.value, metric), len(spec.seeds))

        rows = [row(usable, cells, scene, scene) for scene in dict.fromkeys(r.scene for r in cells[0])]
        at_check = _check_runs(spec, cells) if entry.is_difference else None
        check_protocol = ""
        if at_check is not None:
            c = spec.check
            check_protocol = c.protocol
            rows.append(row(check_usable, at_check, c.scene, f"{c.scene}, the {check_name(c.protocol)} (`{c.protocol}`)"))
        ids = {r.run_id for cell in cells for r in cell}
        out.append(PublishedResult(entry, metric, labels, tuple(rows), _recorded_protocol(table, ids), check_protocol))
    return out


def _check_runs(spec: ExperimentSpec, cells: Sequence[Sequence[RunSpec]]) -> tuple[list[RunSpec], list[RunSpec]] | None:
    """The check's runs (`check_cells`, at its protocol) in the order of a published difference's ``cells``
    (A, B) where the check compares those two cells (its grid-side runs are theirs at its scene); None
    otherwise."""
    if spec.check is None:
        return None
    grid_a, grid_b = ({r.run_id for r in side} for side in check_cells(spec, at_protocol=False))
    first, second = ({r.run_id for r in cell} for cell in cells)
    rerun_a, rerun_b = check_cells(spec)
    if grid_a <= first and grid_b <= second:
        return rerun_a, rerun_b
    if grid_b <= first and grid_a <= second:
        return rerun_b, rerun_a
    return None


def _recorded_protocol(table: pd.DataFrame, ids: set[str]) -> str:
    """The ``config.protocol`` the runs ``ids`` of ``table`` recorded (" / "-joined); "" where none."""
    if not len(table) or "config.protocol" not in table.columns:
        return ""
    values = {v for v in table[table.run_id.isin(ids)]["config.protocol"] if isinstance(v, str) and v}
    return " / ".join(sorted(values))


_SAYS = {"inside": "the published value lies inside this interval",
         "above": "the published value lies above this interval",
         "below": "the published value lies below this interval",
         "no interval": "no interval (one seed, or seeds that did not vary it): no verdict",
         "no result": "no finished run yet: no verdict"}


def _name(spec: MetricSpec) -> str:
    return spec.label.split(" (")[0]


def published_lines(spec: ExperimentSpec, kind: RunKind, table: pd.DataFrame,
                    checked: pd.DataFrame | None = None) -> list[str]:
    """The report's section "Beside published numbers" (title included); `NONE_DECLARED` for a file
    that declares no ``[report] published`` entry; ``checked``: the check's run table (`published_results`)."""
    results = published_results(spec, kind, table, checked)
    if not results:
        return [NONE_DECLARED, ""]
    lines = [f"## {TITLE}", "",
             "The numbers the experiment file declares as published (`[report] published`; docs/reports.md, "
             "\"Beside published numbers\"), each beside this grid's own: a difference as the grid's paired difference over "
             "seeds on each scene with its 95 % t interval (as in the findings), a value as the cell's mean over "
             "seeds with its 95 % t interval; the verdict says where the published value lies against that interval, "
             "its bounds as written.", ""]
    seeds = len(spec.seeds)
    for r in results:
        e, m = r.entry, r.metric
        unit = f" ({m.unit})" if m.unit else ""
        if e.is_difference:
            a, b = r.labels
            title = f"`{a}` − `{b}`, {_name(m)}"
            head = ["scene", f"this grid: `{a}` − `{b}`, paired", "seeds", "published", "verdict"]
            how = "diff"
        else:
            title = f"`{r.labels[0]}` on {e.scene}, {_name(m)}"
            head = ["scene", f"this grid: `{r.labels[0]}`", "seeds", "published", "verdict"]
            how = "mean"
        rows = [[row.scene, row.text, f"{row.interval.n} of {seeds}", fmt_number(e.value, how, m), _SAYS[row.verdict]]
                for row in r.rows]
        lines += [f"### {title}{unit}", "", f"Published: {fmt_number(e.value, how, m)} ({e.source}).", "",
                  *markdown_table(head, rows, align="--rr-").splitlines(), "", _differs(spec, r), ""]
    return lines


def _differs(spec: ExperimentSpec, r: PublishedResult) -> str:
    """The sentence naming what differs between this grid's number and the published one."""
    e = r.entry
    at = f"at protocol `{r.grid_protocol}`" if r.grid_protocol else "at its own settings (its runs name no protocol)"
    where = (f"on its scene {e.scene}" if not e.is_difference else
             f"on its own scene{'s' if len(spec.scenes) != 1 else ''} ({', '.join(spec.scenes)}), one row each")
    if r.check_protocol:  # set only where the file has a [check]
        where += f"; the last row is the check's runs, at protocol `{r.check_protocol}` on {spec.check.scene}"
    return (f"**Not a replication**: this grid's number is {at} {where}, {len(spec.seeds)} seed"
            f"{'s' if len(spec.seeds) != 1 else ''} (the header gives its settings); the published one's protocol: "
            f"{e.protocol}; where protocol, scenes, resolution or code differ, a published value inside this grid's "
            f"interval does not replicate it, nor does one outside refute it.")


__all__ = ["VERDICTS", "TITLE", "NONE_DECLARED", "PublishedRow", "PublishedResult", "headline_metric", "placement",
           "published_results", "published_lines"]
