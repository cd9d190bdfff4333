"""Report figures (matplotlib, Agg backend, PNG): training curves, and the cell means
the Pareto figures (time or Gaussians against error) draw.

* `curves_figure`: one panel per scene, one line per axis row: the mean over the
  row's runs of the test PSNR at each evaluation (``eval_step`` / ``eval_psnr`` in the
  curves) when runs evaluated at least twice, else of the training-view PSNR.
* `cell_means`: one point per grid cell (mean over seeds, with the half-widths of the
  95 % t intervals over seeds), what `splatbench.plotting.pareto_figure` draws.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from splatbench.plotting import panels, pyplot
from splatbench.metrics.stats import t_interval
from splatbench.report_files import save_figure
from splatbench.reports.tables import AxisTable, done_runs


def mean_curve(curves: Sequence[dict], x_key: str, y_key: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``y_key`` over runs at the ``x_key`` steps every run has (sorted)."""
    series = []
    for c in curves:
        xs, ys = c.get(x_key) or [], c.get(y_key) or []
        series.append({int(x): float(y) for x, y in zip(xs, ys) if y is not None and math.isfinite(y)})
    if not series:
        return np.zeros(0), np.zeros(0)
    common = sorted(set.intersection(*(set(s) for s in series)))
    return np.array(common, dtype=float), np.array([np.mean([s[x] for s in series]) for x in common])


def curve_keys(curves: Sequence[dict]) -> tuple[str, str, str] | None:
    """(x key, y key, y label) for the runs' curves: test PSNR when evaluated twice or
    more, else training PSNR; None when the curves hold neither."""
    if curves and all(len(c.get("eval_step") or []) >= 2 for c in curves):
        return "eval_step", "eval_psnr", "test PSNR (dB)"
    if curves and all(len(c.get("step") or []) >= 2 and "psnr" in c for c in curves):
        return "step", "psnr", "training-view PSNR (dB)"
    return None


def curves_figure(table: AxisTable, runs: pd.DataFrame, path: Path) -> Path | None:
    """Training curves of one axis (module doc); None when the runs have no curves."""
    done = done_runs(runs)
    if "curves" not in done.columns or done.empty:
        return None
    parsed = {rid: json.loads(c) if isinstance(c, str) else None for rid, c in zip(done.run_id, done.curves)}
    parsed = {k: v for k, v in parsed.items() if isinstance(v, dict)}
    keys = curve_keys(list(parsed.values()))
    if keys is None:
        return None
    x_key, y_key, y_label = keys
    scenes = list(dict.fromkeys(table.frame.scene))
    plt = pyplot()
    fig, axes = panels(plt, len(scenes))
    for ax, scene in zip(axes, scenes):
        ids = set(done.run_id[done.scene == scene])
        for row in table.rows:
            curves = [parsed[r] for r in row.run_ids if r in ids and r in parsed]
            x, y = mean_curve(curves, x_key, y_key)
            if len(x):
                ax.plot(x, y, marker="o", markersize=2.5, linewidth=1.2, label=row.label)
        ax.set_title(scene)
        ax.set_xlabel("iteration")
        ax.set_ylabel(y_label)
        ax.grid(alpha=0.3)
    axes[-1].legend(title=table.axis, fontsize=7, title_fontsize=8, loc="lower right")
    fig.suptitle(f"{y_label} during training, by {table.axis} (mean over runs)", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)  # whole or not at all, titles and labels never clipped; closes the figure


def cell_means(runs: pd.DataFrame, labels: pd.Series, cost: str, quality: str) -> pd.DataFrame:
    """Mean cost (metric ``cost``: a time, the number of Gaussians) and quality per (scene,
    cell label) over the done runs (one run per seed in a cell), with the half-widths of
    their 95 % t intervals; columns ``time`` (the cost, as `pareto_figure` names its x),
    ``quality``, ``time_half``, ``quality_half`` (NaN with one seed)."""
    done = done_runs(runs)
    frame = pd.DataFrame({"scene": done.scene, "cell": labels.loc[done.index],
                          "time": pd.to_numeric(done[f"metric.{cost}"], errors="coerce"),
                          "quality": pd.to_numeric(done[f"metric.{quality}"], errors="coerce")})
    order = list(dict.fromkeys(frame.cell))
    records = []
    for (scene, cell), group in frame.groupby(["scene", "cell"], sort=False):
        t, q = t_interval(list(group.time)), t_interval(list(group.quality))
        records.append({"scene": scene, "cell": cell, "time": t.estimate, "quality": q.estimate,
                        "time_half": t.half_width, "quality_half": q.half_width})
    out = pd.DataFrame.from_records(records, columns=["scene", "cell", "time", "quality", "time_half",
                                                      "quality_half"])
    out["order"] = out.cell.map(order.index)
    return out.sort_values(["order"], kind="stable").drop(columns="order").reset_index(drop=True)


__all__ = ["curves_figure", "cell_means", "mean_curve", "curve_keys"]
