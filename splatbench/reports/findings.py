"""Findings: short statements written from an axis table's numbers, never by hand.

Each finding is a list of `Claim` records (a number, its 95 % interval, where it comes
from and how it is written); the text is rendered from the claims, so a test can
recompute every number from ``results.parquet`` and find its text in the report. Per
axis:

* **best**: per scene, the row with the best mean of the kind's primary metric;
* **vs**: every other row against the reference row (the one-at-a-time base, else the
  axis's first value), per scene, for each of the kind's comparisons, **paired over
  seeds** (`splatbench.metrics.stats`): ``diff`` is the mean of ``b_s - a_s`` with
  its t interval, ``ratio`` the geometric mean of ``b_s / a_s`` with its interval;
  ``mean`` is the row's own mean (for a metric that is already relative to the base,
  like the raster kind's time ratio) with its t interval. When the interval contains
  the null value (0 for a difference, 1 for a ratio or a relative metric) the text
  says "no significant difference"; with one seed it says no interval can be computed;
* **count**: how many such comparisons the table makes (each at 95 %, no correction
  for multiplicity);
* kind-specific notes appended to it (`splatbench.reports.notes`, registered by kind
  name), e.g. the degree ``auto`` ended at on the train kind's SH degree axis.

Runs whose ``metric.loaded`` is 1 (the raster kind: timed while the load average
exceeded half the cores) are left out of every finding (not of the tables). Runs whose
``metric.time_loaded`` is 1 (the train kind) are left out of the comparisons of the
kind's ``timed`` metrics only: their quality metrics do not depend on the load.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import pandas as pd

from splatbench.experiments.kind_report import Comparison, FindingRules
from splatbench.metrics.spec import MetricSpec
from splatbench.metrics.stats import Interval, paired_difference, paired_ratio, t_interval
from splatbench.reports.tables import AxisTable, Row, done_runs, kind_report, seed_values


def rules_for(kind: str, metrics: tuple[MetricSpec, ...]) -> FindingRules | None:
    """The kind's rules, restricted to metrics present; another kind compares its first metric."""
    names = {m.name for m in metrics}
    declared = kind_report(kind)
    if declared is not None:
        r = declared.rules
        if r is None:
            return None
        if r.primary not in names:
            return None
        return FindingRules(r.primary, tuple(c for c in r.comparisons if c.metric in names))
    if not metrics:
        return None
    return FindingRules(metrics[0].name, (Comparison(metrics[0].name, "diff"),))


