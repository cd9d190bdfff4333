"""Findings: short statements written from an axis table's numbers, never by hand.

Each finding is a list of `Claim` records (a number, its 95 % interval, where it comes
from and how it is written); the text is rendered from the claims, so a test can
recompute every number from ``results.parquet`` and find its text in the report. Per
axis:

* **best**: per scene, the row with the best mean of the kind's primary metric, named only
  when its paired lead over the runner-up is significant and at least the comparison's
  minimum effect (claim ``best``) and, for a kind that declares a size metric
  (`FindingRules.size`: the train kind's Gaussian count), the leader is not larger than the
  runner-up by more than that metric's minimum effect (geometric mean of the paired ratio);
  otherwise "no single best" (claim ``no best``; "at comparable size" with a ``size`` claim
  when only the size kept it from being named);
* **vs**: every other row against the reference row (the one-at-a-time base, else the
  axis's first value), per scene, for each of the kind's comparisons, **paired over
  seeds** (`splatbench.metrics.stats`): ``diff`` is the mean of ``b_s - a_s`` with
  its t interval, ``ratio`` the geometric mean of ``b_s / a_s`` with its interval;
  ``mean`` is the row's own mean (for a metric that is already relative to the base,
  like the raster kind's time ratio) with its t interval. When the interval contains
  the null value (0 for a difference, 1 for a ratio or a relative metric) the text
  says "no significant difference"; against the comparison's ``min_effect``, one rule
  (`reading`): "no practical difference" only where the whole interval lies within ± it,
  "inconclusive" where the interval reaches beyond it while the estimate is below it or the
  interval contains no difference; when the seeds did not vary the result (a
  half-width of zero at the precision written, `no_spread`), "no interval" and nothing
  is significant; with one seed it says no interval can be computed. Where the kind
  declares its curves (`KindReport.settling`), a primary-metric comparison whose cells
  had not settled is marked **not settled** (`splatbench.reports.settling`), and the
  kind's confound counts (`KindReport.confounds`) that differ are named ("Also changed");
* **holm**: Holm's step-down correction (family-wise 5 %) over the primary metric's "vs" comparisons
  that have an interval, each one's two-sided p-value from its own t interval (`t_p_value`): how
  many significant alone remain (the Summary marks the others "not significant after Holm"), and per
  row and scene how many seeds put the row above the reference (`holm_line`);
* **count**: how many such comparisons the table prints with an interval (each at 95 %, no correction
  for multiplicity but Holm's over the primary ones);
* the kind's own notes appended to it (`KindReport.axis_notes`), e.g. the degree ``auto``
  ended at on the train kind's SH degree axis.

Runs the kind marks as timed under load (`KindReport.load`) are left out of every finding
(not of the tables) where the mark's scope is "all" (the raster kind's ``metric.loaded``:
timed while the load average exceeded half the cores), and of the comparisons of the kind's
``timed`` metrics only where it is "timed" (the train kind's ``metric.time_loaded``): their
quality metrics do not depend on the load.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import pandas as pd

from splatbench.errors import InputError
from splatbench.experiments.kind_report import (AxisNote, Claim, Comparison, Finding, FindingRules, SettlingCurves,
                                                done_runs)
from splatbench.experiments.kinds import RunKind
from splatbench.plotting import pareto_front
from splatbench.metrics.spec import MetricSpec, clip
from splatbench.metrics.stats import Interval, holm, paired_difference, paired_ratio, t_interval, t_p_value
from splatbench.reports.settling import CellSettling, cell_settling, paired_curve, unsettled_reason
from splatbench.experiments.configs import decode, flatten, run_config
from splatbench.experiments.spec import ExperimentSpec, same_value
from splatbench.reports.tables import AxisTable, Row, display, loaded_runs, seed_values


def rules_for(kind: RunKind, metrics: tuple[MetricSpec, ...], min_effect: Mapping[str, float] | None = None
              ) -> FindingRules | None:
    """The kind's rules, restricted to metrics present; another kind compares its first metric.
    ``min_effect`` (an experiment file's ``[report] min_effect``) replaces the kind's minimum
    effects by metric name; a name the kind does not compare is a one-line `InputError`."""
    names = {m.name for m in metrics}
    declared = kind.report
    if declared is not None:
        r = declared.rules
        if r is None:
            return None
        rules = FindingRules(r.primary, tuple(c for c in r.comparisons if c.metric in names),
                             r.size if r.size in names else None, tuple(q for q in r.quality if q in names))
        compared = [c.metric for c in r.comparisons]
        if r.primary not in names:
            return None
    elif not metrics:
        return None
    else:
        rules = FindingRules(metrics[0].name, (Comparison(metrics[0].name, "diff"),))
        compared = [metrics[0].name]
    for metric in (min_effect or {}):
        if metric not in compared:
            raise InputError(f"report.min_effect.{metric}: not a metric the {kind.name!r} findings compare "
                             f"(expected one of: {', '.join(compared)})")
    if min_effect:
        rules = FindingRules(rules.primary, tuple(dataclasses.replace(c, min_effect=min_effect[c.metric])
                                                  if c.metric in min_effect else c for c in rules.comparisons),
                             rules.size, rules.quality)
    return rules


def fmt_number(value: float, how: str, spec: MetricSpec) -> str:
    """A claim's number as written: ``+0.42 dB``, ``×1.312``, ``27.50 dB``."""
    if value is None or not math.isfinite(value):
        return "n/a"
    unit = f" {spec.unit}" if spec.unit else ""
    if how == "diff":
        return f"{value:+{spec.fmt}}{unit}"
    if how == "ratio":
        return f"×{value:.3f}"
    return f"{format(value, spec.fmt)}{unit}"


def _bound(value: float, how: str, spec: MetricSpec) -> str:
    if how == "diff":
        return f"{value:+{spec.fmt}}"
    if how == "ratio":
        return f"×{value:.3f}"
    return format(value, spec.fmt)


def no_spread(iv: Interval, how: str, spec: MetricSpec) -> bool:
    """True when the interval is defined but its half-width is zero at the precision the report
    writes (``±0.00``): the seeds did not vary the result, so the interval is no evidence of
    anything (a rerun varies more than these seeds did; docs/reports.md)."""
    if not iv.defined:
        return False
    fmt = ".3f" if how == "ratio" else spec.fmt
    return float(format(iv.half_width, fmt)) == 0.0


def _effect_size(value: float, how: str, null: float | None, fmt: str) -> float:
    """How far ``value`` lies from no difference, at the precision the report writes it: ``|v - null|``
    (``fmt``), or for a ratio the relative change ``r - 1`` or ``1 / r - 1`` (``r`` at ``.3f``)."""
    if how == "ratio":  # judged at the precision the report writes (×1.050 is 5 %)
        if value <= 0:
            return math.inf
        up = value if value >= 1 else 1.0 / value
        return float(f"{up:.3f}") - 1.0
    return abs(float(format(value - (null or 0.0), fmt or ".6g")))


def practical(iv: Interval, how: str, null: float | None, min_effect: float | None, fmt: str = "") -> bool:
    """True when the estimate, at the precision the report writes it (``fmt``), is at least
    ``min_effect`` from the null value (a relative change for a ratio: ``r >= 1 + min_effect``
    or ``1 / r >= 1 + min_effect``); True when there is no minimum effect. A printed +0.10 dB
    is never "below the 0.1 dB minimum effect"."""
    if min_effect is None or not math.isfinite(iv.estimate):
        return min_effect is None
    if how == "ratio" and iv.estimate <= 0:
        return False
    return _effect_size(iv.estimate, how, null, fmt) >= min_effect - 1e-12


#: How an interval reads against no difference and the minimum effect (`reading`).
READINGS = ("difference", "no practical difference", "inconclusive", "no significant difference", "no interval",
            "no test")


def bounded(iv: Interval, how: str, spec: MetricSpec) -> Interval:
    """``iv`` cut at the values its number can take (`splatbench.metrics.spec.clip`: an SSIM mean
    never above 1, an LPIPS never below 0): what the report prints and judges."""
    if not iv.defined:
        return iv
    return dataclasses.replace(iv, **dict(zip(("low", "high"), clip(iv.low, iv.high, how, spec))))


def reading(iv: Interval, how: str, null: float | None, spec: MetricSpec, min_effect: float | None = None) -> str:
    """The one rule that decides what a difference may be called (`READINGS`), at the precision written:

    * "no interval": one seed, or seeds that did not vary the result (`no_spread`);
    * "no test": no null value (a "mean" comparison without one);
    * "difference": the interval excludes ``null`` and the estimate is at least ``min_effect`` from it
      (`practical`; any significant difference where there is no minimum effect);
    * "no practical difference": both of the interval's bounds lie less than ``min_effect`` from
      ``null`` (the whole interval within ± the minimum effect; significant or not): only here
      does a report rule an effect out;
    * "inconclusive": every other case with a minimum effect: the interval reaches beyond it while
      the estimate is below it or the interval contains ``null``;
    * "no significant difference": the interval contains ``null`` and there is no minimum effect."""
    if not iv.defined or no_spread(iv, how, spec):
        return "no interval"
    if null is None:
        return "no test"
    iv = bounded(iv, how, spec)
    if iv.excludes(null) and practical(iv, how, null, min_effect, spec.fmt):
        return "difference"
    if min_effect is None:
        return "no significant difference"
    if max(_effect_size(iv.low, how, null, spec.fmt), _effect_size(iv.high, how, null, spec.fmt)) < min_effect - 1e-12:
        return "no practical difference"
    return "inconclusive"


def fmt_min_effect(min_effect: float, how: str, spec: MetricSpec) -> str:
    """``0.1 dB``, ``5 %`` (a ratio)."""
    if how == "ratio":
        return f"{100 * min_effect:g} %"
    return f"{min_effect:g}" + (f" {spec.unit}" if spec.unit else "")


def judge(iv: Interval, how: str, null: float | None, spec: MetricSpec, min_effect: float | None = None
          ) -> tuple[bool, bool]:
    """(significant, practical) of an interval (`Claim`): practical is `reading`'s "difference"."""
    significant = null is not None and iv.excludes(null) and not no_spread(iv, how, spec)
    return significant, reading(iv, how, null, spec, min_effect) == "difference"


@dataclasses.dataclass(frozen=True)
class IntervalText:
    """An interval as the findings write it (`interval_text`), in parts: ``estimate`` (``+0.42 dB``);
    ``interval`` (`` [95 % CI +0.10, +0.74]``, "" where there is none); ``verdict``, its `reading` in words
    (``, no significant difference, inconclusive``; "" for a difference) or why it has no interval
    (`` (1 seed: no interval)``); ``why``, what explains the reading (`` (its interval reaches beyond the
    0.1 dB minimum effect)``; "" where nothing does). The findings print `text`, the Summary `short`."""

    estimate: str
    interval: str = ""
    verdict: str = ""
    why: str = ""

    @property
    def text(self) -> str:
        """The whole: ``+0.34 dB [95 % CI -0.84, +1.52], no significant difference, inconclusive (its
        interval reaches beyond the 0.1 dB minimum effect)``."""
        return self.estimate + self.interval + self.verdict + self.why

    @property
    def short(self) -> str:
        """Without the explanation of its reading: ``+0.34 dB [95 % CI -0.84, +1.52], no significant
        difference, inconclusive`` (the Summary's)."""
        return self.estimate + self.interval + self.verdict


def interval_text(iv: Interval, how: str, spec: MetricSpec, null: float | None, min_effect: float | None = None
                  ) -> IntervalText:
    """``+0.42 dB [95 % CI +0.10, +0.74]`` followed by its `reading`: nothing for a difference;
    ", no practical difference (interval within ±0.1 dB)"; ", inconclusive (below the 0.1 dB minimum
    effect, but its interval reaches beyond it)" or ", no significant difference, inconclusive (its
    interval reaches beyond the 0.1 dB minimum effect)"; ", no significant difference" without a
    minimum effect; ``(1 seed: no interval)``, or, when its half-width is zero at the report's
    precision (never ``±0.00``), ``(seeds did not vary the result: no interval)`` where it is
    exactly zero and ``(seeds varied it by less than the precision shown, ±0.003 dB: no interval)``
    where it is not; in parts (`IntervalText`)."""
    number = fmt_number(iv.estimate, how, spec)
    if not iv.defined:
        return IntervalText(number, verdict=f" ({iv.n} seed{'s' if iv.n != 1 else ''}: no interval)")
    if no_spread(iv, how, spec):
        if iv.half_width <= 1e-12 * max(1.0, abs(iv.estimate)):  # equal values, up to the t-interval's own rounding
            return IntervalText(number, verdict=" (seeds did not vary the result: no interval)")
        unit = "" if how == "ratio" or not spec.unit else f" {spec.unit}"
        return IntervalText(number, verdict=f" (seeds varied it by less than the precision shown, "
                                            f"±{iv.half_width:.1g}{unit}: no interval)")
    shown = bounded(iv, how, spec)
    interval = f" [95 % CI {_bound(shown.low, how, spec)}, {_bound(shown.high, how, spec)}]"
    said = reading(iv, how, null, spec, min_effect)
    effect = fmt_min_effect(min_effect, how, spec) if min_effect is not None else ""
    if said == "no practical difference":
        return IntervalText(number, interval, ", no practical difference", f" (interval within ±{effect})")
    if said == "inconclusive" and iv.excludes(null):
        return IntervalText(number, interval, ", inconclusive",
                            f" (below the {effect} minimum effect, but its interval reaches beyond it)")
    if said == "inconclusive":
        return IntervalText(number, interval, ", no significant difference, inconclusive",
                            f" (its interval reaches beyond the {effect} minimum effect)")
    if said == "no significant difference":
        return IntervalText(number, interval, ", no significant difference")
    return IntervalText(number, interval)


def fmt_interval(iv: Interval, how: str, spec: MetricSpec, null: float | None, min_effect: float | None = None
                 ) -> str:
    """An interval and its reading as the findings write it: `interval_text`'s whole text."""
    return interval_text(iv, how, spec, null, min_effect).text


def clears(iv: Interval, how: str, null: float, min_effect: float | None) -> bool:
    """True when the whole interval lies beyond the minimum effect on the estimate's side of ``null``:
    its bound nearer to no difference exceeds it (``low - null > min_effect`` for a positive
    difference; for a ratio ``low > null (1 + min_effect)``, or ``high < null / (1 + min_effect)``).
    What "best" asks of a lead over the runner-up (docs/reports.md, "Best"); without a minimum
    effect, that the interval excludes ``null``."""
    if not iv.defined or not math.isfinite(iv.low) or not math.isfinite(iv.high):
        return False
    m = min_effect or 0.0
    if how == "ratio":
        return iv.low > null * (1 + m) or iv.high < null / (1 + m)
    return iv.low - null > m or null - iv.high > m


def other_way(primary: MetricSpec, diff: float, others: Sequence[tuple[MetricSpec, Interval, str]]
              ) -> list[tuple[str, str]]:
    """The quality metrics (`FindingRules.quality`) that go significantly the other way of a primary
    difference ``diff`` (its estimate minus the null, in the primary's direction: positive is the
    compared cell better where higher is better): ``others`` holds each one's paired interval and
    how it compares ("diff" or "ratio"); each one whose interval excludes no difference (with a
    spread) on the side that is worse, as (its name, ``SSIM −0.010 [95 % CI −0.015, −0.005]``)."""
    if not math.isfinite(diff) or diff == 0.0:
        return []
    up = (diff > 0) == (primary.better != "lower")  # the compared cell is better in the primary metric
    out = []
    for spec, iv, how in others:
        null = 1.0 if how == "ratio" else 0.0
        if not iv.defined or not iv.excludes(null) or no_spread(iv, how, spec):
            continue
        higher = iv.estimate > null
        better = higher == (spec.better != "lower")
        if better != up:
            out.append((_name(spec), f"{_name(spec)} {fmt_interval(iv, how, spec, null)}"))
    return out


def paired(a: dict[int, float], b: dict[int, float], comp: Comparison) -> tuple[Interval, float | None]:
    """The interval of row ``b`` against reference ``a`` (per-seed values) and its null value."""
    if comp.how == "diff":
        return paired_difference(a, b), 0.0
    if comp.how == "ratio":
        return paired_ratio(a, b), 1.0
    return t_interval(list(b.values())), comp.null


def reference_row(table: AxisTable) -> Row:
    """The one-at-a-time base row, else the first row."""
    return next((r for r in table.rows if r.is_base), table.rows[0])


def usable_runs(runs: pd.DataFrame, kind: RunKind) -> pd.DataFrame:
    """The done runs findings may use: not those the kind marks as timed under load where the
    mark leaves them out of every finding (module doc)."""
    done = done_runs(runs)
    load = kind.report.load if kind.report is not None else None
    col = f"metric.{load.flag}" if load is not None and load.scope == "all" else None
    if col in done.columns:
        done = done[pd.to_numeric(done[col], errors="coerce").fillna(0) == 0]
    return done

@dataclasses.dataclass(frozen=True, eq=False)
class _Axis:
    """What every part of one axis's finding reads (`axis_finding`; built by `_Axis.of`): the table, the
    kind and its rules, the runs the findings may use, and the ``[report] matched`` cells. Its methods
    pick a cell's runs and per-seed values, its model size and whether its curves settled."""

    table: AxisTable
    kind: RunKind
    runs: pd.DataFrame  # every run of the grid, as given (the kind's axis notes and `load_recorded` read them)
    experiment: ExperimentSpec | None
    rules: FindingRules
    specs: dict[str, MetricSpec]  # metric name -> its spec, for the table's metrics
    scenes: list[str]  # in the table's order
    usable: pd.DataFrame  # the done runs the findings use (`usable_runs`)
    timed_usable: pd.DataFrame  # of those, the ones whose times count (`loaded_runs`: not timed under load)
    excluded: int  # done runs left out of every finding, timed under load (`usable_runs`)
    untimed: int  # usable runs left out of the timed metrics' comparisons only
    stratum: set[str]  # the run ids at the matched size (`_stratum`; empty: none declared)
    by_bytes: bool  # the size is judged by bytes, not by the size metric (`bytes_differ`)
    _settled: dict = dataclasses.field(default_factory=dict, repr=False)  # (scene, label) -> `settle`'s answer

    @classmethod
    def of(cls, table: AxisTable, kind: RunKind, runs: pd.DataFrame, min_effect: Mapping[str, float] | None,
           experiment: ExperimentSpec | None) -> _Axis | None:
        """The axis's context; None when the kind has no rules for its metrics or the table is empty."""
        rules = rules_for(kind, table.metrics, min_effect)
        if rules is None or table.frame.empty:
            return None
        specs = {m.name: m for m in table.metrics}
        usable = usable_runs(runs, kind)
        timed = bool(kind.report is not None and kind.report.timed)
        loaded = loaded_runs(usable, kind)  # all False where the kind's mark is not recorded
        dim, matched_values = _matched_setting(experiment)
        size = specs.get(rules.size) if rules.size else None
        bytes_of = kind.report.model_bytes if kind.report is not None else None
        return cls(table, kind, runs, experiment, rules, specs, list(dict.fromkeys(table.frame.scene)), usable,
                   usable[~loaded] if timed else usable, len(done_runs(runs)) - len(usable),
                   int(loaded.sum()) if timed else 0, _stratum(usable, dim, matched_values),
                   size is not None and bytes_differ(usable, bytes_of, size.name))

    # what the kind declares, and what it compares

    @property
    def declared(self):
        """The kind's `KindReport` (None: it declares none)."""
        return self.kind.report

    @property
    def timed(self) -> set[str]:
        """The metrics that are times (`KindReport.timed`)."""
        return set(self.declared.timed) if self.declared is not None else set()

    @property
    def primary(self) -> MetricSpec:
        return self.specs[self.rules.primary]

    @property
    def sign(self) -> float:
        """+1 where higher is better in the primary metric, -1 where lower is."""
        return -1.0 if self.primary.better == "lower" else 1.0

    @property
    def primary_comp(self) -> Comparison:
        """How the primary metric is compared (a difference where the rules do not say)."""
        return next((c for c in self.rules.comparisons if c.metric == self.primary.name),
                    Comparison(self.primary.name, "diff"))

    @property
    def primary_null(self) -> float:
        """The primary comparison's no difference (0 for a difference, 1 for a ratio)."""
        comp = self.primary_comp
        return {"diff": 0.0, "ratio": 1.0}.get(comp.how, comp.null or 0.0)

    @property
    def unit_text(self) -> str | None:
        """The primary comparison's minimum effect as written (``0.1 dB``; None: it has none)."""
        comp = self.primary_comp
        return fmt_min_effect(comp.min_effect, comp.how, self.primary) if comp.min_effect is not None else None

    @property
    def qualities(self) -> list[tuple[MetricSpec, str]]:
        """The kind's other quality metrics (`FindingRules.quality`), each with how it is compared."""
        return [(self.specs[q], next((c.how for c in self.rules.comparisons if c.metric == q), "diff"))
                for q in self.rules.quality if q in self.specs and q != self.primary.name]

    @property
    def size_spec(self) -> MetricSpec | None:
        """The size metric (`FindingRules.size`; None: the kind declares none)."""
        return self.specs.get(self.rules.size) if self.rules.size else None

    @property
    def size_effect(self) -> float:
        """The size metric's minimum effect (0 where none)."""
        return next((c.min_effect for c in self.rules.comparisons if c.metric == self.rules.size), None) or 0.0

    @property
    def size_word(self) -> str:
        """What the size is counted in: ``bytes``, ``Gaussians`` ("" without a size metric)."""
        return "bytes" if self.by_bytes else (_name(self.size_spec) if self.size_spec is not None else "")

    @property
    def bytes_of(self) -> Callable[[pd.DataFrame], pd.Series] | None:
        """The kind's bytes per run (`KindReport.model_bytes`; None: it has none)."""
        return self.declared.model_bytes if self.declared is not None else None

    @property
    def settling(self) -> SettlingCurves | None:
        """The kind's curves (`KindReport.settling`; None: none declared)."""
        return self.declared.settling if self.declared is not None else None

    @property
    def matched(self) -> tuple[str | None, tuple]:
        """The ``[report] matched`` setting and its values (`_matched_setting`)."""
        return _matched_setting(self.experiment)

    # a cell's runs and values

    def selected(self, scene: str, row: Row, pool: pd.DataFrame) -> pd.DataFrame:
        """The runs of ``pool`` of ``row`` at ``scene``."""
        return pool[(pool.scene == scene) & pool.run_id.isin(row.run_ids)]

    def cells(self, scene: str, row: Row, ids: set[str] | None = None) -> pd.DataFrame:
        """The usable runs of ``row`` at ``scene``, only those of ``ids`` (None: all)."""
        sel = self.selected(scene, row, self.usable)
        return sel if ids is None else sel[sel.run_id.isin(ids)]

    def values(self, scene: str, row: Row, metric: str) -> dict[int, float]:
        """seed -> the row's ``metric`` at ``scene`` (a timed metric: of the runs whose times count)."""
        sel = self.selected(scene, row, self.timed_usable if metric in self.timed else self.usable)
        return seed_values(sel, metric) if len(sel) else {}

    def values_in(self, scene: str, row: Row, metric: str, ids: set[str] | None) -> dict[int, float]:
        """seed -> the row's ``metric`` at ``scene`` over the runs of ``ids`` (None: all; {}: not recorded)."""
        sel = self.cells(scene, row, ids)
        return seed_values(sel, metric) if len(sel) and f"metric.{metric}" in sel.columns else {}

    def quality_intervals(self, scene: str, a: Row, b: Row) -> list[tuple[MetricSpec, Interval, str]]:
        """The paired interval of ``b`` against ``a`` of each of the kind's other quality metrics, with how it
        is compared (`other_way`'s ``others``)."""
        out = []
        for spec, how in self.qualities:
            iv, _ = paired(self.values(scene, a, spec.name), self.values(scene, b, spec.name),
                           Comparison(spec.name, how))
            out.append((spec, iv, how))
        return out

    # model size

    def size_values(self, scene: str, row: Row, ids: set[str] | None = None) -> dict[int, float]:
        """seed -> the row's model size at ``scene``: its bytes where the table's cells' bytes per
        Gaussian differ (`bytes_differ`), else its size metric (a seed's runs averaged first)."""
        return _sizes(self.cells(scene, row, ids), self.size_spec.name, self.bytes_of, self.by_bytes)

    def size_ratio_text(self, text: str, scene: str, ra: Row, rb: Row, ids: set[str] | None = None) -> str:
        """``×3.999 [95 % CI …] the bytes (×0.949 the Gaussians)`` where sized by bytes, else
        ``… the Gaussians``: both named where they differ (``text``: the ratio as written)."""
        if not self.by_bytes:
            return f"{text} the {self.size_word}"
        name = self.size_spec.name
        count = paired_ratio(self.values_in(scene, ra, name, ids), self.values_in(scene, rb, name, ids))
        also = f" (×{count.estimate:.3f} the {_name(self.size_spec)})" if count.n and math.isfinite(count.estimate) \
            else ""
        return f"{text} the bytes{also}"

    def mean_of(self, scene: str, row: Row, metric: str) -> float | None:
        """The row's mean over seeds at ``scene`` of ``metric``, or of its bytes where ``metric`` is "bytes"
        (None: not recorded)."""
        sel = self.cells(scene, row)
        if metric == "bytes":
            if self.bytes_of is None:
                return None
            v = pd.Series(_sizes(sel, metric, self.bytes_of, True), dtype="float64")
        else:
            v = pd.Series(self.values_in(scene, row, metric, None), dtype="float64")
        return float(v.mean()) if len(v) else None

    def off_size(self, ratio: Interval) -> bool:
        """Two cells declared matched that did not end at one size: their paired size ratio, as written
        (×4.070), is more than the size's minimum effect (5 % where none) from ×1 (a run that missed its
        count: the budget strategy short of its budget warns)."""
        return bool(ratio.n) and math.isfinite(ratio.estimate) and \
            abs(float(f"{ratio.estimate:.3f}") - 1.0) > (self.size_effect or 0.05) + 1e-12

    def size_line(self, a: Row, b: Row) -> str:
        """``Size (mean over seeds, `b` against `a`): fox 5,210 Gaussians, 1.23 MB against 1,000, 0.24 MB``
        ("" without a size metric or sizes)."""
        size = self.size_spec
        if size is None:
            return ""
        parts = []
        for scene in self.scenes:
            na, nb = self.mean_of(scene, a, size.name), self.mean_of(scene, b, size.name)
            if na is None or nb is None:
                continue
            ba, bb = self.mean_of(scene, a, "bytes"), self.mean_of(scene, b, "bytes")
            mb = (lambda x: f", {x / 1e6:.2f} MB") if ba is not None and bb is not None else (lambda x: "")
            parts.append(f"{scene} {_count(nb)} {_name(size)}{mb(bb)} against {_count(na)}{mb(ba)}")
        if not parts:
            return ""
        what = f"{_name(size)} and bytes" if self.bytes_of is not None else _name(size)
        return f"{what[:1].upper()}{what[1:]} (mean over seeds, `{b.label}` against `{a.label}`): " + "; ".join(parts)

    # settling

    def settle(self, scene: str, row: Row) -> CellSettling | None:
        """The row's curves at ``scene`` over the last quarter (None: not judged: the kind declares no curves
        of the primary metric, or the primary comparison has no minimum effect)."""
        settling, comp = self.settling, self.primary_comp
        effect = comp.min_effect if settling is not None and settling.metric == self.primary.name else None
        if effect is None:
            return None
        key = (scene, row.label)
        if key not in self._settled:
            self._settled[key] = cell_settling(self.selected(scene, row, self.usable), settling, effect)
        return self._settled[key]

    def unsettled(self, scene: str, a: Row, b: Row, diff: float) -> str:
        """"" when the difference ``b - a`` at ``scene`` is settled or not judged, else why not."""
        return unsettled_reason(self.settle(scene, a), self.settle(scene, b), (a.label, b.label), diff,
                                self.primary.unit)


def _matched_setting(experiment: ExperimentSpec | None) -> tuple[str | None, tuple]:
    """The experiment's ``[report] matched`` setting and its values ((None, ()): none declared)."""
    dim, values = next(iter((dict(experiment.matched) if experiment is not None else {}).items()), (None, ()))
    return dim, tuple(values)


def axis_finding(table: AxisTable, kind: RunKind, runs: pd.DataFrame, min_effect: Mapping[str, float] | None = None,
                 experiment: ExperimentSpec | None = None) -> Finding | None:
    """The finding of one axis (None when the kind has no rules or nothing is done),
    with the lines and claims of the kind's axis notes (`KindReport.axis_notes`) appended;
    ``experiment``: its ``[report] matched`` cells (docs/reports.md, "Model size");
    ``min_effect``: the experiment file's minimum effects by metric (`rules_for`). Its blocks, in order
    (`_Part`): the best per scene (`_best_part`), each row against the reference with Holm's correction
    (`_against_reference`), the matched cells against each other (`_matched_cells_part`), the reference
    against itself (`_self_part`), how many comparisons have an interval (`_count_part`), and what the runs
    left out or did not record (`_caveats_part`)."""
    ax = _Axis.of(table, kind, runs, min_effect, experiment)
    if ax is None:
        return None
    bests = [b for b in (_best_at(ax, scene) for scene in ax.scenes) if b is not None]
    if not bests:
        return _all_loaded(ax)
    best = _best_part(ax, bests)
    ref = reference_row(table)
    others = [r for r in table.rows if r.label != ref.label and not r.extra]
    vs, family = _against_reference(ax, ref, others) if others and ax.rules.comparisons else (_Part(), [])
    matched = _matched_cells_part(ax)
    itself = _self_part(ax, ref)
    claims = [*best.claims, *vs.claims, *matched.claims, *itself.claims]
    count = _count_part(ax, claims, family, ref)
    caveats = _caveats_part(ax, others)
    lines = [*best.lines, *vs.lines, *matched.lines, *itself.lines, *caveats.lines]
    claims += count.claims
    appendix = [*vs.appendix, *count.appendix, *caveats.appendix]  # the section "Appendix: <axis> in full"
    summary = [*vs.summary, *best.summary]  # the report's "Summary" (`Finding.summary`): the texts above, cut short
    for note in ax.declared.axis_notes if ax.declared is not None else ():
        more_lines, more_claims = note(table, runs, ax.scenes)
        appendix += more_lines
        claims += more_claims
    chose = [c for c in claims if c.kind == "auto"]  # a row that chose its setting per scene (SH degree "auto")
    if chose:
        summary.append(f"- **`{chose[0].label}`** ended at SH degree " + ", ".join(f"{c.text} on {c.scene}" for c in chose)
                       + f": each of its differences is the degree it chose and its holdout's cost together, not "
                         f"one degree's (\"Appendix: {table.axis} in full\").")
    return Finding(table.axis, lines, claims, appendix, summary)


@dataclasses.dataclass(frozen=True)
class _Part:
    """One block of an axis's finding (`axis_finding` puts them together): its ``lines`` (the findings'),
    ``claims``, ``appendix`` lines and ``summary`` lines, each in the order written."""

    lines: tuple[str, ...] = ()
    claims: tuple[Claim, ...] = ()
    appendix: tuple[str, ...] = ()
    summary: tuple[str, ...] = ()


def _all_loaded(ax: _Axis) -> Finding | None:
    """The finding of an axis with no best at any scene: that every done run was timed under load, where
    the runs were left out for it (`_Axis.excluded`); None otherwise (nothing done)."""
    if not ax.excluded:
        return None
    return Finding(ax.table.axis, [f"- No findings: all {ax.excluded} done run(s) were timed while the load average "
                                   f"exceeded half the cores (the table's `loaded` column); rerun them on a "
                                   f"quiet machine (docs/reports.md, \"Quiet numbers\")."], [])


# Best per scene

@dataclasses.dataclass(frozen=True)
class _Best:
    """One scene's verdict on its best cell (`_best_at`): ``text`` as the findings write it, ``short`` as the
    Summary does (without the lead's numbers), and its ``claims``."""

    text: str
    short: str
    claims: tuple[Claim, ...]


@dataclasses.dataclass(frozen=True)
class _Lead:
    """The leader ``row``'s paired lead over the runner-up ``runner`` at one scene (`_best_at`), which each verdict
    reads: ``mean``, the leader's mean, written ``mean_text``; ``how``, "diff" or "ratio", with its ``null``;
    ``text``, the lead as written (`fmt_interval`); ``why``, why it is not settled ("": settled or not
    judged); ``settled``, the claim's."""

    scene: str
    row: Row
    runner: Row
    metric: str  # the primary metric's name
    mean: Interval
    mean_text: str
    how: str
    null: float
    lead: Interval
    significant: bool
    practical: bool
    text: str
    why: str
    settled: bool | None

    def claim(self, kind: str, text: str) -> Claim:
        """The verdict's claim: "best" (on the leader's mean) or "no best" (on its lead)."""
        how, value = ("mean", self.mean.estimate) if kind == "best" else (self.how, self.lead.estimate)
        return Claim(kind, self.scene, self.row.label, self.metric, how, value, text, self.runner.label,
                     self.lead.low, self.lead.high, self.lead.n, self.significant, self.practical, self.settled)


def _best_at(ax: _Axis, scene: str) -> _Best | None:
    """The best cell at ``scene`` by the mean of the primary metric over seeds (extra cells left out: they
    are compared only at a matched size): the only cell, a best (`_best_named`), or no single best
    (`_no_best`, `_no_best_at_size`); None where no cell has a done run."""
    primary, comp = ax.primary, ax.primary_comp
    means = [(t_interval(list(ax.values(scene, row, primary.name).values())), row) for row in ax.table.rows
             if not row.extra]
    means = sorted(((iv, row) for iv, row in means if iv.n > 0), key=lambda m: -ax.sign * m[0].estimate)
    if not means:
        return None
    iv, row = means[0]
    mean_text = fmt_number(iv.estimate, "mean", primary)
    if len(means) == 1:
        text = f"{scene} `{row.label}` ({mean_text}; the only cell)"
        return _Best(text, text, (Claim("best", scene, row.label, primary.name, "mean", iv.estimate, mean_text,
                                        n=iv.n),))
    runner = means[1][1]
    how = "ratio" if comp.how == "ratio" else "diff"
    null = 1.0 if how == "ratio" else 0.0
    lead = (paired_ratio if how == "ratio" else paired_difference)(ax.values(scene, runner, primary.name),
                                                                   ax.values(scene, row, primary.name))
    significant, is_practical = judge(lead, how, null, primary, comp.min_effect)
    why = ax.unsettled(scene, runner, row, lead.estimate - null)
    settled = None if ax.settle(scene, row) is None else not why
    told = _Lead(scene, row, runner, primary.name, iv, mean_text, how, null, lead, significant, is_practical,
                 fmt_interval(lead, how, primary, null, comp.min_effect), why, settled)
    if not (significant and clears(lead, how, null, comp.min_effect)):
        return _no_best(ax, told)
    larger = _larger(ax, scene, row, runner)
    return _best_named(ax, told) if larger is None else _no_best_at_size(ax, told, larger)


def _larger(ax: _Axis, scene: str, row: Row, runner: Row) -> Interval | None:
    """The paired size ratio of the leader ``row`` to the runner-up ``runner`` at ``scene`` where the leader is
    larger by at least the size's minimum effect (None: not, or the kind has no size metric)."""
    if ax.size_spec is None:
        return None
    ratio = paired_ratio(ax.size_values(scene, runner), ax.size_values(scene, row))
    if ratio.n and math.isfinite(ratio.estimate) and ratio.estimate > 1.0 \
            and practical(ratio, "ratio", 1.0, ax.size_effect):
        return ratio
    return None


def _best_named(ax: _Axis, told: _Lead) -> _Best:
    """A best: ``glossy `0.2` (27.50 dB; +0.42 dB [95 % CI …] over `0`)``, with the quality metrics that go
    the other way (`other_way`) and whether it settled."""
    scene, row, runner = told.scene, told.row, told.runner
    reversed_ = other_way(ax.primary, told.lead.estimate - told.null, ax.quality_intervals(scene, runner, row))
    text = f"{scene} `{row.label}` ({told.mean_text}; {told.text} over `{runner.label}`)"
    short = text
    if reversed_:
        names = " and ".join(n for n, _ in reversed_)
        but = f", **but {names} go{'es' if len(reversed_) == 1 else ''} the other way**"
        text += f"{but} ({'; '.join(t for _, t in reversed_)})"
        short += but
    if told.why:
        text += f", **not settled** ({told.why})"
        short += ", **not settled**"
    return _Best(text, short, (told.claim("best", text),))


def _no_best_at_size(ax: _Axis, told: _Lead, larger: Interval) -> _Best:
    """No single best at comparable size: the leader leads clearly but is ``larger`` than the runner-up by
    more than the size's minimum effect; claimed "no best" and "size"."""
    scene, row, runner, size, table = told.scene, told.row, told.runner, ax.size_spec, ax.table
    size_text = fmt_interval(larger, "ratio", size, None)
    sized = {r.label: ax.mean_of(scene, r, "bytes") for r in table.rows} if ax.by_bytes else None
    front = _on_front(table, scene, size, ax.primary, (row, runner), sized,
                      [r.label for r in table.rows if not r.extra])
    at = ax.size_ratio_text(size_text, scene, runner, row)
    text = (f"{scene}: no single best at comparable size (`{row.label}`, {told.mean_text}, leads "
            f"`{runner.label}` by {told.text} at {at}, more than the "
            f"{fmt_min_effect(ax.size_effect, 'ratio', size)} minimum effect"
            + (f"; both on {FRONT_OF[any(r.extra for r in table.rows)]} {ax.size_word}/quality Pareto front"
               if front else "") + ")")
    short = (f"{scene}: no single best at comparable size (`{row.label}` leads `{runner.label}` at "
             f"{fmt_number(larger.estimate, 'ratio', size)} `{runner.label}`'s {ax.size_word})")
    if told.why:
        text += f", **not settled** ({told.why})"
        short += ", **not settled**"
    return _Best(text, short, (told.claim("no best", text),
                               Claim("size", scene, row.label, "bytes" if ax.by_bytes else size.name, "ratio",
                                     larger.estimate, size_text, runner.label, larger.low, larger.high, larger.n,
                                     *judge(larger, "ratio", 1.0, size, ax.size_effect))))


def _no_best(ax: _Axis, told: _Lead) -> _Best:
    """No single best: the lead's interval is not wholly beyond the minimum effect (or no difference)."""
    unit_text = ax.unit_text
    bound = ("" if not told.practical or unit_text is None else
             f"; its interval's bound nearer no difference is not beyond the {unit_text} minimum effect")
    text = (f"{told.scene}: no single best (`{told.row.label}`, {told.mean_text}, leads `{told.runner.label}` by "
            f"{told.text}{bound})")
    return _Best(text, f"{told.scene}: no single best", (told.claim("no best", text),))


def _best_part(ax: _Axis, bests: Sequence[_Best]) -> _Part:
    """The line of the best per scene with the rule that names one, its claims, and its Summary line."""
    primary, size = ax.primary, ax.size_spec
    word = "best" if primary.better != "lower" else "lowest"
    unit_text = ax.unit_text
    rule = ("named only where the 95 % interval of its paired lead over the runner-up lies wholly beyond "
            + (f"the {unit_text} minimum effect" if unit_text else "no difference")
            + (f" with no more than {fmt_min_effect(ax.size_effect, 'ratio', size)} more {ax.size_word}"
               if size is not None else "")
            + (" (float32 parameters: the cells' bytes per Gaussian differ)"
               if ax.by_bytes else ""))
    line = (f"- **{word.capitalize()} {_name(primary)}** per scene (mean over seeds; {rule}): "
            + "; ".join(b.text for b in bests) + ".")
    summary = f"- **{word.capitalize()} {_name(primary)}**: " + "; ".join(b.short for b in bests) + "."
    return _Part((line,), tuple(c for b in bests for c in b.claims), summary=(summary,))


# Each row against the reference

@dataclasses.dataclass(frozen=True)
class _Vs:
    """One row against the reference at one scene in one comparison (`_vs_at`): its "vs" ``claim``;
    ``brief``, its difference as the Summary writes it (`IntervalText.short`); ``sign``, how many seeds put
    the row above the reference, ``k/n`` (None: not the primary metric's difference or ratio); ``why``, why
    it is not settled ("": settled, not judged, or not the primary metric)."""

    claim: Claim
    brief: str
    sign: str | None
    why: str


def _vs_at(ax: _Axis, scene: str, ref: Row, row: Row, comp: Comparison) -> _Vs | None:
    """``row`` against ``ref`` at ``scene``, paired over seeds, in the comparison ``comp`` (`_Vs`); None where
    no seed has both."""
    spec = ax.specs[comp.metric]
    a, b = ax.values(scene, ref, comp.metric), ax.values(scene, row, comp.metric)
    iv, null = paired(a, b, comp)
    if iv.n == 0:
        return None
    is_primary = comp.metric == ax.primary.name
    sign = None
    if is_primary and comp.how in ("diff", "ratio"):
        pairs = [(a[k], b[k]) for k in a if k in b and math.isfinite(a[k]) and math.isfinite(b[k])]
        sign = f"{sum(1 for x, y in pairs if y > x)}/{len(pairs)}"
    written = interval_text(iv, comp.how, spec, null, comp.min_effect)
    significant, is_practical = judge(iv, comp.how, null, spec, comp.min_effect)
    why, settled = "", None
    if is_primary:
        why = ax.unsettled(scene, ref, row, iv.estimate - (null or 0.0))
        settled = None if ax.settle(scene, row) is None or ax.settle(scene, ref) is None else not why
    return _Vs(Claim("vs", scene, row.label, comp.metric, comp.how, iv.estimate, written.text, ref.label, iv.low,
                     iv.high, iv.n, significant, is_practical, settled), written.short, sign, why)


@dataclasses.dataclass(frozen=True)
class _RowAgainst:
    """One ``row`` against the reference (`_row_against`): ``line``, its findings line; ``more``, its appendix
    line ("": none); ``claims``, its "vs" claims, then its "matched" ones; ``signs``, per scene how many seeds
    put it above the reference (`holm_line`); and what its Summary line marks (`_row_summary`): ``primaries``,
    its primary-metric claims, ``briefs``, each one's text in brief, ``moving``, ``scene: why`` where not
    settled, ``opposed``, the quality metrics that go the other way in brief, ``across`` (`across_scenes`)
    and ``sized``, its remark on model size (`_matched_text`)."""

    row: Row
    line: str
    more: str
    claims: tuple[Claim, ...]
    signs: tuple[str, ...]
    primaries: tuple[Claim, ...]
    briefs: tuple[str, ...]
    moving: tuple[str, ...]
    opposed: tuple[str, ...]
    across: Across | None
    sized: _MatchedText


def _row_against(ax: _Axis, ref: Row, row: Row) -> _RowAgainst:
    """``row`` against ``ref`` in each of the kind's comparisons, per scene: the primary metric's in the
    findings' line with its marks (not settled, the other way, across scenes, model size, also changed), the
    others, the curve along the run, the confounds and the sizes in its appendix line."""
    primary, scenes = ax.primary, ax.scenes
    parts, rest = [], []  # the primary comparison's texts (the line's), the other comparisons' (the appendix's)
    claims, signs, primaries, briefs, moving = [], [], [], [], []
    for comp in ax.rules.comparisons:
        texts = []
        for scene in scenes:
            vs = _vs_at(ax, scene, ref, row, comp)
            if vs is None:
                texts.append("–")
                continue
            if vs.sign is not None:
                signs.append(vs.sign)
            if vs.why:
                moving.append(f"{scene}: {vs.why}")
            claims.append(vs.claim)
            if comp.metric == primary.name:
                primaries.append(vs.claim)
                briefs.append(vs.brief)
            texts.append(vs.claim.text)
        (parts if comp.metric == primary.name else rest).append(f"{_name(ax.specs[comp.metric])} {' / '.join(texts)}")
    line = f"  - `{row.label}`: " + "; ".join(parts)
    more = ["; ".join(rest)] if rest else []
    along = _along_the_run(scenes, ref, row, ax.usable, ax.settling, primary) if ax.settling is not None else ""
    if along:
        more.append(along)
    if moving:
        line += f". **Not settled** ({'; '.join(moving)})"
    also = confounds(scenes, ref, row, ax.usable, ax.kind)
    if also:
        more.append(f"Also changed: {also}")
    opposed, opposed_short = _the_other_way(ax, ref, row, primaries)
    if opposed:
        line += f". **The other way** (against the {_name(primary)} difference, significantly): " + "; ".join(opposed)
    across = across_scenes(primaries, scenes, ax.primary_null, ax.primary, ax.primary_comp.min_effect)
    if across is not None:
        line += f". {across.text}{across.over}"
    size = ax.size_line(ref, row)
    if size:
        more.append(size)
    sized = _matched_text(ax, ref, row) if ax.size_spec is not None else _MatchedText()
    line += sized.text
    if also:
        line += f". Also changed: other settings too (what, in \"Appendix: {ax.table.axis} in full\")"
    return _RowAgainst(row, line, f"  - `{row.label}`: " + ". ".join(more) if more else "",
                       (*claims, *sized.claims), tuple(signs), tuple(primaries), tuple(briefs), tuple(moving),
                       tuple(opposed_short), across, sized)


def _the_other_way(ax: _Axis, ref: Row, row: Row, primaries: Sequence[Claim]) -> tuple[list[str], list[str]]:
    """Per scene where ``row``'s primary difference is significant, the quality metrics that go significantly
    the other way (`other_way`): (in full, ``glossy: SSIM −0.010 [95 % CI …]``; in brief, ``SSIM on glossy``)."""
    opposed, opposed_short = [], []
    for c in primaries:
        if c.significant:
            against = other_way(ax.primary, c.value - ax.primary_null, ax.quality_intervals(c.scene, ref, row))
            if against:
                opposed.append(f"{c.scene}: {'; '.join(t for _, t in against)}")
                opposed_short.append(f"{' and '.join(n for n, _ in against)} on {c.scene}")
    return opposed, opposed_short


@dataclasses.dataclass(frozen=True)
class _Holm:
    """Holm's correction over an axis's primary comparisons (`_holm`): ``family``, the claims it covers (empty:
    nothing to correct, one comparison or none significant alone); ``lost``, (scene, label) of those
    significant alone but not after it; ``claim``, its "holm" claim (None where the family is empty)."""

    family: list[Claim]
    lost: set[tuple[str, str]]
    claim: Claim | None


def _holm(ax: _Axis, ref: Row, claims: Sequence[Claim], signs: Mapping[str, Sequence[str]]) -> _Holm:
    """Holm's step-down correction (family-wise 5 %) over the primary "vs" claims against ``ref`` printed with
    an interval, each one's p-value from its own t interval (`t_p_value`); its line is `holm_line`'s."""
    primary, comp = ax.primary, ax.primary_comp
    method = {"diff": "paired t", "ratio": "paired t on log ratios"}.get(comp.how, "t")
    family = [c for c in claims if c.kind == "vs" and c.reference == ref.label and c.metric == primary.name
              and _with_interval(c, ax.specs)]
    p = [t_p_value(Interval(c.value, c.low, c.high, c.n, method), ax.primary_null) for c in family]
    kept = holm(p)
    lost = {(c.scene, c.label) for c, k in zip(family, kept) if c.significant and not k}
    if len(family) < 2 or not any(c.significant for c in family):
        return _Holm([], lost, None)
    line = holm_line(family, p, kept, _name(primary), ref.label, ax.scenes, signs)
    return _Holm(family, lost, Claim("holm", "", "", primary.name, "count", float(sum(kept)), line, ref.label,
                                     n=len(family)))


def _row_summary(ax: _Axis, ref: Row, r: _RowAgainst, lost: set[tuple[str, str]]) -> str:
    """The Summary's line of one row against ``ref``: its primary difference per scene (``lost``: those no
    longer significant after Holm's correction) with the marks its findings line gives it, in brief."""
    primary = ax.primary
    marks = []
    if r.moving:
        marks.append("**not settled** on " + ", ".join(m.split(":")[0] for m in r.moving))
    if r.opposed:
        marks.append(f"**the other way** (against the {_name(primary)} difference): " + "; ".join(r.opposed))
    if r.across is not None:
        short = sum((c.scene, c.label) in lost for c in r.primaries)  # across scenes per comparison only
        marks.append(r.across.text + (f" (each per comparison; {len(r.primaries) - short} of {len(r.primaries)} "
                                      f"significant after Holm)" if short and r.across.everywhere else "")
                     + r.across.over)
    if r.sized.heads:
        at_size = r.sized.at_size
        marks.append("**against model size**: " + _sizes_in_brief(r.sized.heads)
                     + "".join(f"; at a matched size ({named}): "
                               + "; ".join(m.text for m in at_size if m.matched == named)
                               + _over_matched([m for m in at_size if m.matched == named], ax)
                               for named in dict.fromkeys(m.matched for m in at_size)))
    said = "; ".join(f"{c.scene} {brief}" + (", not significant after Holm" if (c.scene, c.label) in lost else "")
                     for c, brief in zip(r.primaries, r.briefs))
    return (f"- **`{r.row.label}`** against `{ref.label}`, {_name(primary)}: {said}"
            + "".join(f"; {m}" for m in marks) + ".")


def _against_reference(ax: _Axis, ref: Row, others: Sequence[Row]) -> tuple[_Part, list[Claim]]:
    """Every row of ``others`` against the reference ``ref`` (`_row_against`), Holm's correction over their
    primary comparisons (`_holm`) and each row's Summary line: (the block, Holm's family; empty where Holm
    has nothing to correct)."""
    scenes = " / ".join(ax.scenes)
    rows = [_row_against(ax, ref, row) for row in others]
    signs: dict[str, list[str]] = {}  # row -> per scene "seeds above the reference/pairs"
    for r in rows:
        if r.signs:
            signs.setdefault(r.row.label, []).extend(r.signs)
    claims = [c for r in rows for c in r.claims]
    corrected = _holm(ax, ref, claims, signs)
    lines = [f"- **Against `{ref.label}`**, paired over seeds ({scenes}):", *(r.line for r in rows)]
    if corrected.claim is not None:
        lines.append(f"- {corrected.claim.text}.")
        claims.append(corrected.claim)
    more = [r.more for r in rows if r.more]
    appendix = [f"- **Against `{ref.label}`**, paired over seeds ({scenes}), the other comparisons:", *more] \
        if more else []  # no row compared anything else: no head either
    summary = [_row_summary(ax, ref, r, corrected.lost) for r in rows if r.primaries]
    return _Part(tuple(lines), tuple(claims), tuple(appendix), tuple(summary)), corrected.family


# The lines after the comparisons

def _matched_cells_part(ax: _Axis) -> _Part:
    """Where the matched setting is this table's axis with two or more values, its cells compared with each
    other (``- **At a matched size** …``), each claimed "matched" unless it did not end at one size. The
    reference is the first matched cell; where several extra cells set its axis value (at disjoint
    ``scenes``), each scene's is the one run there, compared with the other cells run there."""
    dim, values = ax.matched
    size, primary, comp, table = ax.size_spec, ax.primary, ax.primary_comp, ax.table
    if size is None or dim != table.axis or len(values) < 2:
        return _Part()
    rows = [r for r in table.rows if any(same_value(r.value, v) for v in values)]
    spec = ax.experiment
    cells = spec.extra.get(dim, {}) if spec is not None else {}

    def sets(r: Row) -> tuple[str, str]:  # the axis value an extra cell sets; the row itself otherwise
        return ("value", repr(cells[r.value][dim])) if r.extra and dim in cells.get(r.value, {}) else ("row", r.label)

    def reference(scene: str) -> Row:  # the scene's cell of the first cell's value (the first where none runs)
        return next((r for r in rows if sets(r) == sets(rows[0]) and spec.extra_runs_at(dim, r.value, scene)),
                    rows[0]) if rows and rows[0].extra else rows[0]

    per_scene = len({sets(r) for r in rows}) < len(rows)  # some value has one cell per scene
    texts: dict[tuple[str, str], list[str]] = {}  # (row, its reference) -> each scene's difference
    claims = []
    for row in rows[1:]:
        if sets(row) == sets(rows[0]):  # another scene's reference
            continue
        for scene in ax.scenes:
            ref = reference(scene)
            iv, null = paired(ax.values(scene, ref, primary.name), ax.values(scene, row, primary.name), comp)
            if not iv.n:
                continue
            said = texts.setdefault((row.label, ref.label), [])
            text = fmt_interval(iv, comp.how, primary, null, comp.min_effect)
            ratio = paired_ratio(ax.size_values(scene, ref), ax.size_values(scene, row))
            at = f" at {ax.size_ratio_text(f'×{ratio.estimate:.3f}', scene, ref, row)}" if ratio.n else ""
            if ax.off_size(ratio):  # declared matched, ended apart: said, never claimed at one size
                said.append(f"{scene} {text}{at}: **not at one size** (a run that missed its count: see "
                            f"\"Warnings\")")
                continue
            claims.append(Claim("matched", scene, row.label, primary.name, comp.how, iv.estimate, text,
                                ref.label, iv.low, iv.high, iv.n,
                                *judge(iv, comp.how, null, primary, comp.min_effect)))
            why = ax.unsettled(scene, ref, row, iv.estimate - (null or 0.0))
            said.append(f"{scene} {text}{at}" + (f", **not settled** ({why})" if why else ""))
    parts = [f"`{label}` against `{ref}`: " + "; ".join(said) for (label, ref), said in texts.items()]
    head = (f"- **At a matched size** (`[report] matched`: {', '.join(f'`{r.label}`' for r in rows)} end at one "
            f"{'byte' if ax.by_bytes else _name(size)} count"
            f"{' at each scene, each value one cell there (their `scenes`)' if per_scene else ''}; "
            f"{setting_text(ax.experiment, dim, [r.value for r in rows])}): ")
    if parts:
        return _Part((head + ". ".join(parts) + ".",), tuple(claims))
    if rows:
        return _Part((head + "no done runs of these cells yet, so nothing is compared at a matched size.",))
    return _Part()


def _self_part(ax: _Axis, ref: Row) -> _Part:
    """The reference row against itself in each "mean" comparison with a null value (the defaults timed as
    both sides of each pair: the noise floor of a time ratio), claimed "self"."""
    parts, claims = [], []
    for comp in ax.rules.comparisons:
        if comp.how != "mean" or comp.null is None:
            continue
        spec = ax.specs[comp.metric]
        for scene in ax.scenes:
            iv = t_interval(list(ax.values(scene, ref, comp.metric).values()))
            if iv.n:
                text = fmt_interval(iv, "mean", spec, comp.null, comp.min_effect)
                significant, is_practical = judge(iv, "mean", comp.null, spec, comp.min_effect)
                claims.append(Claim("self", scene, ref.label, comp.metric, "mean", iv.estimate, text, ref.label,
                                    iv.low, iv.high, iv.n, significant, is_practical))
                parts.append(f"{scene} {text}")
    if not parts:
        return _Part()
    return _Part((f"- `{ref.label}` against itself (the same options timed as both sides of each pair; the "
                  f"noise floor of the ratio): " + "; ".join(parts) + ".",), tuple(claims))


def _count_part(ax: _Axis, claims: Sequence[Claim], family: Sequence[Claim], ref: Row) -> _Part:
    """How many comparisons the finding makes with a 95 % interval (the "count" claim and its appendix line):
    the leader's lead over the runner-up (and its size against it), each row against the reference, the
    matched-size ones, among ``claims``; ``family``: Holm's (named where not empty)."""
    primary, specs = ax.primary, ax.specs
    made = [c for c in claims if c.kind in ("best", "no best", "size", "vs", "matched") and c.reference and c.n]
    count = sum(1 for c in made if _with_interval(c, specs))
    if count:
        effects = [f"{_name(specs[c.metric])} {fmt_min_effect(c.min_effect, c.how, specs[c.metric])}"
                   for c in ax.rules.comparisons if c.min_effect is not None]
        rest = len(made) - count
        return _Part(claims=(Claim("count", "", "", "", "count", float(count), str(count)),), appendix=(
            f"- This table makes {count} comparisons with a 95 % interval (Student's t over seeds; no "
            f"correction for multiple comparisons, so about 1 in 20 intervals misses by chance"
            + (f", except Holm's over the {len(family)} {_name(primary)} ones against `{ref.label}`"
               if family else "") + ")"
            + (f"; {rest} more have none (one seed, or seeds that did not vary the result) and are no "
               f"evidence either way" if rest else "") + "."
            + (f" Minimum effects ({', '.join(effects)}): a difference reads \"no practical difference\" "
               f"only where its whole interval lies within ± its minimum effect, \"inconclusive\" where "
               f"the interval reaches beyond it while the difference is not significant or its estimate "
               f"is below it." if effects else ""),))
    if made:
        return _Part(claims=(Claim("count", "", "", "", "count", 0.0, "0"),), appendix=(
            f"- This table makes {len(made)} comparisons, but none has an interval (one seed per cell, "
            f"or seeds that did not vary the result): none of them is a significant difference; add "
            f"seeds to the grid.",))
    return _Part()


def _caveats_part(ax: _Axis, others: Sequence[Row]) -> _Part:
    """What the runs did not record or left out: the confound counts (where ``others`` are compared), the
    runs timed under load left out of every finding (a line) or of the timed comparisons, and the machine's
    load where it was not recorded."""
    declared, specs, timed = ax.declared, ax.specs, ax.timed
    lines, appendix = [], []
    if declared is not None and declared.confounds and others and not _recorded(ax.usable, declared):
        labels = ", ".join(ax.kind.specs[name].label for name in declared.confounds[:5])
        appendix.append("- What else each setting changed (" + labels
                        + ") was not recorded by these runs (run before it was); \"(planned)\" counts are what "
                          "their configs schedule; rerun the grid to see the rest.")
    if ax.excluded:
        lines.append(f"- {ax.excluded} run(s) timed while the load average exceeded half the cores are left out of "
                     f"these findings (marked in the table's `loaded` column).")
    timed_names = " / ".join(sorted(_name(specs[m]) for m in timed if m in specs))
    if timed & set(specs) and not load_recorded(ax.runs, ax.kind):
        appendix.append(f"- These runs did not record the machine's load (run before it was recorded): the "
                        f"{timed_names} comparisons may come from a loaded machine and are no evidence of speed.")
    if ax.untimed:
        appendix.append(f"- {ax.untimed} run(s) timed while other processes loaded the machine are left out of the "
                        f"{timed_names} comparisons (marked in the table's `timed under load` column; their "
                        f"quality metrics are kept).")
    return _Part(tuple(lines), appendix=tuple(appendix))


# A comparison's remark on model size

@dataclasses.dataclass(frozen=True)
class _AtSize:
    """One matched-size difference in brief, for the Summary (`_MatchedText.at_size`): ``matched``, what is
    matched (the pair of extra cells, or the matched setting); ``text``, ``fox +0.52 dB [95 % CI +0.20, +0.84]``."""

    matched: str
    text: str
    estimate: float | None = None  # the paired difference where both cells are done and at one size
    runs_here: bool = True  # False: the pair is not run at this scene (its `scenes`)
    own_pair: bool = False  # True: a pair of this scene's own (a matched size per scene), named in ``text``


@dataclasses.dataclass(frozen=True)
class _AtScene:
    """What the model-size remark says at one scene (`_matched_text`): ``piece``, its text; ``at_size``, the
    Summary's brief (None: none); ``claim``, the "matched" claim it makes (None: none)."""

    piece: str
    at_size: _AtSize | None = None
    claim: Claim | None = None


@dataclasses.dataclass(frozen=True)
class _MatchedText:
    """A row's remark on model size (`_matched_text`): ``text``, ``. **Against model size**: …`` ("" where
    none); ``heads``, each scene's size change, (scene, `size_shift`'s); ``at_size``, the matched-size
    differences in brief; ``claims``, the "matched" claims it makes."""

    text: str = ""
    heads: tuple[tuple[str, SizeShift], ...] = ()
    at_size: tuple[_AtSize, ...] = ()
    claims: tuple[Claim, ...] = ()


def _matched_text(ax: _Axis, a: Row, b: Row) -> _MatchedText:
    """Where ``b`` comes with `MATCHED_SHARE` more (or fewer) Gaussians than ``a`` at a scene, the same
    difference at the matched size (`[report] matched`), or that the grid has none (`_MatchedText`;
    empty for the matched axis's own rows: natural against matched, or two matched cells)."""
    dim, values = ax.matched
    own = dim == ax.table.axis  # the matched setting is this table's axis
    if own and (len(values) < 2 or all(any(same_value(r.value, v) for v in values) for r in (a, b))):
        return _MatchedText()
    pairs = {scene: _matched_pair(ax.experiment, ax.table, a, b, values, scene) for scene in ax.scenes} \
        if own else {}  # each scene's (`_matched_pair`: its own where the matched cells have `scenes`)
    natural = None if not ax.stratum or own else set(ax.usable.run_id) - ax.stratum  # the runs at their own size
    brief = _pair_brief(ax, pairs) if any(p is not None for p in pairs.values()) else None  # the Summary's
    heads, said = [], []
    for scene in ax.scenes:
        shift = size_shift(*(ax.selected(scene, r, ax.usable) for r in (a, b)), ax.size_spec, ax.bytes_of,
                           ax.by_bytes, natural)
        if shift is None:
            continue
        head = f"{scene}: {shift.text}"
        heads.append((scene, shift))
        if dim is None:
            said.append(_AtScene(head + "; the grid declares no matched-size cell, `[report] matched`: quality and "
                                        "size are not separated)"))
        elif pairs.get(scene) is not None:
            said.append(_at_matched_pair(ax, scene, head, pairs[scene], brief))
        elif own:
            said.append(_AtScene(head + f"; no matched-size cell of this comparison: the matched cells are "
                                        f"{', '.join(f'`{display(v)}`' for v in values)}, compared below)"))
        else:
            said.append(_at_matched_setting(ax, scene, head, a, b))
    if not said:
        return _MatchedText()
    return _MatchedText(". **Against model size**: " + "; ".join(s.piece for s in said), tuple(heads),
                        tuple(s.at_size for s in said if s.at_size is not None),
                        tuple(s.claim for s in said if s.claim is not None))


def _at_matched_pair(ax: _Axis, scene: str, head: str, pair: tuple[Row, Row],
                     brief: tuple[str, bool]) -> _AtScene:
    """``head`` (the size change at ``scene``) with the same comparison at one size through the two
    ``[extra]`` cells ``pair`` (`_matched_pair`; ``brief``, `_pair_brief` of every scene's): not run there, not yet done,
    not at one size, or the difference; never claimed (the pair is not in Holm's family). Where the scenes
    have pairs of their own (a matched size per scene), the Summary's brief names what every pair sets
    and each scene's text its pair, so the scenes read as one list."""
    spec, primary, comp = ax.experiment, ax.primary, ax.primary_comp
    iv, null = paired(ax.values(scene, pair[0], primary.name), ax.values(scene, pair[1], primary.name), comp)
    named = f"`{pair[1].label}` against `{pair[0].label}`"
    brief, own = brief
    where = f"{scene} ({named})" if own else scene
    if not iv.n:
        away = [r for r in pair if not spec.extra_runs_at(ax.table.axis, r.value, scene)]
        if away:
            return _AtScene(head + f"; its matched-size cells, {named}, are not run at {scene} (their `scenes`): "
                                   f"quality and size are not separated here)",
                            _AtSize(brief, f"{scene} not run (the pair's `scenes`)", runs_here=False, own_pair=own))
        return _AtScene(head + f"; its matched-size cells, {named}, have no done runs yet)")
    size = paired_ratio(ax.size_values(scene, pair[0]), ax.size_values(scene, pair[1]))
    at = ax.size_ratio_text(f"×{size.estimate:.3f}", scene, *pair) if size.n else "sizes not recorded"
    said = interval_text(iv, comp.how, primary, null, comp.min_effect)
    if ax.off_size(size):
        return _AtScene(head + f"; its matched-size cells, {named}, did not end at one size at {scene}: "
                               f"{_name(primary)} {said.text} at {at}, a run that missed its count (see "
                               f"\"Warnings\"): quality and size are not separated here)",
                        _AtSize(brief, f"{where} not at one size (×{size.estimate:.3f})", own_pair=own))
    why = ax.unsettled(scene, pair[0], pair[1], iv.estimate - (null or 0.0))
    return _AtScene(head + f" at its natural size); at a matched size ({named}): {_name(primary)} {said.text}, "
                           f"at {at}" + (f", **not settled** ({why})" if why else ""),
                    _AtSize(brief, f"{where} {said.short}" + (", not settled" if why else ""),
                            iv.estimate if comp.how == "diff" else None, own_pair=own))


def _pair_brief(ax: _Axis, pairs: Mapping[str, tuple[Row, Row] | None]) -> tuple[str, bool]:
    """The Summary's name of a matched-size comparison through ``pairs`` (every scene's; one at least),
    and whether the scenes have pairs of their own. One pair: it and the fields both its cells set alike
    (`` `3 at 140` against `0 at 590`, both also setting ...``). Pairs of their own: "each scene's own
    pair", the fields every pair's cells set alike to one value, and the others some pair's cells set
    alike named as set per scene."""
    spec, axis = ax.experiment, ax.table.axis
    distinct = list(dict.fromkeys(p for p in pairs.values() if p is not None))

    def alike(p: tuple[Row, Row]) -> dict[str, Any]:
        cells = [spec.extra.get(axis, {}).get(r.value, {}) for r in p]
        return {k: v for k, v in cells[0].items() if k not in (axis, "scenes") and cells[1].get(k, object()) == v}

    if len(distinct) == 1:
        pair = distinct[0]
        common = [f"`{k} = {display(v)}`" for k, v in alike(pair).items()]
        return (f"`{pair[1].label}` against `{pair[0].label}`" + (f", both also setting {', '.join(common)}" if common
                                                                  else "") + "; not in Holm's family"), False
    each = [alike(p) for p in distinct]
    keys = list(dict.fromkeys(k for e in each for k in e))
    shared = [f"`{k} = {display(each[0][k])}`" for k in keys if all(k in e and e[k] == each[0][k] for e in each)]
    varying = [f"`{k}`" for k in keys if not all(k in e and e[k] == each[0][k] for e in each)]
    return ("each scene's own pair" + (f", both cells also setting {', '.join(shared)}" if shared else "")
            + (f" and {', '.join(varying)} per scene" if varying else "") + "; not in Holm's family"), True


def _over_matched(at: Sequence[_AtSize], ax: _Axis) -> str:
    """`over_scenes` of a matched-size difference: where it was measured at one size on three scenes or
    more (every scene the pair runs at), the mean over them with its t interval; "" otherwise."""
    here = [m for m in at if m.runs_here]
    if any(m.estimate is None for m in here) or any(m.own_pair for m in at):
        return ""  # a pair per scene: each at its scene's own size, not one size over the scenes
    return over_values([m.estimate for m in here], ax.primary, ax.primary_null, ax.primary_comp.min_effect)


def _at_matched_setting(ax: _Axis, scene: str, head: str, a: Row, b: Row) -> _AtScene:
    """``head`` (the size change at ``scene``) with the same comparison over the runs at the matched setting
    of another axis (`_Axis.stratum`), claimed ("matched"); or that those runs are not done."""
    primary, comp, stratum = ax.primary, ax.primary_comp, ax.stratum
    iv, null = paired(ax.values_in(scene, a, primary.name, stratum), ax.values_in(scene, b, primary.name, stratum),
                      comp)
    if not iv.n:
        return _AtScene(head + "; its matched-size cells have no done runs)")
    size = paired_ratio(ax.size_values(scene, a, stratum), ax.size_values(scene, b, stratum))
    said = interval_text(iv, comp.how, primary, null, comp.min_effect)
    setting = setting_text(ax.experiment, ax.matched[0])
    claim = Claim("matched", scene, b.label, primary.name, comp.how, iv.estimate, said.text, a.label, iv.low,
                  iv.high, iv.n, *judge(iv, comp.how, null, primary, comp.min_effect))
    at = ax.size_ratio_text(f"×{size.estimate:.3f}", scene, a, b, stratum) if size.n else "sizes not recorded"
    return _AtScene(head + f" at its natural size); at the matched size ({setting}): {_name(primary)} {said.text}, "
                           f"at {at}", _AtSize(setting, f"{scene} {said.short}",
                                               iv.estimate if comp.how == "diff" else None), claim)


def _with_interval(c: Claim, specs: Mapping[str, MetricSpec]) -> bool:
    """Whether a comparison's claim was printed with a 95 % interval: two or more seeds, finite
    bounds, and a half-width that is not zero at the precision written (`no_spread`)."""
    if c.n < 2 or not (math.isfinite(c.low) and math.isfinite(c.high)):
        return False
    spec = specs.get(c.metric) or MetricSpec(c.metric, c.metric, ".3f", "", "lower")  # the bytes: a ratio
    return not no_spread(Interval(c.value, c.low, c.high, c.n, ""), c.how, spec)


def bytes_differ(runs: pd.DataFrame, bytes_of: Callable[[pd.DataFrame], pd.Series] | None, count: str) -> bool:
    """Whether the model size is judged by bytes (`KindReport.model_bytes`) rather than by the
    ``count`` metric (Gaussians): the runs' bytes per Gaussian differ (an SH-degree axis: 14 floats
    at degree 0, 59 at 3) and every run with a count has its bytes. Where they are one number, a
    bytes ratio is the count's ratio, so the count is named (docs/reports.md, "Best")."""
    col = f"metric.{count}"
    if bytes_of is None or col not in runs.columns or not len(runs):
        return False
    n = pd.to_numeric(runs[col], errors="coerce")
    per = (bytes_of(runs) / n)[n > 0]
    if not len(per) or not per.notna().all():
        return False
    return float(per.max() - per.min()) > 1e-9 * float(per.max())


#: Whose Pareto front a best's remark weighs (`_on_front`): the table's rows, or the grid's alone beside extra cells.
FRONT_OF = ("this table's", "the grid cells'")

#: A comparison whose size differs by at least this share is also stated at the matched size.
MATCHED_SHARE = 0.10


def _sizes(runs: pd.DataFrame, size: str, bytes_of: Callable[[pd.DataFrame], pd.Series] | None,
           by_bytes: bool) -> dict[int, float]:
    """seed -> the model size of ``runs``: its bytes where ``by_bytes`` (`bytes_differ`), else its
    ``size`` metric (a seed's runs averaged first)."""
    if not len(runs):
        return {}
    if by_bytes:
        per = pd.DataFrame({"seed": runs.seed.astype(int), "v": bytes_of(runs).to_numpy()}).dropna()
        return {int(k): float(v) for k, v in per.groupby("seed").v.mean().items()}
    return seed_values(runs, size) if f"metric.{size}" in runs.columns else {}


@dataclasses.dataclass(frozen=True)
class SizeShift:
    """A model-size change by the findings' rule (`size_shift`): ``ratio``, the paired geometric-mean ratio over
    seeds of the compared runs' size to the reference runs'; of their bytes where ``by_bytes`` (`bytes_differ`),
    else of the size metric named ``name`` (e.g. "Gaussians"); ``count``: where it is the bytes, the same
    ratio of the size metric (None: not known)."""

    ratio: float
    by_bytes: bool
    name: str
    count: float | None = None

    @property
    def measure(self) -> str:
        """``the bytes``, ``the Gaussians``."""
        return "the bytes" if self.by_bytes else f"the {self.name}"

    @property
    def rule(self) -> str:
        """``≥ 10 % more`` (`MATCHED_SHARE`; "larger" / "smaller" for bytes, "more" / "fewer" for a count)."""
        if self.by_bytes:
            more = "larger" if self.ratio > 1 else "smaller"
        else:
            more = "more" if self.ratio > 1 else "fewer"
        return f"≥ {100 * MATCHED_SHARE:g} % {more}"

    @property
    def text(self) -> str:
        """``×1.602 the Gaussians (≥ 10 % more`` or ``×3.999 the bytes (×0.949 the Gaussians) (≥ 10 % larger``
        (the caller closes the bracket)."""
        also = f" (×{self.count:.3f} the {self.name})" if self.by_bytes and self.count is not None else ""
        return f"×{self.ratio:.3f} {self.measure}{also} ({self.rule}"


def size_shift(a: pd.DataFrame, b: pd.DataFrame, size: MetricSpec,
               bytes_of: Callable[[pd.DataFrame], pd.Series] | None, by_bytes: bool, ids: set[str] | None = None
               ) -> SizeShift | None:
    """The model-size rule (docs/reports.md, "Model size"): where the runs ``b`` end at least
    `MATCHED_SHARE` larger or smaller than the runs ``a`` (paired geometric-mean ratio over seeds, of
    the bytes where ``by_bytes``, else of the ``size`` metric), that change (`SizeShift`); None
    otherwise. ``ids``: only these runs (None: all). The findings' comparisons and the check's
    verdict (`splatbench.reports.check`) both flag a size change through it."""
    if ids is not None:
        a, b = a[a.run_id.isin(ids)], b[b.run_id.isin(ids)]
    ratio = paired_ratio(_sizes(a, size.name, bytes_of, by_bytes), _sizes(b, size.name, bytes_of, by_bytes))
    if not ratio.n or not math.isfinite(ratio.estimate) or ratio.estimate <= 0 or \
            max(ratio.estimate, 1 / ratio.estimate) < 1 + MATCHED_SHARE - 1e-12:
        return None
    count = None
    if by_bytes:
        counted = paired_ratio(_sizes(a, size.name, None, False), _sizes(b, size.name, None, False))
        count = counted.estimate if counted.n and math.isfinite(counted.estimate) else None
    return SizeShift(ratio.estimate, by_bytes, _name(size), count)


def _stratum(runs: pd.DataFrame, dim: str | None, values: Sequence) -> set[str]:
    """The run ids of ``runs`` whose ``dim`` is one of ``values`` (`[report] matched`); empty without."""
    col = f"axis.{dim}"
    if dim is None or col not in runs.columns or not len(runs):
        return set()
    keep = [any(same_value(decode(v), w) for w in values) for v in runs[col]]
    return set(runs.run_id[keep])


def _matched_pair(spec: ExperimentSpec | None, table: AxisTable, a: Row, b: Row, values: Sequence,
                  scene: str | None = None) -> tuple[Row, Row] | None:
    """The two ``[extra.AXIS]`` cells among the matched ``values`` of a plain axis that set the axis to
    ``a``'s and ``b``'s values (``sh.degree = 0`` and ``3`` at one byte count, against the grid's
    `0` and `3`): the comparison ``b`` against ``a`` at a matched size; None where there are none.
    Where several set one value (at disjoint ``scenes``: `_parse_report`), the one run at ``scene``
    (the first where none is: the pair is then said not to run there)."""
    if spec is None or table.axis not in spec.axes:
        return None
    cells = spec.extra.get(table.axis, {})
    rows = [r for r in table.rows if r.extra and any(same_value(r.value, v) for v in values)]

    def twin(row: Row) -> Row | None:
        setting = [r for r in rows if table.axis in cells.get(r.value, {})
                   and same_value(cells[r.value][table.axis], row.value)]
        here = [r for r in setting if scene is None or spec.extra_runs_at(table.axis, r.value, scene)]
        return next(iter(here or setting), None)

    ta, tb = twin(a), twin(b)
    return (ta, tb) if ta is not None and tb is not None and ta is not tb else None


def setting_text(spec: ExperimentSpec | None, dim: str | None, values: Sequence | None = None) -> str:
    """What the matched setting sets: ```size = matched` sets `strategy.name = budget`, …`` (a variant's
    fields, or an extra cell's besides its axis; ```x = a` and `x = b` each set …`` where every value
    sets the same), ```loss.ssim_lambda = 0.2``` (a plain axis)."""
    if spec is None or dim is None:
        return ""
    values = list(values if values is not None else spec.matched.get(dim, ()))
    extra = spec.extra.get(dim, {})

    def fields(v) -> dict | None:  # what a variant value or an extra cell sets (None: a plain axis value)
        if isinstance(v, str) and v in extra:
            return {k: x for k, x in extra[v].items() if k != dim}  # the axis value is in its label
        return flatten(dict(spec.variants[dim][v])) if dim in spec.variants else None

    def sets(f: dict) -> str:
        return ", ".join(f"`{k} = {display(x)}`" for k, x in f.items())

    every = [fields(v) for v in values]
    if len(values) > 1 and every[0] and all(f == every[0] for f in every):  # said once: "each sets ..."
        names = [f"`{dim} = {display(v)}`" for v in values]
        return f"{', '.join(names[:-1])} and {names[-1]} each set {sets(every[0])}"
    return ("; " if dim in spec.variants or any(every) else ", ").join(
        f"`{dim} = {display(v)}`" + (" sets " + sets(f) if f else "") for v, f in zip(values, every))


@dataclasses.dataclass(frozen=True)
class Across:
    """Whether a primary difference holds across scenes (`across_scenes`): ``text`` as the findings write it;
    ``everywhere``: practical with one sign on every scene (``**Across scenes**``), else on some scenes only or
    with opposite signs (``**Per scene only**``)."""

    text: str
    everywhere: bool
    over: str = ""  # `over_scenes`' text, "" where there is none


def over_scenes(claims: Sequence[Claim], spec: MetricSpec, null: float, min_effect: float | None) -> str:
    """The mean of the per-scene mean differences with its 95 % t interval over the scenes, the scenes as
    the sample (df = scenes - 1): ``; over the scenes, taken as a random sample of scenes (df 3; not in
    Holm's family), +1.01 dB [95 % CI +0.26, +1.76]``. It covers what another scene like these would
    give, which the per-scene intervals, over seeds, do not; "" for fewer than three scenes (df 1 gives
    a t quantile of 12.7: no interval worth printing) or for a ratio (its per-scene values are
    geometric means): `over_values`."""
    if any(c.how != "diff" for c in claims):
        return ""
    return over_values([c.value for c in claims], spec, null, min_effect)


def over_values(values: Sequence[float], spec: MetricSpec, null: float, min_effect: float | None) -> str:
    """`over_scenes`' text of per-scene mean differences ``values`` (one per scene); "" for fewer than three,
    any not finite, or the same on every scene."""
    if len(values) < 3 or not all(math.isfinite(v) for v in values):
        return ""
    iv = t_interval(values, method="t")
    if no_spread(iv, "diff", spec):  # the same on every scene: the per-scene numbers say it all
        return ""
    return (f"; over the scenes, taken as a random sample of scenes (df {len(values) - 1}; not in Holm's family), "
            f"{interval_text(iv, 'diff', spec, null, min_effect).short}")


def across_scenes(claims: Sequence[Claim], scenes: Sequence[str], null: float = 0.0,
                  spec: MetricSpec | None = None, min_effect: float | None = None) -> Across | None:
    """Whether a primary difference holds across scenes: ``**Across scenes**`` where it is practical
    with one sign on every scene (two or more); where it is practical on some scenes only, or its sign
    differs, ``**Per scene only**`` naming them (the sign against ``null``, the comparison's no
    difference); None with one scene, or nowhere practical. With ``spec``, ``over`` gives the
    difference over the scenes as the sample (`over_scenes`)."""
    if len(scenes) < 2 or not claims:
        return None
    practical_ = [c for c in claims if c.practical]
    if not practical_:
        return None
    over = over_scenes(claims, spec, null, min_effect) if spec is not None else ""
    signs = {c.value > null for c in practical_}
    if len(practical_) == len(scenes) and len(signs) == 1:
        return Across(f"**Across scenes**: practical and of one sign on all {len(scenes)} scenes", True, over)
    on = ", ".join(f"{c.scene} {'+' if c.value > null else '−'}" for c in practical_)
    return Across(f"**Per scene only** (not practical with one sign on every scene: practical on {len(practical_)} of "
                  f"{len(scenes)} scenes"
                  + (", with opposite signs" if len(signs) > 1 else "") + f": {on})", False, over)


def _along_the_run(scenes: Sequence[str], ref: Row, row: Row, runs: pd.DataFrame, keys: SettlingCurves,
                   primary: MetricSpec) -> str:
    """The paired difference of ``row`` against ``ref`` at every evaluation step of the kind's test
    curve (`splatbench.reports.settling.paired_curve`), per scene, when the curve measures the
    primary metric and has more than one step: ``Paired difference at each evaluation (glossy,
    steps 500 / 1,000 / 1,500 / 2,000): +0.21, +0.36, +0.44, +0.47 dB``; "" otherwise."""
    if keys.metric != primary.name:
        return ""
    parts = []
    for scene in scenes:
        sel_a = runs[(runs.scene == scene) & runs.run_id.isin(ref.run_ids)]
        sel_b = runs[(runs.scene == scene) & runs.run_id.isin(row.run_ids)]
        points = paired_curve(sel_a, sel_b, keys)
        if len(points) < 2:
            continue
        steps = " / ".join(f"{s:,}" for s, _ in points)
        diffs = ", ".join(f"{d:+{primary.fmt}}" for _, d in points)
        parts.append(f"{scene}, steps {steps}: {diffs}" + (f" {primary.unit}" if primary.unit else ""))
    return ("Paired difference at each evaluation (mean over seeds; " + "; ".join(parts) + ")") if parts else ""


def _on_front(table: AxisTable, scene: str, size: MetricSpec, quality: MetricSpec, rows: Sequence[Row],
              sizes: Mapping[str, float | None] | None = None, among: Sequence[str] | None = None) -> bool:
    """Whether every one of ``rows`` is on the Pareto front of ``table``'s rows at ``scene`` on the
    means (no other row both smaller in ``size`` and better in ``quality``; `splatbench.plotting`)
    while some row is not: where every row is on the front, saying so tells nothing. ``sizes``:
    label -> the row's mean size to use instead of ``size``'s column (its bytes; None: unknown);
    ``among``: the labels of the rows to weigh (None: all; the findings leave extra cells out)."""
    at = table.frame[table.frame.scene == scene]
    if among is not None:
        at = at[at.label.isin(among)]
    sign = -1.0 if quality.better == "lower" else 1.0
    cost = list(at[f"{size.name}.mean"]) if sizes is None else \
        [math.nan if sizes.get(label) is None else sizes[label] for label in at.label]
    front = pareto_front(cost, [sign * q for q in at[f"{quality.name}.mean"]])
    labels = {at.iloc[i].label for i in front}
    return all(r.label in labels for r in rows) and len(labels) < len(set(at.label))


def load_recorded(runs: pd.DataFrame, kind: RunKind) -> bool:
    """Whether the runs recorded the machine's load: the kind's load mark (`KindReport.load`) is a
    column of ``runs`` (a table of grids run before it was recorded has none)."""
    load = kind.report.load if kind.report is not None else None
    return load is not None and f"metric.{load.flag}" in runs.columns


def _recorded(runs: pd.DataFrame, declared) -> bool:
    """Whether the runs recorded the kind's confound counts (a table from before has no such columns)."""
    cols = [f"metric.{name}" for name in declared.confounds]
    return any(c in runs.columns and pd.to_numeric(runs[c], errors="coerce").notna().any() for c in cols)


def confounds(scenes: Sequence[str], ref: Row, row: Row, runs: pd.DataFrame, kind: RunKind) -> str:
    """What else ``row`` changed against ``ref`` (the kind's confound counts, mean over seeds,
    per scene): each count that differs by more than `CONFOUND_SHARE` of the larger and is not
    below its floor on both sides (`KindReport.confound_floor`), e.g.
    ``textured: opacity resets 7 instead of 4``; "" when none differs. Runs that did not record
    a count (grids run before it was) give the count their config schedules, where the kind
    can say it (`RunKind.planned`), written "(planned)"."""
    declared = kind.report
    if declared is None or not declared.confounds:
        return ""
    plan = _planner(kind)
    floors = dict(declared.confound_floor)
    parts = []
    for scene in scenes:
        moved = []
        for m in (kind.specs[name] for name in declared.confounds):
            sel_a = runs[(runs.scene == scene) & runs.run_id.isin(ref.run_ids)]
            sel_b = runs[(runs.scene == scene) & runs.run_id.isin(row.run_ids)]
            col = f"metric.{m.name}"
            a = seed_values(sel_a, m.name) if col in runs.columns else {}
            b = seed_values(sel_b, m.name) if col in runs.columns else {}
            how = ""
            if not a and not b and plan is not None:
                a, b, how = plan(sel_a, m.name), plan(sel_b, m.name), " (planned)"
            if not a or not b:
                continue
            ma, mb = sum(a.values()) / len(a), sum(b.values()) / len(b)
            if m.name in floors and max(abs(ma), abs(mb)) < floors[m.name]:
                continue  # too few on both sides to change the model (`KindReport.confound_floor`)
            if abs(mb - ma) > CONFOUND_SHARE * max(abs(ma), abs(mb)):
                moved.append(f"{m.label} {_count(mb)} instead of {_count(ma)}{how}")
        if moved:
            parts.append(f"{scene}: " + ", ".join(moved))
    return "; ".join(parts) + (" (mean over seeds)" if parts else "")


def _planner(kind: RunKind) -> Callable[[pd.DataFrame, str], dict[int, float]] | None:
    """``plan(runs, metric) -> seed -> count`` from each run's recorded config through the kind's
    `RunKind.planned`; None for a kind without one."""
    planned = kind.planned
    if planned is None:
        return None

    def plan(runs: pd.DataFrame, metric: str) -> dict[int, float]:
        out: dict[int, list[float]] = {}
        for _, r in runs.iterrows():
            value = planned(run_config(r)).get(metric)
            if value is not None:
                out.setdefault(int(r.seed), []).append(float(value))
        return {k: sum(v) / len(v) for k, v in out.items()}

    return plan


#: A confound count is named when the row's mean differs from the reference's by more than this share.
CONFOUND_SHARE = 0.05


def holm_line(family: Sequence[Claim], p: Sequence[float], kept: Sequence[bool], name: str, reference: str,
              scenes: Sequence[str], signs: Mapping[str, Sequence[str]]) -> str:
    """The findings' line of Holm's correction (`splatbench.metrics.stats.holm`, family-wise 5 %) over
    ``family``, an axis's primary "vs" claims with an interval, ``p`` their p-values (`t_p_value` of each
    claim's own interval) and ``kept`` Holm's verdicts: how many of those significant alone remain, which
    (with p), the first the step-down kept out and its threshold; then per row and scene how many seeds
    put the row above ``reference`` (``signs``: "k/n" per scene, in ``scenes`` order, where every scene has
    one)."""
    alone = sum(1 for c in family if c.significant)
    names = [f"{c.scene} `{c.label}` ({_p(q)})" for c, q, k in sorted(zip(family, p, kept), key=lambda x: x[1])
             if k]
    line = (f"**Holm's correction** over the {len(family)} {name} comparisons of this axis (family-wise 5 %): "
            + (f"the one significant alone {'remains' if sum(kept) else 'does not remain'} significant" if alone == 1
               else f"{sum(kept)} of the {alone} significant alone {'remains' if sum(kept) == 1 else 'remain'} "
                    f"significant")
            + (f": {', '.join(names)}" if names else ""))
    order = sorted(range(len(family)), key=lambda i: p[i])
    first = next((i for i in order if not kept[i]), None)
    if first is not None:
        line += "; the others' intervals are per comparison"
    if first is not None and family[first].significant:
        c, step = family[first], len(family) - order.index(first)
        line += f" (the first kept out: {c.scene} `{c.label}`, {_p(p[first])} > 0.05/{step})"
    whole = {label: s for label, s in signs.items() if len(s) == len(scenes)}
    if whole:
        line += (f". Seeds with the row above `{reference}` ({' / '.join(scenes)}): "
                 + "; ".join(f"`{label}` {', '.join(s)}" for label, s in whole.items()))
    return line


def _p(p: float) -> str:
    """``p = 0.011``, ``p < 0.001``."""
    return "p < 0.001" if p < 0.001 else f"p = {p:.3f}"


def _sizes_in_brief(heads: Sequence[tuple[str, SizeShift]]) -> str:
    """The model-size changes of `size_shift` per scene, in brief: ``fox ×3.998, glossy ×4.054 the bytes
    (≥ 10 % larger)`` where every scene's is of the same kind, else each in full."""
    if len({(s.measure, s.rule) for _, s in heads}) == 1:
        shift = heads[0][1]
        return ", ".join(f"{scene} ×{s.ratio:.3f}" for scene, s in heads) + f" {shift.measure} ({shift.rule})"
    return "; ".join(f"{scene} ×{s.ratio:.3f} {s.measure} ({s.rule})" for scene, s in heads)


def _count(value: float) -> str:
    return f"{value:,.0f}" if abs(value - round(value)) < 1e-9 or abs(value) >= 100 else f"{value:,.1f}"


def _name(spec: MetricSpec) -> str:
    """A metric's label without its unit: "test PSNR (dB)" -> "test PSNR"."""
    return spec.label.split(" (")[0]


__all__ = ["Claim", "Finding", "AxisNote", "axis_finding", "load_recorded", "rules_for", "fmt_number", "fmt_interval",
           "interval_text", "IntervalText", "paired",
           "reference_row", "usable_runs", "no_spread", "practical", "reading", "READINGS", "bounded", "size_shift", "bytes_differ", "MATCHED_SHARE", "judge", "fmt_min_effect", "confounds",
           "SizeShift", "CONFOUND_SHARE"]
