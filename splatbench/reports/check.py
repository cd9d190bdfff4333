"""The protocol check: an experiment's headline comparison rerun at a longer protocol of the field's.

An experiment's ``[check]`` (`splatbench.experiments.CheckSpec`) names two cells of its grid,
one of its scenes and a protocol, e.g. ``graphdeco-7k`` for a quick grid (graphdeco's 30,000-step
schedule as written, stopped and evaluated after 7,000 steps: the 3DGS paper's 7K column; the "7K
check") or ``graphdeco-30k`` for a grid at ``graphdeco-7k`` (the "30K check": `check_name`);
``splatbench run`` runs those two cells at that scene for every seed under that protocol
(`splatbench.experiments.check_runs`). `check_result` sets the paired difference of the
check's runs beside the same difference from the grid's own runs of those cells, with the
statistics of every finding (`splatbench.reports.findings.paired`, `fmt_interval`, `judge`:
the paired t interval over seeds, the minimum effect) and the settled rule on each side's own
test curves (`splatbench.reports.settling`), and gives one verdict (`VERDICTS`):

Each side is read by the findings' one rule (`splatbench.reports.findings.reading`):

* **holds**: every run of both sides is done, and for a headline of a practical difference (the
  grid's side reads "difference": significant and at least the minimum effect) the check's
  reads "difference" too, with the same sign; for a headline of no practical difference (the
  grid's interval within the minimum effect either side of no difference), the check's is too;
* **does not hold**: for a practical headline, the check's interval excludes the headline's sign
  (it lies wholly on the other side of no difference) or lies within the minimum effect either
  side of it (the check shows there is no practical difference); for a no-difference headline, the
  check gives a practical difference;
* **inconclusive**: every other case with every run done: an interval that cannot tell either way
  (it reaches beyond the minimum effect while its estimate is below it or it spans no difference;
  seeds that did not vary the result), or a headline that is itself inconclusive (nothing to hold);
* **not run**: none of the check's runs has a result (the report is written all the same);
* **incomplete**: some of the check's runs, or of the grid's runs of the two cells, have no
  finished result (no verdict from part of the seeds).

Where the two cells' model sizes differ by the findings' rule (`splatbench.reports.findings.size_shift`:
≥ 10 % in Gaussians, or in bytes where bytes per Gaussian differ), the verdict's sentence says so for
each protocol ("against model size"): the check has no matched-size cell, so it does not separate
quality from size. Whether the check's cells had settled is stated beside the verdict and does not change it: at
graphdeco's 7K column a model is mid-schedule (its refinement runs to 15,000 steps and its
last opacity reset was 1,000 steps earlier), which is the column it stands beside.
The check's runs are kept beside the report as ``check.parquet`` (`CHECK_TABLE_NAME`), the
grid's as ``results.parquet``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import pandas as pd

from splatbench.experiments.grid import check_cells
from splatbench.experiments.kind_report import Comparison
from splatbench.experiments.kinds import RunKind
from splatbench.experiments.spec import CheckSpec, ExperimentSpec
from splatbench.experiments.store import build_table, experiment_dir, read_records
from splatbench.metrics.spec import MetricSpec
from splatbench.metrics.stats import Interval
from splatbench.report_files import markdown_table
from splatbench.reports.findings import (Claim, bytes_differ, fmt_interval, fmt_min_effect, fmt_number, judge,
                                         other_way, paired, reading, rules_for, size_shift, usable_runs)
from splatbench.reports.settling import cell_settling, unsettled_reason
from splatbench.reports.tables import Stat, cell_labels, metric_specs, seed_values, stat

#: The check's runs beside a report (the grid's are ``results.parquet``).
CHECK_TABLE_NAME = "check.parquet"
#: What a check can conclude (module doc).
VERDICTS = ("holds", "does not hold", "inconclusive", "not run", "incomplete")
#: The verdicts given from a complete check.
JUDGED = ("holds", "does not hold", "inconclusive")


def protocol_title(protocol: str) -> str:
    """How the report names a protocol in the check's title: ``"7K"`` for ``graphdeco-7k``
    (``"30K"`` for ``graphdeco-30k``), else the name in backquotes."""
    m = re.search(r"(\d+)k$", protocol)
    return f"{m.group(1)}K" if m else f"`{protocol}`"


def check_name(protocol: str) -> str:
    """What the check is called: ``"7K check"`` at ``graphdeco-7k``; ``"check at NAME"`` for a
    protocol whose name gives no step count."""
    title = protocol_title(protocol)
    return f"{title} check" if not title.startswith("`") else f"check at {protocol}"


@dataclass(frozen=True)
class CheckSide:
    """One protocol's side of the check, at the check's scene.

    protocol: its name as the runs recorded it; done / failed / total: runs of the two cells
    (every seed); stats: each cell's mean ± interval of the primary metric over seeds; claim:
    the paired difference, second cell minus first (None without a pair of done runs);
    settled: both cells' curves had flattened and the difference stopped moving (None: not
    judged); why: why not, where not ("" otherwise).
    """

    protocol: str
    done: int
    failed: int
    total: int
    stats: tuple[Stat, Stat]
    claim: Claim | None
    settled: bool | None
    why: str
    others: tuple[tuple[MetricSpec, Stat, Stat], ...] = ()  # the cells' other quality and size metrics
    opposed: tuple[tuple[str, str], ...] = ()  # (name, difference) of each of the kind's other quality metrics
    #   that goes significantly the other way (`splatbench.reports.findings.other_way`)
    per_seed: tuple[dict, dict] = ({}, {})  # each cell's primary metric by seed (a seed's runs averaged)
    size: str = ""  # the second cell's model size against the first's where it differs by at least
    #   `findings.MATCHED_SHARE` (`findings.size_shift`'s `SizeShift.text`: "×1.602 the Gaussians (≥ 10 % more");
    #   "" otherwise

    @property
    def complete(self) -> bool:
        return self.done == self.total and self.claim is not None


@dataclass(frozen=True)
class CheckResult:
    """The check of one report (module doc): the seeds, the cells' labels (reference first), what its
    protocol stands beside (``described``), the grid's side and the rerun's, the verdict with
    the sentence that gives it, and the check's runs that have a result (``table``)."""

    check: CheckSpec
    seeds: tuple[int, ...]
    labels: tuple[str, str]
    described: str
    metric: MetricSpec
    grid: CheckSide
    rerun: CheckSide
    verdict: str
    reason: str
    table: pd.DataFrame
    notes: tuple[str, ...] = ()  # the kind's notes on the check's runs (`KindReport.check_notes`)
    flagged: int = 0  # the check's runs those notes flag (an outlier test view: `RunNotes.flagged`)

    @property
    def name(self) -> str:
        return check_name(self.check.protocol)

    @property
    def headline(self) -> str:
        """``"7K check: holds"``: the words the README's line of the report repeats."""
        return f"{self.name}: {self.verdict}"


