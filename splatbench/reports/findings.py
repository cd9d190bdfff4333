"""Findings: short statements written from an axis table's numbers, never by hand.

Each finding is a list of `Claim` records (a number, where it comes from and how it
is written); the text is rendered from the claims, so a test can recompute every
number from ``results.parquet`` and find its text in the report. Per axis:

* **best**: per scene, the row with the best mean of the kind's primary metric;
* **vs**: every other row against the reference row (the one-at-a-time base, else the
  axis's first value), per scene, for each of the kind's comparisons
  (``diff``: b - a; ``ratio``: b / a; ``percent``: 100 (b / a - 1); ``mean``: b itself);
* **noise**: the largest seed-to-seed standard deviation of the primary metric in
  the table (differences smaller than it are within noise);
* **auto** (train kind, SH degree axis): the degree ``auto`` ended at, per seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pandas as pd

from splatbench.reports.tables import AxisTable, MetricSpec, Row, display, done_runs


@dataclass(frozen=True)
class Comparison:
    """How one metric of a row is set against the reference row."""

    metric: str
    how: str  # "diff", "ratio", "percent" or "mean" (module doc)


@dataclass(frozen=True)
class FindingRules:
    """A kind's primary metric (best-of) and its comparisons."""

    primary: str
    comparisons: tuple[Comparison, ...]


KIND_RULES: dict[str, FindingRules] = {
    "train": FindingRules("test_psnr", (Comparison("test_psnr", "diff"), Comparison("train_seconds", "ratio"),
                                        Comparison("num_gaussians", "ratio"))),
    "raster": FindingRules("fwd_bwd_rel", (Comparison("fwd_bwd_rel", "mean"), Comparison("error_psnr", "mean"))),
}


def rules_for(kind: str, metrics: tuple[MetricSpec, ...]) -> FindingRules | None:
    """The kind's rules, restricted to metrics present; another kind compares its first metric."""
    names = {m.name for m in metrics}
    if kind in KIND_RULES:
        r = KIND_RULES[kind]
        if r.primary not in names:
            return None
        return FindingRules(r.primary, tuple(c for c in r.comparisons if c.metric in names))
    if not metrics:
        return None
    return FindingRules(metrics[0].name, (Comparison(metrics[0].name, "diff"),))


@dataclass(frozen=True)
class Claim:
    """One number of a finding.

    kind: "best", "vs", "noise", "auto" or "parity"; scene ("" for all); label: the
    row; reference: the row compared against ("vs"); metric; how: "mean", "diff",
    "ratio", "percent", "std" or "max"; value: the number; text: how it is written.
    """

    kind: str
    scene: str
    label: str
    metric: str
    how: str
    value: float
    text: str
    reference: str = ""


@dataclass
class Finding:
    """The finding of one axis: markdown lines and the claims they state."""

    axis: str
    lines: list[str]
    claims: list[Claim]

    def markdown(self) -> str:
        return "\n".join(self.lines)


def fmt_number(value: float, how: str, spec: MetricSpec) -> str:
    """A claim's number as written: ``+0.42 dB``, ``×1.31``, ``-12%``, ``27.50 dB``."""
    if value is None or not math.isfinite(value):
        return "n/a"
    unit = f" {spec.unit}" if spec.unit else ""
    if how == "diff":
        return f"{value:+{spec.fmt}}{unit}"
    if how == "ratio":
        return f"×{value:.2f}"
    if how == "percent":
        return f"{value:+.0f}%"
    return f"{format(value, spec.fmt)}{unit}"


def compare(a: float, b: float, how: str) -> float:
    """Row ``b`` against reference ``a`` (module doc)."""
    if how == "diff":
        return b - a
    if how == "ratio":
        return b / a if a else math.nan
    if how == "percent":
        return 100.0 * (b / a - 1.0) if a else math.nan
    return b


def reference_row(table: AxisTable) -> Row:
    """The one-at-a-time base row, else the first row."""
    return next((r for r in table.rows if r.is_base), table.rows[0])


