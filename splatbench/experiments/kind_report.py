"""What a run kind declares about its reports: the metrics a table shows, findings rules,
the Pareto figures of a cost (time, the number of Gaussians) against quality, and the
report hooks (notes and findings of code of its own).

A kind's module builds one `KindReport` and passes it to its `RunKind` (``report=``),
so adding a kind touches that one file: the report code (`splatbench.reports`) is handed
the kind and names none. Every metric is named as a field of the kind's result
(`splatbench.experiments.kinds.RunResult`), where its label, format, unit, direction and
meaning are declared once. A kind without a `KindReport` gets every numeric metric and a
comparison of the first one.

The hooks (`KindReport.header_notes`, ``axis_notes``, ``metric_notes``, ``run_findings``) read
the run table (pandas, the engine's columns) and return markdown lines, or `Finding` records
of `Claim` numbers, defined here so that a kind's module can make them without importing the
reports.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from splatbench.metrics.spec import MetricSpec

if TYPE_CHECKING:  # the hooks' table type; pandas is not loaded by importing this module
    import pandas as pd


@dataclass(frozen=True)
class Claim:
    """One number of a finding.

    kind: "best", "no best", "size" (the leader's size against the runner-up's, where it kept
    a lead from being named best), "vs", "self" (the reference row's own relative metric),
    "count", "holm" (value: how many primary comparisons stay significant after Holm's correction, n:
    how many it covers), "auto", "model size" (a row's parameters against the reference row's), "matched" (a
    difference at the matched model size, `[report] matched`), "settling", "rank", "tau" (two scenes'
    rank agreement; scene "a/b"), "quick tau" (the quick version's against this one) or "parity";
    scene ("" for all); label: the
    row; reference: the row compared against ("vs"); metric; how: "mean", "diff",
    "ratio", "count" or "max"; value: the number; low / high: its 95 % interval (NaN
    when none); n: seeds (pairs) it comes from; significant: the interval excludes the
    null value (False when there is no interval, and when the seeds did not vary the
    result: `no_spread`); practical: significant and at least the comparison's minimum
    effect (False below it; equal to ``significant`` when the comparison has none);
    settled: both cells' curves had flattened and the difference stopped moving
    (`splatbench.reports.settling`; None: not judged); text: how it is written.
    """

    kind: str
    scene: str
    label: str
    metric: str
    how: str
    value: float
    text: str
    reference: str = ""
    low: float = math.nan
    high: float = math.nan
    n: int = 0
    significant: bool = False
    practical: bool = False
    settled: bool | None = None


@dataclass
class Finding:
    """The finding of one axis, or a run finding (its section named by ``axis``): markdown lines
    and the claims they state. An axis finding's ``lines`` hold its primary metric's (the report's
    body); ``appendix``: the rest, for its section "Appendix: <axis> in full" (the other metrics'
    comparisons, what else a setting changed, the count of comparisons, the kind's axis notes);
    ``summary``: the short lines the report's "Summary" opens with (the same texts, cut short; no
    number that is not in ``lines``)."""

    axis: str
    lines: list[str]
    claims: list[Claim]
    appendix: list[str] = field(default_factory=list)
    summary: list[str] = field(default_factory=list)

    def markdown(self) -> str:
        return "\n".join(self.lines)

    def appendix_markdown(self) -> str:
        return "\n".join(self.appendix)


def done_runs(table: pd.DataFrame) -> pd.DataFrame:
    """The runs of a run table whose status is ``done``."""
    return table[table.status == "done"]


class AxisRow(Protocol):
    """What an axis note reads of one row of an axis table (`splatbench.reports.tables.Row`)."""

    value: Any        # the axis value (a variant's label)
    label: str        # the row as a report names it
    run_ids: Sequence[str]


class AxisRows(Protocol):
    """What an axis note reads of an axis table (`splatbench.reports.tables.AxisTable`)."""

    axis: str
    rows: Sequence[AxisRow]


#: Lines of a report's header (e.g. the protocol its runs followed): ``note(runs) -> lines``.
HeaderNote = Callable[["pd.DataFrame"], list[str]]
#: A note on one axis, appended to its finding: ``note(axis_table, runs, scenes) -> (lines, claims)``.
AxisNote = Callable[[AxisRows, "pd.DataFrame", list[str]], tuple[list[str], list[Claim]]]
#: Lines appended to a report's "Metrics" section: ``note(runs) -> lines``.
MetricNote = Callable[["pd.DataFrame"], list[str]]
#: The bytes of each run's trained model, a series over the table's rows (NaN where unknown):
#: ``model_bytes(runs) -> pd.Series``.
ModelBytes = Callable[["pd.DataFrame"], "pd.Series"]
#: Lines about the runs of an experiment's ``[check]`` (their own table), under its per-seed table, and how many
#: runs they flag: ``note(check_runs) -> RunNotes``.
CheckNote = Callable[["pd.DataFrame"], "RunNotes"]
#: Minimum effects that depend on how the runs measured (the train kind's LPIPS: on its net's scale):
#: ``min_effects(runs) -> {metric: minimum effect, or None for significance alone}``, over the kind's
#: `Comparison` defaults; an experiment file's ``[report] min_effect`` overrides them.
MinEffects = Callable[["pd.DataFrame"], "Mapping[str, float | None]"]
#: A finding over all runs, its own section (named by `Finding.axis`): ``finding(runs, min_effect) ->
#: Finding | None`` (``min_effect``: the experiment file's ``[report] min_effect``, metric -> number).
RunFinding = Callable[["pd.DataFrame", "Mapping[str, float] | None"], "Finding | None"]


@dataclass(frozen=True)
class Comparison:
    """How one metric of a row is set against the reference row.

    how: "diff", "ratio" or "mean" (`splatbench.reports.findings`); null: the value that
    means "no difference" for a "mean" comparison (None: no significance statement);
    min_effect: the smallest difference that matters in practice, in the comparison's
    units (a difference in the metric's unit for "diff" and "mean"; a relative change for
    "ratio": 0.05 means ×1.05 or ×1/1.05). A difference reads "no practical difference" only where its
    whole interval lies within ± it, else "inconclusive" below it (`splatbench.reports.findings.reading`);
    None: no practical threshold (significance alone). An
    experiment file may set its own (``[report] min_effect = { test_psnr = 0.2 }``).
    """

    metric: str
    how: str
    null: float | None = None
    min_effect: float | None = None


@dataclass(frozen=True)
class RunNotes:
    """What a `CheckNote` says of the check's runs: its ``lines`` and how many runs they flag (``flagged``: e.g.
    runs with an outlier test view, which the check's section names)."""

    lines: tuple[str, ...] = ()
    flagged: int = 0


@dataclass(frozen=True)
class FindingRules:
    """A kind's primary metric (best-of) and its comparisons.

    size: a metric counting the model's size (the train kind's ``num_gaussians``; None: the kind
    records none): the best-of names a cell only when it is not larger than the runner-up by more
    than that metric's comparison's minimum effect (docs/reports.md, "Best"). quality: other
    metrics of the same quality the primary measures (the train kind's SSIM and LPIPS): a primary
    difference whose quality metric goes significantly the other way says so where it is stated
    (docs/reports.md, "The other way")."""

    primary: str
    comparisons: tuple[Comparison, ...]
    size: str | None = None
    quality: tuple[str, ...] = ()


@dataclass(frozen=True)
class Tradeoff:
    """A Pareto figure: a cost metric across (lower is better), a quality metric up, one
    point per grid cell; the report draws it when the results hold both metrics.

    cheaper: what a lower cost means, in words ("faster", "smaller"); order: how the
    front's cells are listed, in words ("fastest first").
    """

    cost: str      # metric on the x axis (e.g. "train_seconds", "num_gaussians")
    quality: str   # metric on the y axis (e.g. "test_psnr")
    stem: str      # figure file stem under figures/
    title: str
    cheaper: str = "faster"
    order: str = "fastest first"


@dataclass(frozen=True)
class SettlingCurves:
    """The curves (keys of a run's ``curves``) whose last quarter decides whether a cell had
    settled (`splatbench.reports.settling`): the test curve of ``metric`` (steps and values)
    and, where recorded, the training-view curve of the same quantity (overfitting); better:
    "higher" or "lower", the direction of a better value (a cell "past its peak" ended more than
    the minimum effect worse than its best); resets: ``resets(config) -> steps`` of a run's recorded
    config (nested, with ``scene`` and ``seed``), the steps at which its schedule resets what the
    training curve measures (the train kind's opacity resets; None: none): the training-view points
    just after one are left out of the overfitting slope and the train–test gap."""

    metric: str
    test_step: str
    test_value: str
    train_step: str = ""
    train_value: str = ""
    better: str = "higher"
    resets: Callable[[dict], Sequence[int]] | None = None


@dataclass(frozen=True)
class LoadMarks:
    """How a kind's runs mark that they were timed while other processes loaded the machine
    (`splatbench.metrics.load`); every name is a metric of the kind's result.

    flag: a 0 / 1 metric, 1 for a run timed under load; scope: what such a run is left out of:
    "timed" (the comparisons and Pareto fronts of the kind's ``timed`` metrics only: the train
    kind, whose quality does not depend on the load) or "all" (every finding: the raster kind,
    whose every metric is a time); other: the others' estimated load; cores: the usable cores.
    """

    flag: str
    scope: str
    other: str = "load_other"
    cores: str = "cores"


@dataclass(frozen=True)
class KindReport:
    """A kind's report declarations; every metric is named as its result's field (`RunKind.result`),
    where its label, format, unit, direction and meaning are declared.

    metrics: the table's metrics, in column order; rules: the findings' primary metric
    and comparisons (None: no findings); tradeoffs: the Pareto figures, in report order;
    timed: metrics that are times (left out for runs timed under load: ``load``); settling: the
    curves that decide whether a cell had settled; confounds: counts a report names when a
    cell changed them besides its setting; confound_floor: (count, floor) pairs: a confound count left
    out where both sides' means are below its floor (too few to change the model); load: how runs
    timed under load are marked (None:
    the kind records no load); model_bytes: the bytes of each run's trained model (stated beside
    each comparison's Gaussians; None: not known). The hooks, each run in its order: title_notes
    (lines right under the report's title, e.g. that a quick-protocol report is a smoke test),
    header_notes (the report's header), axis_notes (each axis finding), metric_notes (the "Metrics" section), run_findings
    (a section each, after the axes), check_notes (the check's runs, under its per-seed table); min_effects
    (the minimum effects that depend on how the runs measured, `MinEffects`; None: the comparisons' own).
    """

    metrics: tuple[str, ...]
    rules: FindingRules | None = None
    tradeoffs: tuple[Tradeoff, ...] = ()
    timed: tuple[str, ...] = ()
    settling: SettlingCurves | None = None
    confounds: tuple[str, ...] = ()
    confound_floor: tuple[tuple[str, float], ...] = ()
    load: LoadMarks | None = None
    header_notes: tuple[HeaderNote, ...] = ()
    title_notes: tuple[HeaderNote, ...] = ()
    model_bytes: ModelBytes | None = None
    axis_notes: tuple[AxisNote, ...] = ()
    metric_notes: tuple[MetricNote, ...] = ()
    run_findings: tuple[RunFinding, ...] = ()
    check_notes: tuple[CheckNote, ...] = ()
    min_effects: MinEffects | None = None

    def check(self, specs: Mapping[str, MetricSpec]) -> None:
        """`TypeError` naming a metric these declarations name that ``specs`` (the kind's result's
        metrics) lacks, or a load scope other than "timed" and "all"."""
        named = [*self.metrics, *self.timed, *self.confounds, *(name for name, _ in self.confound_floor)]
        if self.rules is not None:
            named += [self.rules.primary, *(c.metric for c in self.rules.comparisons)]
            named += [self.rules.size] if self.rules.size else []
            named += list(self.rules.quality)
        named += [n for t in self.tradeoffs for n in (t.cost, t.quality)]
        if self.load is not None:
            named += [self.load.flag, self.load.other, self.load.cores]
            if self.load.scope not in ("timed", "all"):
                raise TypeError(f"LoadMarks.scope: expected 'timed' or 'all', got {self.load.scope!r}")
        unknown = [n for n in dict.fromkeys(named) if n not in specs]
        if unknown:
            raise TypeError(f"KindReport names metrics its kind's result does not have: {', '.join(unknown)}")


__all__ = ["Claim", "Finding", "done_runs", "AxisRow", "AxisRows", "HeaderNote", "ModelBytes", "AxisNote", "MetricNote", "RunFinding", "CheckNote", "RunNotes", "MinEffects",
           "Comparison", "FindingRules", "Tradeoff", "SettlingCurves", "LoadMarks", "KindReport"]
