"""Report tables: which runs make up each axis value, and mean ± 95 % interval over seeds.

An experiment's runs are grouped per **axis** (a plain axis or a variant axis):

* ``grid = "product"``: the row of axis value ``v`` holds every run whose cell has
  ``v`` on that axis (all values of the other axes, all seeds), per scene;
* ``grid = "one-at-a-time"``: the rows are the base cell and each value of that axis
  alone on top of the base (a value equal to the base is the base row).

Membership comes from the experiment file itself (`axis_rows` expands a one-value
copy of the grid per row and keeps the run ids), so a report always describes the
grid as written, never a stale one. An ``[extra.DIMENSION]`` cell (outside the grid) is
a row of its dimension's table alone, after the grid's rows (`Row.extra`). Statistics are over the *done* runs of a row,
**seed by seed**: a row's runs of one seed are averaged first (in a product grid they
are that seed's runs of every other axis value), then the mean over seeds is given
with the half-width of its 95 % Student's t interval (`splatbench.metrics.stats`; the
seed is the unit of replication). With one seed there is no interval: the mean alone.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import pandas as pd

from splatbench.experiments.configs import decode, flatten, unflatten
from splatbench.experiments.grid import expand
from splatbench.experiments.kind_report import done_runs
from splatbench.experiments.kinds import RunKind
from splatbench.experiments.spec import ExperimentSpec
from splatbench.metrics.spec import MetricSpec, clip
from splatbench.metrics.stats import t_quantile
from splatbench.report_files import markdown_table


def metric_specs(kind: RunKind, table: pd.DataFrame) -> tuple[MetricSpec, ...]:
    """The metrics a report of ``kind`` shows that ``table`` holds: those its `KindReport` names,
    in its order; for a kind without one, every numeric metric (as its result declares it)."""
    present = {c[len("metric."):] for c in table.columns if c.startswith("metric.")}
    specs = kind.specs
    if kind.report is not None:
        return tuple(specs[name] for name in kind.report.metrics if name in present)
    numeric = [c[len("metric."):] for c in table.columns if c.startswith("metric.")
               and pd.api.types.is_numeric_dtype(table[c]) and not pd.api.types.is_bool_dtype(table[c])]
    return tuple(specs.get(name) or MetricSpec(name, name, ".4g") for name in numeric)


# --------------------------------------------------------------------------- rows
@dataclass(frozen=True)
class Row:
    """One row of an axis table: a label and the run ids it pools (every scene and seed)."""

    label: str                 # display label: "3", "auto", "mcmc", "16 (base)", "base"
    value: Any                 # the axis value or variant label (None for a one-at-a-time base)
    run_ids: frozenset[str]
    is_base: bool = False      # the one-at-a-time base cell
    extra: bool = False        # an ``[extra.DIMENSION]`` cell: outside the grid (compared only where
    #                            ``[report] matched`` names it; docs/reports.md, "Model size")


def display(value: Any) -> str:
    """An axis value as the report writes it (``0.1``, ``auto``, ``true``, a table as JSON)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (dict, list)):
        return json.dumps(value, sort_keys=True, separators=(", ", " = ")) if isinstance(value, list) else \
            "{" + ", ".join(f"{k} = {display(v)}" for k, v in sorted(value.items())) + "}"
    return str(value)


def _ids(spec: ExperimentSpec, **changes) -> frozenset[str]:
    """The run ids of a copy of ``spec`` with ``changes`` (without its extra cells, unless they are given)."""
    return frozenset(r.run_id for r in expand(dataclasses.replace(spec, **{"extra": {}, **changes})))


def grid_runs(spec: ExperimentSpec, runs: pd.DataFrame) -> pd.DataFrame:
    """The runs of ``runs`` that belong to the grid itself, not to its extra cells alone (`ExperimentSpec.extra`:
    the ranks order the grid's cells, never a matched-size extra cell)."""
    return runs[runs.run_id.isin(_ids(spec))] if spec.extra and len(runs) else runs