def axis_finding(table: AxisTable, kind: str, runs: pd.DataFrame) -> Finding | None:
    """The finding of one axis (None when the kind has no rules or nothing is done)."""
    rules = rules_for(kind, table.metrics)
    if rules is None or table.frame.empty:
        return None
    specs = {m.name: m for m in table.metrics}
    primary = specs[rules.primary]
    sign = -1.0 if primary.better == "lower" else 1.0
    frame = table.frame
    scenes = list(dict.fromkeys(frame.scene))
    claims: list[Claim] = []
    lines: list[str] = []

    best_parts = []
    for scene in scenes:
        sub = frame[(frame.scene == scene) & (frame[f"{primary.name}.n"] > 0)]
        if sub.empty:
            continue
        best = sub.loc[(sign * sub[f"{primary.name}.mean"]).idxmax()]
        value = float(best[f"{primary.name}.mean"])
        text = fmt_number(value, "mean", primary)
        claims.append(Claim("best", scene, best.label, primary.name, "mean", value, text))
        best_parts.append(f"{scene} `{best.label}` ({text})")
    if not best_parts:
        return None
    word = "best" if primary.better != "lower" else "lowest"
    lines.append(f"- **{word.capitalize()} {_name(primary)}** per scene: " + ", ".join(best_parts) + ".")

    ref = reference_row(table)
    others = [r for r in table.rows if r.label != ref.label]
    if others and rules.comparisons:
        lines.append(f"- **Against `{ref.label}`** ({' / '.join(scenes)}):")
        for row in others:
            parts = []
            for comp in rules.comparisons:
                spec = specs[comp.metric]
                texts = []
                for scene in scenes:
                    a = table.stat(scene, ref.label, comp.metric)
                    b = table.stat(scene, row.label, comp.metric)
                    if a.n == 0 or b.n == 0:
                        texts.append("–")
                        continue
                    value = compare(a.mean, b.mean, comp.how)
                    text = fmt_number(value, comp.how, spec)
                    claims.append(Claim("vs", scene, row.label, comp.metric, comp.how, value, text, ref.label))
                    texts.append(text)
                parts.append(f"{_name(spec)} {' / '.join(texts)}")
            lines.append(f"  - `{row.label}`: " + "; ".join(parts))

    stds = frame[f"{primary.name}.std"].dropna()
    if len(stds):
        worst = float(stds.max())
        text = format(worst, primary.fmt) + (f" {primary.unit}" if primary.unit else "")
        claims.append(Claim("noise", "", "", primary.name, "std", worst, text))
        lines.append(f"- Seed-to-seed standard deviation of {_name(primary)} is up to {text} in this table; "
                     f"smaller differences are within noise.")

    elif int(frame[f"{primary.name}.n"].max()) == 1:
        lines.append("- One run per row: there is no seed-to-seed spread to judge these differences by.")

    if kind == "train" and table.axis == "sh_degree" and "metric.sh_degree" in runs.columns:
        auto = [r for r in table.rows if r.value == "auto"]
        if auto:
            parts = []
            done = done_runs(runs)
            for scene in scenes:
                sel = done[(done.scene == scene) & done.run_id.isin(auto[0].run_ids)]
                degrees = [int(d) for d in pd.to_numeric(sel["metric.sh_degree"], errors="coerce").dropna()]
                if not degrees:
                    continue
                mean = sum(degrees) / len(degrees)
                if len(set(degrees)) == 1:
                    text = f"{degrees[0]}"
                    where = "every seed" if len(degrees) > 1 else "one seed"
                else:
                    text = f"{min(degrees)}–{max(degrees)}"
                    where = "per seed: " + ", ".join(map(str, degrees))
                claims.append(Claim("auto", scene, auto[0].label, "sh_degree", "mean", mean, text))
                parts.append(f"{text} on {scene} ({where})")
            if parts:
                lines.append("- `auto` ended at SH degree " + ", ".join(parts) + ".")
    return Finding(table.axis, lines, claims)


def _name(spec: MetricSpec) -> str:
    """A metric's label without its unit: "test PSNR (dB)" -> "test PSNR"."""
    return spec.label.split(" (")[0]


def parity_finding(runs: pd.DataFrame) -> Finding | None:
    """Raster kind: the largest implementation error against the matched reference."""
    col = "metric.parity_max_abs"
    done = done_runs(runs)
    if col not in done.columns or done[col].dropna().empty:
        return None
    worst = float(pd.to_numeric(done[col]).max())
    text = f"{worst:.1e}"
    claim = Claim("parity", "", "", "parity_max_abs", "max", worst, text)
    return Finding("parity", [f"- Against the float64 reference with the *same* options, the largest difference "
                              f"over all {len(done)} runs is {text} (float32 rounding; the error columns above "
                              f"are what each option trades in against the default-option ground truth)."],
                   [claim])


__all__ = ["Comparison", "FindingRules", "KIND_RULES", "Claim", "Finding", "axis_finding", "parity_finding",
           "fmt_number", "compare", "reference_row", "display"]