def check_table(spec: ExperimentSpec, results_dir) -> pd.DataFrame:
    """The check's runs that have a result file under ``results_dir`` (the experiment's folder),
    in check order (`splatbench.experiments.check_runs`); empty without a check."""
    a, b = check_cells(spec)
    records = read_records(experiment_dir(results_dir, spec.name))
    return build_table([records[r.run_id] for r in (*a, *b) if r.run_id in records])


def check_result(spec: ExperimentSpec, kind: RunKind, table: pd.DataFrame, checked: pd.DataFrame | None
                 ) -> CheckResult | None:
    """The check of ``spec`` (its runs of ``kind``) from the grid's run table ``table`` and the
    check's ``checked`` (`check_table`; None or empty: not run); None for an experiment without a
    ``[check]`` or a kind without findings rules."""
    check = spec.check
    metrics = metric_specs(kind, table)
    rules = rules_for(kind, metrics, spec.min_effect) if check is not None else None
    if rules is None:
        return None
    declared = kind.report
    metric = next(m for m in metrics if m.name == rules.primary)
    comp = next((c for c in rules.comparisons if c.metric == metric.name), Comparison(metric.name, "diff"))
    checked = checked if checked is not None else pd.DataFrame(columns=["run_id", "status"])
    quick = check_cells(spec, at_protocol=False)
    rerun = check_cells(spec)
    labels = tuple(cell_labels(spec, pd.DataFrame([{f"axis.{k}": v for k, v in r.labels.items()}
                                                   for r in (quick[0][0], quick[1][0])])))
    settling = declared.settling if declared is not None and declared.settling is not None \
        and declared.settling.metric == metric.name else None
    # beside the primary metric, each cell's other compared metrics that do not depend on the load (the
    # train kind: SSIM, LPIPS, Gaussians): what else the headline's cells are at each protocol
    timed = set(declared.timed) if declared is not None else set()
    by_name = {m.name: m for m in metrics}
    shown = [by_name[c.metric] for c in rules.comparisons if c.metric != metric.name and c.metric not in timed
             and c.metric in by_name]
    size_spec = by_name.get(rules.size) if rules.size else None
    bytes_of = declared.model_bytes if declared is not None else None

    def side(runs: pd.DataFrame, cells, protocol: str) -> CheckSide:
        ids = [{r.run_id for r in cell} for cell in cells]
        total = sum(len(c) for c in cells)
        mine = runs[runs.run_id.isin(ids[0] | ids[1])] if len(runs) else runs
        done, failed = int((mine.status == "done").sum()), int((mine.status == "failed").sum())
        usable = usable_runs(mine, kind) if len(mine) else mine
        pick = [usable[usable.run_id.isin(i)] if len(usable) else usable for i in ids]
        values = [seed_values(p, metric.name) if len(p) else {} for p in pick]
        others = tuple((m, *(stat(seed_values(p, m.name) if len(p) and f"metric.{m.name}" in p.columns else {})
                             for p in pick)) for m in shown)
        iv, null = paired(values[0], values[1], comp)
        quality = []
        for q in (by_name[n] for n in rules.quality if n in by_name and n != metric.name):
            q_how = next((c.how for c in rules.comparisons if c.metric == q.name), "diff")
            q_values = [seed_values(p, q.name) if len(p) and f"metric.{q.name}" in p.columns else {} for p in pick]
            quality.append((q, paired(q_values[0], q_values[1], Comparison(q.name, q_how))[0], q_how))
        opposed = tuple(other_way(metric, iv.estimate - (null or 0.0), quality)) if iv.n else ()
        shift = None
        if size_spec is not None and len(usable):  # the findings' model-size rule, in bytes where they differ
            shift = size_shift(pick[0], pick[1], size_spec, bytes_of, bytes_differ(usable, bytes_of, size_spec.name))
        size = shift.text if shift is not None else ""
        claim = None
        settled, why = None, ""
        if iv.n:
            if settling is not None and comp.min_effect is not None:
                sa, sb = (cell_settling(p, settling, comp.min_effect) if len(p) else None for p in pick)
                why = unsettled_reason(sa, sb, labels, iv.estimate - (null or 0.0), metric.unit)
                settled = None if sa is None or sb is None else not why
            text = fmt_interval(iv, comp.how, metric, null, comp.min_effect)
            significant, practical = judge(iv, comp.how, null, metric, comp.min_effect)
            claim = Claim("check", check.scene, labels[1], metric.name, comp.how, iv.estimate, text, labels[0],
                          iv.low, iv.high, iv.n, significant, practical, settled)
        return CheckSide(protocol, done, failed, total, (stat(values[0]), stat(values[1])), claim, settled, why,
                         others, opposed, (values[0], values[1]), size)

    grid_protocol = _recorded_protocol(table, {r.run_id for c in quick for r in c})
    grid_side = side(table, quick, grid_protocol)
    rerun_side = side(checked, rerun, check.protocol)
    verdict, reason = _verdict(grid_side, rerun_side, labels, metric, comp)
    if verdict in JUDGED and rerun_side.opposed:
        reason += (f"; **but {opposed_text(rerun_side)}** at `{check.protocol}`: "
                   f"{'; '.join(t for _, t in rerun_side.opposed)}")
    if verdict in JUDGED:
        reason += size_text(grid_side, rerun_side, labels)
    described = kind.protocols.describe(check.protocol) if kind.protocols is not None else check.protocol
    mine = checked[checked.run_id.isin({r.run_id for c in rerun for r in c})] if len(checked) else checked
    said = [note(mine) for note in (declared.check_notes if declared is not None else ()) if len(mine)]
    return CheckResult(check, tuple(spec.seeds), labels, described, metric, grid_side, rerun_side, verdict, reason,
                       checked if len(checked) else build_table([]), tuple(line for s in said for line in s.lines),
                       sum(s.flagged for s in said))