def axis_rows(spec: ExperimentSpec, axis: str) -> list[Row]:
    """The rows of ``axis`` in file order (module doc), with the run ids of each: the grid's, then
    its extra cells' (`Row.extra`)."""
    extra = spec.extra.get(axis, {})
    if extra:
        grid_ids = _ids(spec)
        return [*_grid_rows(spec, axis), *(Row(display(lab), lab, _ids(spec, extra={axis: {lab: s}}) - grid_ids,
                                               extra=True) for lab, s in extra.items())]
    return _grid_rows(spec, axis)


def _grid_rows(spec: ExperimentSpec, axis: str) -> list[Row]:
    """The rows of ``axis`` of the grid itself (module doc)."""
    if axis in spec.axes:
        choices = [(v, {"axes": {**spec.axes, axis: (v,)}}) for v in spec.axes[axis]]
        only = [(v, {"grid": "product", "axes": {axis: (v,)}, "variants": {}}) for v in spec.axes[axis]]
    else:
        labels = spec.variants[axis]
        choices = [(lab, {"variants": {**spec.variants, axis: {lab: labels[lab]}}}) for lab in labels]
        only = [(lab, {"grid": "product", "axes": {}, "variants": {axis: {lab: labels[lab]}}}) for lab in labels]
    if spec.grid == "product":
        return [Row(display(v), v, _ids(spec, **changes)) for v, changes in choices]
    base_ids = _ids(spec, axes={}, variants={})
    rows: list[Row] = []
    base_value = _base_value(spec, axis)
    base_seen = False
    for v, changes in only:
        ids = _ids(spec, **changes)
        if ids == base_ids:
            rows.append(Row(f"{display(v)} (base)", v, ids, True))
            base_seen = True
        else:
            rows.append(Row(display(v), v, ids))
    if not base_seen:
        label = "base" if base_value is None else f"{display(base_value)} (base)"
        rows.insert(0, Row(label, base_value, base_ids, True))
    return rows


def _base_value(spec: ExperimentSpec, axis: str) -> Any:
    """The base cell's value of a plain axis (resolved: the kind's default when unset);
    None for a variant axis."""
    if axis not in spec.axes:
        return None
    return _base_labels(spec).get(axis)


def _base_labels(spec: ExperimentSpec) -> dict[str, Any]:
    """The base cell's label on every axis: a plain axis's resolved value, None for variants."""
    runs = expand(dataclasses.replace(spec, axes={}, variants={}, extra={}))
    if not runs:
        return {}
    resolved = flatten(runs[0].config)
    out: dict[str, Any] = {}
    for axis in spec.axes:
        if axis in resolved:
            out[axis] = resolved[axis]
        else:
            sub = {k[len(axis) + 1:]: v for k, v in resolved.items() if k.startswith(axis + ".")}
            out[axis] = unflatten(sub) if sub else None
    return out


# --------------------------------------------------------------------------- statistics
@dataclass(frozen=True)
class Stat:
    """Mean over seeds, sample std of the per-seed values (ddof 1; NaN with fewer than
    two) and the number of seeds n, of one metric."""

    mean: float
    std: float
    n: int

    @property
    def half_width(self) -> float:
        """Half-width of the 95 % t interval of the mean, ``t_{0.975, n-1} std / sqrt(n)``
        (NaN with fewer than two seeds)."""
        if self.n < 2 or math.isnan(self.std):
            return math.nan
        return t_quantile(self.n) * self.std / math.sqrt(self.n)

    def text(self, fmt: str, bounds: tuple[float, float] = (-math.inf, math.inf)) -> str:
        """``"27.31 ± 0.42"`` (mean ± 95 % half-width), the mean alone for one seed, "–" for none,
        ``"41.26 (no spread)"`` when the half-width is zero at ``fmt``'s precision: the seeds did
        not vary the value, so there is no interval to show (never ``± 0.00``); ``"0.9981 [0.9952,
        1.0000]"`` where mean ± half-width would cross the metric's ``bounds`` (`MetricSpec.bounds`):
        the interval cut there (`splatbench.metrics.spec.clip`)."""
        if self.n == 0 or math.isnan(self.mean):
            return "–"
        if self.n < 2 or math.isnan(self.std):
            return format(self.mean, fmt)
        if float(format(self.half_width, fmt)) == 0.0:
            return f"{format(self.mean, fmt)} (no spread)"
        low, high = self.mean - self.half_width, self.mean + self.half_width
        if low < bounds[0] or high > bounds[1]:
            low, high = clip(low, high, "mean", MetricSpec("", "", fmt, bounds=bounds))
            return f"{format(self.mean, fmt)} [{format(low, fmt)}, {format(high, fmt)}]"
        return f"{format(self.mean, fmt)} ± {format(self.half_width, fmt)}"


