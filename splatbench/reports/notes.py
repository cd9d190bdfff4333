"""Kind-specific findings, registered with the reports by kind name.

A run kind declares its report as plain data (`splatbench.experiments.kind_report`);
a finding that needs code of its own lives here and is looked up by the kind's name,
so the experiments never import the reports:

* axis notes (`register_axis_note`): ``note(axis_table, runs, scenes) -> (lines, claims)``
  appended to each axis finding of the kind (train: `auto_sh_degree_note`);
* run findings (`register_run_finding`): ``finding(runs) -> Finding | None`` over all
  runs of the kind (raster: `parity_finding`; train: `settling_finding`), each its own
  section of the report;
* metric notes (`register_metric_note`): ``note(runs) -> lines`` appended to the report's
  "Metrics" section (train: `lpips_note`, which LPIPS the column is).
"""

from __future__ import annotations

from collections.abc import Callable

import json

import pandas as pd

from splatbench.metrics.stats import paired_difference, t_interval
from splatbench.reports.findings import AxisNote, Claim, Finding
from splatbench.reports.tables import AxisTable, done_runs

#: A finding over all runs of a kind: ``finding(runs) -> Finding | None``.
RunFinding = Callable[[pd.DataFrame], "Finding | None"]


def auto_sh_degree_note(table: AxisTable, runs: pd.DataFrame, scenes: list[str]) -> tuple[list[str], list[Claim]]:
    """Train kind, ``sh_degree`` axis: the degree the ``auto`` rows ended at, per scene."""
    lines: list[str] = []
    claims: list[Claim] = []
    if table.axis != "sh_degree" or "metric.sh_degree" not in runs.columns:
        return lines, claims
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
    return lines, claims


def _cell_label(done: pd.DataFrame, axes: list[str]):
    """A row's cell as ``axis=value, ...``; in a one-at-a-time grid (every cell differs from the
    most common one in at most one axis, with more than one axis) only the axis that differs,
    or ``base``."""
    common = {c: done[c].mode().iloc[0] for c in axes}

    def moved(row) -> list[str]:
        return [c for c in axes if row[c] != common[c]]

    one_at_a_time = len(axes) > 1 and all(len(moved(row)) <= 1 for _, row in done.iterrows())
    if one_at_a_time:
        return lambda row: ", ".join(f"{c[5:]}={row[c]}" for c in moved(row)) or "base"
    return lambda row: ", ".join(f"{c[5:]}={row[c]}" for c in axes)


def settling_finding(runs: pd.DataFrame) -> Finding | None:
    """Train kind: whether the differences between a scene's cells had settled when the runs
    ended, from the curves' last evaluation interval (``eval_step`` / ``eval_psnr``).

    Each cell's test PSNR change over that interval is listed (mean over seeds). The
    differences are what a grid reports, so a scene is *not settled* when its fastest- and
    slowest-rising cells' gap moved over the interval (paired over seeds: the 95 % t interval
    of the change excludes 0) by more than the half-width of the 95 % interval of their final
    difference: the reported difference then is what this run length gives, not where the two
    converge (the report protocol asks for settled models; docs/reports.md)."""
    done = done_runs(runs)
    if done.empty or "curves" not in done.columns:
        return None
    axes = [c for c in done.columns if c.startswith("axis.")]
    label = _cell_label(done, axes)
    rise: dict[tuple, dict[int, float]] = {}
    final: dict[tuple, dict[int, float]] = {}
    steps: set[tuple[int, int]] = set()
    for _, row in done.iterrows():
        try:
            curves = json.loads(row["curves"]) if isinstance(row["curves"], str) else {}
        except ValueError:
            continue
        step, psnr = curves.get("eval_step") or [], curves.get("eval_psnr") or []
        if len(step) < 2 or len(psnr) != len(step) or None in psnr[-2:]:
            continue
        key = (row["scene"], label(row))
        rise.setdefault(key, {})[int(row["seed"])] = float(psnr[-1]) - float(psnr[-2])
        final.setdefault(key, {})[int(row["seed"])] = float(psnr[-1])
        steps.add((int(step[-2]), int(step[-1])))
    if not rise:
        return None
    parts = [f"{scene} `{label}` {t_interval(list(v.values())).estimate:+.2f} dB" for (scene, label), v in rise.items()]
    span = ", ".join(f"{a}→{b}" for a, b in sorted(steps))
    lines = [f"- Test PSNR change over the last evaluation interval (steps {span}), mean over seeds: "
             + "; ".join(parts) + "."]
    claims, moving = [], []
    for scene in dict.fromkeys(k[0] for k in rise):
        keys = sorted((k for k in rise if k[0] == scene), key=lambda k: t_interval(list(rise[k].values())).estimate)
        if len(keys) < 2:
            continue
        slow, fast = keys[0], keys[-1]
        change = paired_difference(rise[slow], rise[fast])  # how much `fast` gained on `slow` (> 0)
        gap = paired_difference(final[slow], final[fast])
        still = change.excludes(0.0) and gap.defined and abs(change.estimate) > gap.half_width
        claims.append(Claim("settling", scene, fast[1], "test_psnr", "diff", change.estimate,
                            f"{change.estimate:+.2f} dB", reference=slow[1], low=change.low, high=change.high,
                            n=change.n, significant=still))
        if still:
            moving.append(f"on {scene}, `{fast[1]}` gained {change.estimate:.2f} dB [95 % CI {change.low:.2f}, "
                          f"{change.high:.2f}] on `{slow[1]}` over that interval, more than the 95 % interval of their "
                          f"final difference (±{gap.half_width:.2f} dB)")
    if moving:
        lines.append("- **Not settled**: " + "; ".join(moving) + ". The difference reported above is what this run "
                     "length gives, not where the cells converge.")
    elif claims:
        lines.append("- Settled: on every scene the gap between the fastest- and slowest-rising cells moved over the "
                     "last interval by no more than the 95 % interval of their final difference (or not beyond seed "
                     "noise).")
    return Finding("settling", lines, claims)