def size_text(grid: CheckSide, rerun: CheckSide, labels: tuple[str, str]) -> str:
    """``; **against model size**: `b` ends at ×1.602 the Gaussians (≥ 10 % more) than `a` at
    `graphdeco-7k` …; the check has no matched-size cell: quality and size are not separated``
    where either side's cells differ in size by the findings' rule (`CheckSide.size`); "" otherwise."""
    parts = [f"{s.size}) at `{s.protocol}`" for s in (grid, rerun) if s.size]
    if not parts:
        return ""
    return (f"; **against model size**: `{labels[1]}` ends at {' and '.join(parts)} against `{labels[0]}`; the "
            f"check has no matched-size cell: quality and size are not separated")


def opposed_text(side: CheckSide) -> str:
    """``SSIM goes the other way, significantly`` (the metrics of `CheckSide.opposed`)."""
    names = [n for n, _ in side.opposed]
    return f"{' and '.join(names)} go{'es' if len(names) == 1 else ''} the other way, significantly"


def _interval(claim: Claim) -> Interval:
    return Interval(claim.value, claim.low, claim.high, claim.n, "paired t")


def _recorded_protocol(table: pd.DataFrame, ids: set[str]) -> str:
    """The protocol the grid's runs of the check's cells recorded (``config.protocol``; a config
    without one is the quick protocol, `splatbench.experiments.train_report`)."""
    if not len(table) or "config.protocol" not in table.columns:
        return "quick"
    values = {v for v in table[table.run_id.isin(ids)]["config.protocol"] if isinstance(v, str) and v}
    return " / ".join(sorted(values)) or "quick"