def seed_values(runs: pd.DataFrame, metric: str) -> dict[int, float]:
    """Seed -> the mean of ``metric`` over ``runs`` of that seed (finite values only)."""
    v = pd.to_numeric(runs[f"metric.{metric}"], errors="coerce").astype("float64")
    frame = pd.DataFrame({"seed": runs.seed.astype(int), "v": v})
    frame = frame[frame.v.map(math.isfinite).astype(bool)]  # bool: an empty object mask would select columns
    return {int(k): float(x) for k, x in frame.groupby("seed", sort=True).v.mean().items()}


def stat(values: pd.Series | dict[int, float]) -> Stat:
    """`Stat` of the finite values (a per-seed mapping, or a series of one value per seed)."""
    raw = list(values.values()) if isinstance(values, dict) else list(values)
    v = pd.to_numeric(pd.Series(raw, dtype=object), errors="coerce").astype("float64")
    v = v[v.map(math.isfinite)]
    if len(v) == 0:
        return Stat(math.nan, math.nan, 0)
    return Stat(float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else math.nan, int(len(v)))


@dataclass
class AxisTable:
    """mean ± 95 % interval over seeds per (scene, row) of each metric.

    frame: one row per (scene, row label) in grid order, columns ``scene``, ``label``,
    ``runs`` (done runs pooled), then ``<metric>.mean``, ``<metric>.std``, ``<metric>.n``
    (statistics of the per-seed values, module doc) and ``<metric>.loaded`` (runs timed under
    load left out of a time metric; 0 for the others). per_seed: (scene, label, metric)
    -> seed -> value, what the findings pair.
    """

    axis: str
    rows: list[Row]
    metrics: tuple[MetricSpec, ...]
    frame: pd.DataFrame
    per_seed: dict[tuple[str, str, str], dict[int, float]] = dataclasses.field(default_factory=dict)

    @property
    def max_seeds(self) -> int:
        """The most seeds any cell of the table has (1: no interval anywhere)."""
        cols = [f"{m.name}.n" for m in self.metrics]
        return int(self.frame[cols].max().max()) if cols and len(self.frame) else 0

    def stat(self, scene: str, label: str, metric: str) -> Stat:
        row = self.frame[(self.frame.scene == scene) & (self.frame.label == label)].iloc[0]
        return Stat(float(row[f"{metric}.mean"]), float(row[f"{metric}.std"]), int(row[f"{metric}.n"]))

    def markdown(self) -> str:
        return markdown_table(["scene", self.axis, "runs", *(m.label for m in self.metrics)],
                              ([r.scene, f"`{r.label}`", int(r.runs), *(_cell(r, m) for m in self.metrics)]
                               for _, r in self.frame.iterrows() if not r.get("absent", False)),
                              align="---" + "r" * len(self.metrics))


def _cell(r: pd.Series, m: MetricSpec) -> str:
    """One table cell: `Stat.text`; a time none of whose runs was timed on a quiet machine reads
    "— (loaded)", and one that left some out says how many (``<metric>.loaded``, `axis_table`)."""
    text = Stat(r[f"{m.name}.mean"], r[f"{m.name}.std"] if m.interval else math.nan, int(r[f"{m.name}.n"])).text(m.fmt, m.bounds)
    left = int(r.get(f"{m.name}.loaded", 0) or 0)
    if not left:
        return text
    if int(r[f"{m.name}.n"]) == 0:
        return "— (loaded)"
    return f"{text} ({left} loaded run{'s' if left != 1 else ''} left out)"