@dataclass(frozen=True)
class Claim:
    """One number of a finding.

    kind: "best", "vs", "self" (the reference row's own relative metric), "count", "auto" or
    "parity"; scene ("" for all); label: the
    row; reference: the row compared against ("vs"); metric; how: "mean", "diff",
    "ratio", "count" or "max"; value: the number; low / high: its 95 % interval (NaN
    when none); n: seeds (pairs) it comes from; significant: the interval excludes the
    null value (False when there is no interval); text: how it is written.
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


@dataclass
class Finding:
    """The finding of one axis: markdown lines and the claims they state."""

    axis: str
    lines: list[str]
    claims: list[Claim]

    def markdown(self) -> str:
        return "\n".join(self.lines)


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


def fmt_interval(iv: Interval, how: str, spec: MetricSpec, null: float | None) -> str:
    """``+0.42 dB [95 % CI +0.10, +0.74]``, with ", no significant difference" when the
    interval contains ``null``, or ``(1 seed: no interval)``."""
    text = fmt_number(iv.estimate, how, spec)
    if not iv.defined:
        return f"{text} ({iv.n} seed{'s' if iv.n != 1 else ''}: no interval)"
    text += f" [95 % CI {_bound(iv.low, how, spec)}, {_bound(iv.high, how, spec)}]"
    if null is not None and not iv.excludes(null):
        text += ", no significant difference"
    return text


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


def usable_runs(runs: pd.DataFrame) -> pd.DataFrame:
    """The done runs findings may use: not those marked ``metric.loaded`` (module doc)."""
    done = done_runs(runs)
    if "metric.loaded" in done.columns:
        done = done[pd.to_numeric(done["metric.loaded"], errors="coerce").fillna(0) == 0]
    return done


#: A kind-specific note on one axis: ``note(axis_table, runs, scenes) -> (lines, claims)``.
AxisNote = Callable[[AxisTable, pd.DataFrame, list[str]], tuple[list[str], list["Claim"]]]


def axis_finding(table: AxisTable, kind: str, runs: pd.DataFrame, notes: Sequence[AxisNote] = ()) -> Finding | None:
    """The finding of one axis (None when the kind has no rules or nothing is done),
    with the lines and claims of ``notes`` appended."""
    rules = rules_for(kind, table.metrics)
    if rules is None or table.frame.empty:
        return None
    specs = {m.name: m for m in table.metrics}
    primary = specs[rules.primary]
    sign = -1.0 if primary.better == "lower" else 1.0
    scenes = list(dict.fromkeys(table.frame.scene))
    usable = usable_runs(runs)
    excluded = len(done_runs(runs)) - len(usable)
    declared = kind_report(kind)
    timed = set(declared.timed) if declared is not None else set()
    untimed = 0
    if timed and "metric.time_loaded" in usable.columns:
        loaded = pd.to_numeric(usable["metric.time_loaded"], errors="coerce").fillna(0) != 0
        untimed = int(loaded.sum())
        timed_usable = usable[~loaded]
    else:
        timed_usable = usable

    def values(scene: str, row: Row, metric: str) -> dict[int, float]:
        pool = timed_usable if metric in timed else usable
        sel = pool[(pool.scene == scene) & pool.run_id.isin(row.run_ids)]
        return seed_values(sel, metric) if len(sel) else {}

    claims: list[Claim] = []
    lines: list[str] = []
    best_parts = []
    for scene in scenes:
        means = [(t_interval(list(values(scene, row, primary.name).values())), row) for row in table.rows]
        means = [(iv, row) for iv, row in means if iv.n > 0]
        if not means:
            continue
        iv, row = max(means, key=lambda m: sign * m[0].estimate)
        text = fmt_number(iv.estimate, "mean", primary)
        claims.append(Claim("best", scene, row.label, primary.name, "mean", iv.estimate, text, n=iv.n))
        best_parts.append(f"{scene} `{row.label}` ({text})")
    if not best_parts:
        if excluded:
            return Finding(table.axis, [f"- No findings: all {excluded} done run(s) were timed while the load average "
                                        f"exceeded half the cores (the table's `loaded` column); rerun them on a "
                                        f"quiet machine (docs/reports.md, \"Quiet numbers\")."], [])
        return None
    word = "best" if primary.better != "lower" else "lowest"
    lines.append(f"- **{word.capitalize()} {_name(primary)}** per scene (mean over seeds): "
                 + ", ".join(best_parts) + ".")

    ref = reference_row(table)
    others = [r for r in table.rows if r.label != ref.label]
    count = 0
    if others and rules.comparisons:
        lines.append(f"- **Against `{ref.label}`**, paired over seeds ({' / '.join(scenes)}):")
        for row in others:
            parts = []
            for comp in rules.comparisons:
                spec = specs[comp.metric]
                texts = []
                for scene in scenes:
                    a, b = values(scene, ref, comp.metric), values(scene, row, comp.metric)
                    iv, null = paired(a, b, comp)
                    if iv.n == 0:
                        texts.append("–")
                        continue
                    text = fmt_interval(iv, comp.how, spec, null)
                    significant = null is not None and iv.excludes(null)
                    claims.append(Claim("vs", scene, row.label, comp.metric, comp.how, iv.estimate, text, ref.label,
                                        iv.low, iv.high, iv.n, significant))
                    texts.append(text)
                    count += 1
                parts.append(f"{_name(spec)} {' / '.join(texts)}")
            lines.append(f"  - `{row.label}`: " + "; ".join(parts))
    self_parts = []
    for comp in rules.comparisons:
        if comp.how != "mean" or comp.null is None:
            continue
        for scene in scenes:  # the reference row's own value: the defaults timed against themselves
            iv = t_interval(list(values(scene, ref, comp.metric).values()))
            if iv.n:
                text = fmt_interval(iv, "mean", specs[comp.metric], comp.null)
                claims.append(Claim("self", scene, ref.label, comp.metric, "mean", iv.estimate, text, ref.label,
                                    iv.low, iv.high, iv.n, iv.excludes(comp.null)))
                self_parts.append(f"{scene} {text}")
    if self_parts:
        lines.append(f"- `{ref.label}` against itself (the same options timed as both sides of each pair; the "
                     f"noise floor of the ratio): " + "; ".join(self_parts) + ".")
    if count:
        claims.append(Claim("count", "", "", "", "count", float(count), str(count)))
        seeds = max((c.n for c in claims if c.kind == "vs"), default=0)
        if seeds >= 2:
            lines.append(f"- This table makes {count} comparisons, each with its own 95 % interval (Student's t "
                         f"over seeds; no correction for multiple comparisons, so about 1 in 20 intervals misses "
                         f"by chance).")
        else:
            lines.append(f"- This table makes {count} comparisons, but with one seed per cell no interval can be "
                         f"computed (n = 1): none of them is a significant difference; add seeds to the grid.")
    if excluded:
        lines.append(f"- {excluded} run(s) timed while the load average exceeded half the cores are left out of "
                     f"these findings (marked in the table's `loaded` column).")
    if untimed:
        lines.append(f"- {untimed} run(s) timed while other processes loaded the machine are left out of the "
                     f"{' / '.join(sorted(_name(specs[m]) for m in timed if m in specs))} comparisons (marked in "
                     f"the table's `timed under load` column; their quality metrics are kept).")

    for note in notes:
        more_lines, more_claims = note(table, runs, scenes)
        lines += more_lines
        claims += more_claims
    return Finding(table.axis, lines, claims)


def _name(spec: MetricSpec) -> str:
    """A metric's label without its unit: "test PSNR (dB)" -> "test PSNR"."""
    return spec.label.split(" (")[0]


__all__ = ["Claim", "Finding", "AxisNote", "axis_finding", "rules_for", "fmt_number", "fmt_interval", "paired",
           "reference_row", "usable_runs"]