def _verdict(grid: CheckSide, rerun: CheckSide, labels: tuple[str, str], metric: MetricSpec,
             comp: Comparison) -> tuple[str, str]:
    """(verdict, the sentence that gives it) (module doc)."""
    how, min_effect = comp.how, comp.min_effect
    at = f"`{rerun.protocol}`"
    if rerun.done == 0:
        failed = f" ({rerun.failed} failed)" if rerun.failed else ""
        return "not run", f"none of its {rerun.total} runs has a finished result{failed}"
    if not rerun.complete:
        return "incomplete", (f"{rerun.done} of its {rerun.total} runs are done"
                              + (f" ({rerun.failed} failed)" if rerun.failed else "") + "; no verdict from part of "
                                                                                         "the seeds")
    if not grid.complete:
        return "incomplete", (f"{grid.done} of the grid's {grid.total} runs of these two cells at "
                              f"{rerun.claim.scene} are done; no verdict from part of the seeds")
    g, r = grid.claim, rerun.claim
    compared = f"`{labels[1]}` against `{labels[0]}` on {r.scene}"
    quick = f"the grid's protocol ({grid.protocol}) gives {g.text}"
    null = 1.0 if how == "ratio" else (comp.null or 0.0) if how == "mean" else 0.0  # `findings.paired`'s
    said = {k: reading(_interval(c), how, null, metric, min_effect) for k, c in (("grid", g), ("check", r))}
    bound = fmt_min_effect(min_effect, how, metric) if min_effect is not None else None
    cannot_tell = (f"at {at}, {compared}: {r.text}, where {quick}; " + (
        "the seeds did not vary the check's result, so it has no interval" if said["check"] == "no interval" else
        "its interval can tell neither a practical difference of the grid's sign nor one ruled out"
        + (f" (it reaches beyond the {bound} minimum effect)" if bound else "")))
    if said["grid"] == "difference":
        sign = 1.0 if g.value > null else -1.0
        if said["check"] == "difference" and (r.value - null) * sign > 0:
            effect = f" and at least the {bound} minimum effect" if bound else ""
            return "holds", (f"at {at}, {compared}: {r.text}; the same sign as under the grid's protocol "
                             f"({fmt_number(g.value, how, metric)}), significant{effect}")
        if said["check"] != "no interval" and ((sign > 0 and r.high < null) or (sign < 0 and r.low > null)):
            return "does not hold", (f"at {at}, {compared}: {r.text}: its interval excludes the sign of the grid's "
                                     f"protocol ({fmt_number(g.value, how, metric)})")
        if said["check"] == "no practical difference":
            return "does not hold", (f"at {at}, {compared}: {r.text}, where {quick}: its interval lies within the "
                                     f"{bound} minimum effect either side, so the difference is not practical there")
        return "inconclusive", cannot_tell
    if said["grid"] != "no practical difference":  # the headline neither shows a difference nor rules one out
        return "inconclusive", (f"{quick}, which neither shows a practical difference nor rules one out, so there is "
                                f"no headline for the check to hold or break; at {at}, {compared}: {r.text}")
    # a headline of no practical difference (its interval within the minimum effect): holds where the check's does too
    if said["check"] == "difference":
        return "does not hold", (f"at {at}, {compared}: {r.text}, a practical difference, where {quick}")
    if said["check"] == "no practical difference":
        return "holds", (f"neither protocol gives a practical difference: {quick}; {at} gives {r.text}, its "
                         f"interval within the {bound} minimum effect either side")
    return "inconclusive", cannot_tell