def loaded_runs(runs: pd.DataFrame, kind: RunKind) -> pd.Series:
    """True per run timed while other processes loaded the machine, where the kind's mark leaves
    such a run out of its timed metrics only (`LoadMarks`, scope "timed": the train kind's
    ``metric.time_loaded`` is 1); False for every run where the kind has no such mark or the
    column is absent (runs from before it was recorded)."""
    load = kind.report.load if kind.report is not None else None
    col = f"metric.{load.flag}" if load is not None and load.scope == "timed" else None
    if col not in runs.columns:
        return pd.Series(False, index=runs.index)
    return pd.to_numeric(runs[col], errors="coerce").fillna(0) != 0


def axis_table(spec: ExperimentSpec, kind: RunKind, axis: str, table: pd.DataFrame, metrics: Sequence[MetricSpec]
               ) -> AxisTable:
    """The `AxisTable` of ``axis`` over the done runs of ``table``. The kind's time metrics
    (`KindReport.timed`) pool only the runs not timed under load (`loaded_runs`): column
    ``<metric>.loaded`` counts those left out (docs/reports.md, "Loaded times")."""
    rows = axis_rows(spec, axis)
    timed = set(kind.report.timed) if kind.report is not None else set()
    done = done_runs(table)
    records = []
    per_seed: dict[tuple[str, str, str], dict[int, float]] = {}
    for scene in spec.scenes:
        at_scene = done[done.scene == scene]
        for row in rows:
            runs = at_scene[at_scene.run_id.isin(row.run_ids)]
            # an extra cell whose `scenes` leave this one out: kept in the frame, not written as a row of runs
            absent = row.extra and not spec.extra_runs_at(axis, row.value, scene)
            rec: dict[str, Any] = {"scene": scene, "label": row.label, "runs": len(runs), "absent": absent}
            loaded = loaded_runs(runs, kind)
            for m in metrics:
                left = int(loaded.sum()) if m.name in timed else 0
                values = seed_values(runs[~loaded] if left else runs, m.name)
                per_seed[(scene, row.label, m.name)] = values
                s = stat(values)
                rec.update({f"{m.name}.mean": s.mean, f"{m.name}.std": s.std, f"{m.name}.n": s.n,
                            f"{m.name}.loaded": left})
            records.append(rec)
    return AxisTable(axis, rows, tuple(metrics), pd.DataFrame.from_records(records), per_seed)


# --------------------------------------------------------------------------- cells
def shared_prefix(names: Sequence[str]) -> str:
    """The dotted prefix every name shares (``"strategy."`` for
    ``strategy.refine_stop`` and ``strategy.reset_every``), else ""."""
    parts = [n.split(".")[:-1] for n in names]
    common: list[str] = []
    for level in zip(*parts) if parts else ():
        if len(set(level)) != 1:
            break
        common.append(level[0])
    return "".join(f"{c}." for c in common)


def cell_labels(spec: ExperimentSpec, table: pd.DataFrame, short: bool = False) -> pd.Series:
    """A display label per run of ``table`` naming its grid cell (``sh_degree=3``;
    ``densify=mcmc, loss.ssim_lambda=0.2``; ``base`` for a one-at-a-time base). ``short``: the
    axes' shared dotted prefix left out (``refine_stop=25%`` for
    ``strategy.refine_stop=25%``; the figures' point labels)."""
    dims = spec.dimensions
    if not dims:
        return pd.Series(["all"] * len(table), index=table.index)
    cols = [f"axis.{d}" for d in dims]
    prefix = shared_prefix(dims) if short else ""
    names = [d[len(prefix):] for d in dims]
    if spec.grid == "one-at-a-time":
        base = {d: _json(v) for d, v in _base_labels(spec).items()}

        def label(row) -> str:
            diff = [f"{n}={display(decode(row[c]))}" for d, n, c in zip(dims, names, cols)
                    if _json(decode(row[c])) != base.get(d, _json(None))]
            return ", ".join(diff) or "base"
    else:
        def label(row) -> str:
            return ", ".join(f"{n}={display(decode(row[c]))}" for n, c in zip(names, cols))
    return table.apply(label, axis=1) if len(table) else pd.Series([], dtype=object)


def _json(value: Any) -> str:
    return json.dumps(value, sort_keys=True)


__all__ = ["metric_specs", "shared_prefix", "Row", "axis_rows", "grid_runs", "display", "Stat", "stat", "seed_values", "AxisTable",
           "axis_table", "cell_labels", "done_runs", "loaded_runs"]
