"""Kind-specific findings, registered with the reports by kind name.

A run kind declares its report as plain data (`splatbench.experiments.kind_report`);
a finding that needs code of its own lives here and is looked up by the kind's name,
so the experiments never import the reports:

* axis notes (`register_axis_note`): ``note(axis_table, runs, scenes) -> (lines, claims)``
  appended to each axis finding of the kind (train: `auto_sh_degree_note`);
* run findings (`register_run_finding`): ``finding(runs, min_effect) -> Finding | None`` over all
  runs of the kind (raster: `parity_finding`; train: `settling_finding`), each its own
  section of the report;
* header notes (`register_header_note`): ``note(runs) -> lines`` in the report's header
  (train: `splatbench.reports.protocol.protocol_lines`, the protocol its runs followed);
* metric notes (`register_metric_note`): ``note(runs) -> lines`` appended to the report's
  "Metrics" section (train: `lpips_note`, which LPIPS the column is).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping

import pandas as pd

from splatbench.reports.findings import AxisNote, Claim, Finding
from splatbench.reports.protocol import protocol_lines
from splatbench.reports.settling import CellSettling, cell_settling
from splatbench.reports.tables import AxisTable, done_runs, kind_report

#: A finding over all runs of a kind: ``finding(runs, min_effect) -> Finding | None`` (``min_effect``: the
#: experiment file's ``[report] min_effect``, metric -> number).
RunFinding = Callable[[pd.DataFrame, "Mapping[str, float] | None"], "Finding | None"]


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


#: Strategies whose opacity resets gate size pruning and fire only inside the refine window
#: (`splatbench.strategies.default.DefaultStrategy` and its subclasses).
_RESETTING = ("default", "absgrad", "budget")


def schedule_confound_note(table: AxisTable, runs: pd.DataFrame, scenes: list[str]) -> tuple[list[str], list[Claim]]:
    """Train kind: what a densification-schedule setting changes besides itself, read from the
    runs' configs (so it holds for grids run before the counts were recorded):
    ``reset_every = 0`` also turns off size pruning (DefaultStrategy prunes by size only after
    the first reset), and ``refine_stop`` also changes the number of opacity resets (they fire
    only inside the refine window)."""
    done = done_runs(runs)
    col = f"config.{table.axis}" if not table.axis.startswith("config.") else table.axis
    if "config.strategy" not in done.columns or col not in done.columns:
        return [], []
    resetting = done[done["config.strategy"].isin(_RESETTING)]
    lines = []
    if table.axis == "strategy_options.reset_every":
        zero = [r for r in table.rows if _decoded(r.value) == 0 and resetting.run_id.isin(r.run_ids).any()]
        for r in zero:
            lines.append(f"- `{r.label}` (no opacity resets) also turns off size pruning: the default strategy prunes "
                         f"Gaussians larger than `max_world_size` × the scene extent only after its first opacity "
                         f"reset (splatbench/strategies/default.py), so this cell changes two things, not one.")
    if table.axis == "strategy_options.refine_stop" and len(resetting):
        lines.append("- Opacity resets fire only inside the refine window (as in graphdeco), so `refine_stop` also "
                     "changes how many resets a run makes (`metric.opacity_resets` where recorded).")
    return lines, []


def _decoded(value):
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


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


def settling_finding(runs: pd.DataFrame, min_effect: Mapping[str, float] | None = None) -> Finding | None:
    """Train kind: whether each cell had settled when its runs ended (`splatbench.reports.settling`):
    the slope of its test curve over the last quarter of the run (mean over seeds, per 1,000
    steps) against the threshold, the minimum effect of test PSNR (0.1 dB, or the experiment
    file's) per 1,000 steps; and, where the training-view PSNR is recorded, whether the test
    curve is flat or falling while the training curve still rises (overfitting, not
    convergence). One claim per cell: ``significant`` is True when it is *not* settled."""
    declared = kind_report("train")
    done = done_runs(runs)
    keys = declared.settling if declared is not None else None
    if done.empty or "curves" not in done.columns or keys is None:
        return None
    effect = dict(min_effect or {}).get(keys.metric)
    if effect is None:
        effect = next((c.min_effect for c in declared.rules.comparisons if c.metric == keys.metric), None)
    if effect is None:
        return None
    axes = [c for c in done.columns if c.startswith("axis.")]
    label = _cell_label(done, axes) if axes else (lambda row: "all")
    labels = done.apply(label, axis=1) if len(done) else pd.Series([], dtype=object)
    cells: dict[tuple[str, str], CellSettling] = {}
    for (scene, cell), group in done.groupby([done.scene, labels], sort=False):
        c = cell_settling(group, keys, effect)
        if c is not None:
            cells[(scene, cell)] = c
    if not cells:
        return None
    windows = sorted({(c.start, c.end) for c in cells.values()})
    span = ", ".join(f"{a}→{b}" for a, b in windows)
    threshold = f"{effect:g} dB per 1,000 steps"
    lines = [f"- Test PSNR slope over the last quarter of the run (steps {span}; least squares, mean over seeds; "
             f"a cell is settled below {threshold}, the minimum effect per 1,000 steps: docs/reports.md), with the "
             f"training-view PSNR's slope where recorded: "
             + "; ".join(f"{scene} `{cell}` {c.describe()}" for (scene, cell), c in cells.items()) + "."]
    claims = []
    for (scene, cell), c in cells.items():
        claims.append(Claim("settling", scene, cell, keys.metric, "slope", c.test, f"{c.test:+.2f} dB / 1,000 steps",
                            n=len(c.per_seed), significant=not c.settled, settled=c.settled))
    moving = [f"{scene} `{cell}` ({c.test:+.2f})" for (scene, cell), c in cells.items() if not c.settled]
    overfit = [f"{scene} `{cell}` (test {c.test:+.2f}, train {c.train:+.2f})" for (scene, cell), c in cells.items()
               if c.overfitting]
    if moving:
        lines.append(f"- **Not settled**: {len(moving)} of {len(cells)} cells still moved by {threshold} or more over "
                     f"the last quarter: " + ", ".join(moving) + ". Their differences above are what this run length "
                     "gives, not where the cells converge (each such comparison is marked **not settled**).")
    else:
        lines.append(f"- Settled: every cell's test curve moved by less than {threshold} over the last quarter.")
    if overfit:
        lines.append("- **Overfitting**: the test curve is flat or falling while the training-view PSNR still rises "
                     f"(by {threshold} or more beyond the test curve's slope): " + ", ".join(overfit)
                     + ". Such a cell has stopped generalising; it has not converged.")
    return Finding("settling", lines, claims)


def parity_finding(runs: pd.DataFrame, min_effect: Mapping[str, float] | None = None) -> Finding | None:
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
#: Lines of a report's header (the protocol its runs followed): ``note(runs) -> lines``.
HeaderNote = Callable[[pd.DataFrame], list[str]]

_AXIS_NOTES: dict[str, list[AxisNote]] = {"train": [auto_sh_degree_note, schedule_confound_note]}
_METRIC_NOTES: dict[str, list[MetricNote]] = {"train": [lpips_note]}
_HEADER_NOTES: dict[str, list[HeaderNote]] = {"train": [protocol_lines]}
_RUN_FINDINGS: dict[str, list[tuple[str, RunFinding]]] = {"raster": [("parity", parity_finding)],
                                                           "train": [("settling", settling_finding)]}


def register_axis_note(kind: str, note: AxisNote) -> AxisNote:
    """Append ``note`` to every axis finding of the kind called ``kind``."""
    _AXIS_NOTES.setdefault(kind, []).append(note)
    return note


def register_run_finding(kind: str, name: str, finding: RunFinding) -> RunFinding:
    """Add the finding ``name`` (``finding(runs, min_effect)``) to the reports of the kind called ``kind``."""
    _RUN_FINDINGS.setdefault(kind, []).append((name, finding))
    return finding


def register_metric_note(kind: str, note: MetricNote) -> MetricNote:
    """Append ``note``'s lines to the "Metrics" section of the reports of ``kind``."""
    _METRIC_NOTES.setdefault(kind, []).append(note)
    return note


def register_header_note(kind: str, note: HeaderNote) -> HeaderNote:
    """Add ``note``'s lines to the header of the reports of ``kind`` (e.g. its protocol)."""
    _HEADER_NOTES.setdefault(kind, []).append(note)
    return note


def header_notes(kind: str) -> tuple[HeaderNote, ...]:
    """The header notes registered for ``kind``."""
    return tuple(_HEADER_NOTES.get(kind, ()))


def metric_notes(kind: str) -> tuple[MetricNote, ...]:
    """The metric notes registered for ``kind``."""
    return tuple(_METRIC_NOTES.get(kind, ()))


def axis_notes(kind: str) -> tuple[AxisNote, ...]:
    """The axis notes registered for ``kind`` (none for another kind)."""
    return tuple(_AXIS_NOTES.get(kind, ()))


def run_findings(kind: str) -> tuple[tuple[str, RunFinding], ...]:
    """The ``(name, finding)`` run findings registered for ``kind``."""
    return tuple(_RUN_FINDINGS.get(kind, ()))


__all__ = ["RunFinding", "MetricNote", "HeaderNote", "schedule_confound_note", "register_header_note", "header_notes", "auto_sh_degree_note", "parity_finding", "settling_finding", "lpips_note", "register_axis_note",
           "register_run_finding", "register_metric_note", "axis_notes", "run_findings", "metric_notes"]