def _cell(side: CheckSide, k: int, metric: MetricSpec, seeds: int) -> str:
    """One cell's mean ± interval; with only some of its runs done, the mean of those seeds alone,
    marked, and no interval (a part of the seeds is not the cell)."""
    st = side.stats[k]
    if side.done >= side.total:
        return st.text(metric.fmt, metric.bounds)
    if st.n == 0:
        return "–"
    return f"{format(st.mean, metric.fmt)} ({st.n} of {seeds} seeds; no interval)"


#: The title of the check's section in a report's appendix (`check_appendix_lines`).
APPENDIX_TITLE = "Appendix: The check in full"


def check_lines(result: CheckResult, run_command: str, appendix: bool) -> list[str]:
    """The report's section "Headline at the 7K protocol" ("... 30K ...": the check's) (title included): what is rerun, its
    table of the headline's metric, its verdict; ``run_command``: the ``splatbench run ...`` that runs
    the check; ``appendix``: whether the report's appendix holds the check's other tables (the other
    metrics, each seed's values and the outlier views: `check_appendix_lines` gave lines), which this
    section then points to."""
    c, m = result.check, result.metric
    a, b = result.labels
    title = protocol_title(c.protocol)
    seeds = ", ".join(map(str, result.seeds))
    lines = [f"## Headline at the {title} protocol", "",
             f"The headline comparison, `{b}` against `{a}` on {c.scene}, every seed ({seeds}), under the grid's "
             f"protocol and rerun at `{c.protocol}`: {result.described}. Declared in the experiment file's `[check]`; "
             f"`{run_command}` runs it after the grid's runs (docs/reports.md, \"The protocol check\"). "
             f"{_name(m)[:1].upper()}{_name(m)[1:]} paired over seeds with its 95 % t interval, the minimum "
             f"effect and the settled rule on "
             f"each protocol's own test curves, as in the findings above"
             + (f"; the check's runs are in `{CHECK_TABLE_NAME}` beside this file." if len(result.table) else "."),
             ""]
    rows = []
    for side, name in ((result.grid, f"`{result.grid.protocol}` (the grid's)"),
                       (result.rerun, f"`{result.rerun.protocol}`")):
        runs = f"{side.done} of {side.total}" + (f" ({side.failed} failed)" if side.failed else "")
        diff = side.claim.text if side.claim is not None else "–"
        settled = "–" if side.settled is None else "yes" if side.settled else f"no: {side.why}"
        if side.settled is not None and side.done < side.total:  # judged on the seeds done so far
            settled += f" (on the {side.done} of {side.total} runs done)"
        rows.append([name, runs, _cell(side, 0, m, len(result.seeds)), _cell(side, 1, m, len(result.seeds)), diff,
                     settled])
    head = ["protocol", "runs done", f"`{a}`", f"`{b}`", f"`{b}` − `{a}`, paired", "settled"]
    lines += [*markdown_table(head, rows, align="-rrr--").splitlines(),
              "", f"Cells: {_name(m)} ({m.unit}), mean over seeds ± the half-width of its 95 % t interval."
              if m.unit else f"Cells: {_name(m)}, mean over seeds ± the half-width of its 95 % t interval.", ""]
    if appendix:
        flagged = result.flagged
        lines += [f"Each cell's other metrics, each seed's {_name(m)}"
                  + (" and the check's runs' outlier test views" if result.notes else "")
                  + (f" (**{'runs' if flagged > 1 else 'a run'} flagged with an outlier test view**)" if flagged else "")
                  + f": \"{APPENDIX_TITLE}\".", ""]
    sentence = f"**{result.headline}**: {result.reason}"
    if result.verdict in JUDGED and result.rerun.settled is False:
        sentence += f"; **not settled** at `{c.protocol}` ({result.rerun.why})"
    if result.verdict in ("not run", "incomplete"):
        sentence += f". Run `{run_command}` (finished runs are skipped) and report again"
    lines += [sentence + ".", ""]
    failed = result.table[result.table.status == "failed"] if len(result.table) else result.table
    if len(failed):
        lines += ["Failed runs of the check:", ""]
        lines += [f"- `{r.run_id}` ({r.scene}, seed {r.seed}): {' '.join(str(r.error).split())}"
                  for _, r in failed.iterrows()]
        lines.append("")
    return lines


