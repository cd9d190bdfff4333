"""Report figures (matplotlib, Agg backend, PNG): training curves and time against error.

* `curves_figure`: one panel per scene, one line per axis row: the mean over the
  row's runs of the test PSNR at each evaluation (``eval_step`` / ``eval_psnr`` in the
  curves) when runs evaluated at least twice, else of the training-view PSNR.
* `pareto_figure`: one panel per scene, one point per grid cell (mean over seeds, with
  95 % t-interval bars over seeds in both directions when a cell has two seeds or
  more): a time metric across, a quality metric up; the Pareto-optimal cells (no
  other cell is both faster and better, on the means) are ringed and joined by a
  step line. `pareto_front` is the
  computation, shared with the report text.
* `difference_figure`: a per-pixel error map with its colour scale (the demo's
  ``garden_difference.png``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from splatbench.reports.stats import t_interval
from splatbench.reports.tables import AxisTable, MetricSpec, done_runs


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _panels(plt, count: int, width: float = 4.2, height: float = 3.4):
    fig, axes = plt.subplots(1, count, figsize=(width * count, height), squeeze=False)
    return fig, list(axes[0])


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
    plt = _pyplot()
    fig, axes = _panels(plt, len(scenes))
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
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight", pad_inches=0.1)  # titles and labels never clipped
    plt.close(fig)
    return path


def pareto_front(times: Sequence[float], quality: Sequence[float]) -> list[int]:
    """Indices of the points no other point dominates (time <= and quality >=, one
    strictly), sorted by time. NaN points are never on the front."""
    pts = [(t, q, i) for i, (t, q) in enumerate(zip(times, quality)) if math.isfinite(t) and math.isfinite(q)]
    front = []
    for t, q, i in pts:
        dominated = any((t2 <= t and q2 >= q) and (t2 < t or q2 > q) for t2, q2, _ in pts)
        if not dominated:
            front.append((t, i))
    return [i for _, i in sorted(front)]


def cell_means(runs: pd.DataFrame, labels: pd.Series, time: str, quality: str) -> pd.DataFrame:
    """Mean time and quality per (scene, cell label) over the done runs (one run per seed
    in a cell), with the half-widths of their 95 % t intervals (``time_half``,
    ``quality_half``; NaN with one seed)."""
    done = done_runs(runs)
    frame = pd.DataFrame({"scene": done.scene, "cell": labels.loc[done.index],
                          "time": pd.to_numeric(done[f"metric.{time}"], errors="coerce"),
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


def pareto_figure(means: pd.DataFrame, scenes: Sequence[str], time: MetricSpec, quality: MetricSpec, path: Path,
                  title: str) -> dict[str, list[str]]:
    """Time against quality per scene, the Pareto front marked; returns scene -> front cells."""
    plt = _pyplot()
    fig, axes = _panels(plt, len(scenes), 4.6, 3.8)
    fronts: dict[str, list[str]] = {}
    for ax, scene in zip(axes, scenes):
        sub = means[means.scene == scene].reset_index(drop=True)
        idx = pareto_front(list(sub.time), list(sub.quality))
        fronts[scene] = [sub.cell[i] for i in idx]
        ax.scatter(sub.time, sub.quality, s=18, color="tab:blue", zorder=3)
        if "time_half" in sub.columns:
            ax.errorbar(sub.time, sub.quality, xerr=sub.time_half.fillna(0.0), yerr=sub.quality_half.fillna(0.0),
                        fmt="none", ecolor="tab:blue", elinewidth=0.8, capsize=2, alpha=0.7, zorder=2)
        finite = sub.time[np.isfinite(sub.time)]
        middle = float(finite.min() + finite.max()) / 2 if len(finite) else 0.0
        for _, r in sub.iterrows():
            if math.isfinite(r.time) and math.isfinite(r.quality):  # labels point inwards: never off the edge
                right = r.time > middle
                ax.annotate(r.cell, (r.time, r.quality), fontsize=6, xytext=(-3 if right else 3, 3),
                            textcoords="offset points", ha="right" if right else "left")
        if idx:
            fx, fy = sub.time[idx].to_numpy(), sub.quality[idx].to_numpy()
            ax.step(fx, fy, where="post", color="tab:red", linewidth=1.0, zorder=2, label="Pareto front")
            ax.scatter(fx, fy, s=70, facecolors="none", edgecolors="tab:red", linewidths=1.2, zorder=4)
            ax.legend(fontsize=7, loc="lower right")
        ax.set_title(scene)
        ax.set_xlabel(f"{time.label} (lower is better)")
        ax.set_ylabel(f"{quality.label} (higher is better)")
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight", pad_inches=0.1)  # titles and labels never clipped
    plt.close(fig)
    return fronts


def difference_figure(error: np.ndarray, path: Path, *, tolerance: float, title: str) -> Path:
    """``error`` [H, W] (>= 0) on a log colour scale with its colour bar, from tolerance / 100
    (and below, zeros included) to its maximum; the ``tolerance`` is marked on the bar."""
    from matplotlib.colors import LogNorm

    plt = _pyplot()
    height, width = error.shape
    low = tolerance / 100
    high = max(float(error.max()), tolerance * 10)
    fig, ax = plt.subplots(figsize=(6.4, 6.4 * height / width))
    shown = ax.imshow(np.maximum(error, low), norm=LogNorm(vmin=low, vmax=high), cmap="magma",
                      interpolation="nearest")
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)
    bar = fig.colorbar(shown, ax=ax, fraction=0.046 * height / width, pad=0.02)  # as tall as the image
    bar.set_label(f"|difference|, max over RGB (cyan: the {tolerance:.0e} tolerance)", fontsize=7)
    bar.ax.axhline(tolerance, color="cyan", linewidth=1.5)
    bar.ax.tick_params(labelsize=7)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight", pad_inches=0.1)
    plt.close(fig)
    return path


__all__ = ["curves_figure", "pareto_figure", "difference_figure", "pareto_front", "cell_means", "mean_curve", "curve_keys"]