def parity_finding(runs: pd.DataFrame) -> Finding | None:
    """Raster kind: the largest implementation error against the matched reference."""
    col = "metric.parity_max_abs"
    done = done_runs(runs)
    if col not in done.columns or done[col].dropna().empty:
        return None
    values = pd.to_numeric(done[col])
    worst = float(values.max())
    row = done.loc[values.idxmax()]
    # the worst run's cell: the axes where it differs from the most common value (the base, one at a time)
    axes = [c for c in done.columns if c.startswith("axis.")]
    cell = ", ".join(f"{c[5:]}={row[c]}" for c in axes if row[c] != done[c].mode().iloc[0]) or "the base"
    text = f"{worst:.1e}"
    claim = Claim("parity", "", "", "parity_max_abs", "max", worst, text)
    return Finding("parity", [f"- Against the float64 reference with the *same* options, the largest difference "
                              f"over all {len(done)} runs is {text} ({row['scene']}, {cell}). Most of a pixel's "
                              f"difference is float32 rounding (~1e-6); a pixel where float32 and float64 fall on "
                              f"different sides of a threshold (alpha_min, the cutoff, the early stop) differs by a "
                              f"whole contribution, up to about alpha_min x its colour, which is why the largest "
                              f"difference grows with alpha_min. The exact-error columns above are what each option "
                              f"trades in against the exact Gaussian mixture."],
                   [claim])


def lpips_note(runs: pd.DataFrame) -> list[str]:
    """Train kind: which LPIPS the report's column is (net and input convention), from the
    done runs' ``lpips_net`` / ``lpips_scale_inputs``; none for a table without them."""
    from splatbench.metrics.perceptual import convention  # late: the reports start without torch

    if "metric.lpips_net" not in runs.columns:
        return []
    done = done_runs(runs)
    done = done[done["metric.lpips_net"].fillna("").astype(bool)]
    kinds = sorted({(str(r["metric.lpips_net"]), bool(r["metric.lpips_scale_inputs"])) for _, r in done.iterrows()})
    if len(kinds) == 1:
        return [f"- The `LPIPS` column is {convention(*kinds[0])}."]
    return [f"- The `LPIPS` column mixes {len(kinds)} conventions (compare within one only): "
            + "; ".join(convention(*k) for k in kinds) + "."] if kinds else []


#: A note of a report's "Metrics" section: ``note(runs) -> lines``.
MetricNote = Callable[[pd.DataFrame], list[str]]

_AXIS_NOTES: dict[str, list[AxisNote]] = {"train": [auto_sh_degree_note]}
_METRIC_NOTES: dict[str, list[MetricNote]] = {"train": [lpips_note]}
_RUN_FINDINGS: dict[str, list[tuple[str, RunFinding]]] = {"raster": [("parity", parity_finding)],
                                                           "train": [("settling", settling_finding)]}


def register_axis_note(kind: str, note: AxisNote) -> AxisNote:
    """Append ``note`` to every axis finding of the kind called ``kind``."""
    _AXIS_NOTES.setdefault(kind, []).append(note)
    return note


def register_run_finding(kind: str, name: str, finding: RunFinding) -> RunFinding:
    """Add the finding ``name`` (``finding(runs)``) to the reports of the kind called ``kind``."""
    _RUN_FINDINGS.setdefault(kind, []).append((name, finding))
    return finding


def register_metric_note(kind: str, note: MetricNote) -> MetricNote:
    """Append ``note``'s lines to the "Metrics" section of the reports of ``kind``."""
    _METRIC_NOTES.setdefault(kind, []).append(note)
    return note


def metric_notes(kind: str) -> tuple[MetricNote, ...]:
    """The metric notes registered for ``kind``."""
    return tuple(_METRIC_NOTES.get(kind, ()))


def axis_notes(kind: str) -> tuple[AxisNote, ...]:
    """The axis notes registered for ``kind`` (none for another kind)."""
    return tuple(_AXIS_NOTES.get(kind, ()))


def run_findings(kind: str) -> tuple[tuple[str, RunFinding], ...]:
    """The ``(name, finding)`` run findings registered for ``kind``."""
    return tuple(_RUN_FINDINGS.get(kind, ()))


__all__ = ["RunFinding", "MetricNote", "auto_sh_degree_note", "parity_finding", "settling_finding", "lpips_note", "register_axis_note",
           "register_run_finding", "register_metric_note", "axis_notes", "run_findings", "metric_notes"]