def check_appendix_lines(result: CheckResult) -> list[str]:
    """The check's tables the report's appendix holds (no title; [] when it has none): each cell's
    other metrics beside the headline's, each seed's value, and the notes on its runs (outlier test
    views)."""
    m = result.metric
    a, b = result.labels
    lines: list[str] = []
    # the sides with a result (a check not run yet has none: no rows of dashes)
    others = [(side, name) for side, name in ((result.grid, f"`{result.grid.protocol}`"),
                                              (result.rerun, f"`{result.rerun.protocol}`"))
              if side.others and any(st.n for _, *sts in side.others for st in sts)]
    if others:
        specs = [m for m, _, _ in others[0][0].others]
        head = ["protocol", "cell", _label(m), *(_label(o) for o in specs)]
        cells = []
        for side, name in others:
            for k, label in enumerate((a, b)):
                cells.append([name, f"`{label}`", _cell(side, k, m, len(result.seeds)),
                              *(_other(st[k], o, side, len(result.seeds)) for o, *st in side.others)])
        lines += [f"Each cell's {', '.join(_name(o) for o in specs)} beside its {_name(m)} (mean over seeds ± the "
                  f"half-width of its 95 % t interval):", "",
                  *markdown_table(head, cells, align="--" + "r" * (1 + len(specs))).splitlines(), ""]
    lines += _per_seed_lines(result)
    if result.notes:
        lines += [*result.notes, ""]
    return lines


def _per_seed_lines(result: CheckResult) -> list[str]:
    """Each seed's value of both cells at both protocols: three seeds summarised by a mean and a t
    interval can hide one seed that went its own way (a run that diverged, say); this shows it."""
    m = result.metric
    a, b = result.labels
    rows = []
    for side in (result.grid, result.rerun):
        va, vb = side.per_seed
        for seed in sorted(set(va) | set(vb), key=str):
            x, y = va.get(seed), vb.get(seed)
            cells = [format(v, m.fmt) if v is not None else "–" for v in (x, y)]
            diff = format(y - x, "+" + m.fmt) if x is not None and y is not None else "–"
            rows.append([f"`{side.protocol}`", str(seed), *cells, diff])
    if not rows:
        return []
    head = ["protocol", "seed", f"`{a}`", f"`{b}`", f"`{b}` − `{a}`"]
    return [f"Each seed's {_name(m)}" + (f" ({m.unit})" if m.unit else "") + ", both cells (a seed that went its own "
            "way shows here, not in the means above):", "", *markdown_table(head, rows, align="--rrr").splitlines(),
            ""]


def _label(spec: MetricSpec) -> str:
    return spec.label or spec.name


def _other(st: Stat, spec: MetricSpec, side: CheckSide, seeds: int) -> str:
    """Another metric's cell, written as the primary's (`_cell`): mean ± interval, or the mean of the
    seeds done, marked."""
    if st.n == 0:
        return "–"
    if side.done >= side.total:
        return st.text(spec.fmt, spec.bounds)
    return f"{format(st.mean, spec.fmt)} ({st.n} of {seeds} seeds; no interval)"


def header_line(result: CheckResult) -> str:
    """The report header's line naming the check and its verdict."""
    a, b = result.labels
    unsettled = ", not settled there" if result.verdict in JUDGED and result.rerun.settled is False else ""
    but = ""
    if result.verdict in JUDGED and result.rerun.opposed:
        but = (f", **but {opposed_text(result.rerun)} there** "
               f"({'; '.join(t for _, t in result.rerun.opposed)})")
    said = ""
    if result.rerun.claim is not None and result.grid.claim is not None:
        said = (f": {result.rerun.claim.text} at `{result.check.protocol}`, "
                f"{fmt_number(result.grid.claim.value, result.grid.claim.how, result.metric)} under the grid's "
                f"protocol")
    return (f"**{result.headline}**{but}{said} (`{b}` against `{a}` on {result.check.scene} alone, "
            f"{len(result.seeds)} seed{'' if len(result.seeds) == 1 else 's'}, rerun at protocol "
            f"`{result.check.protocol}`{unsettled}; no other comparison of the grid is rerun; section \"Headline at the "
            f"{protocol_title(result.check.protocol)} protocol\").")


def _name(spec: MetricSpec) -> str:
    return spec.label.split(" (")[0]


__all__ = ["CHECK_TABLE_NAME", "VERDICTS", "JUDGED", "CheckSide", "CheckResult", "check_name", "protocol_title", "check_table", "check_result",
           "check_lines", "check_appendix_lines", "APPENDIX_TITLE", "header_line"]
