"""Plotting shared by the report writers (experiment reports, ``compare``, ``conform``, ``validate``, the demo):
matplotlib on the Agg backend (PNG), side-by-side panels, and the cost-against-quality
figure with its Pareto front.

`pareto_figure`: one panel per scene, one point per cell (with 95 % interval bars in
both directions when the means come with half-widths ``time_half`` / ``quality_half``):
a cost metric across (a time, or the number of Gaussians; column ``time``), a quality
metric up; the Pareto-optimal cells (no other cell is both cheaper and better, on the
means) are ringed and joined by a step line.
`pareto_front` is the computation, shared with the report text. `difference_figure`:
a per-pixel error map on a log colour scale with its bar (the demo's garden check).
Every figure is written by `splatbench.report_files.save_figure`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from splatbench.metrics.spec import MetricSpec
from splatbench.report_files import save_figure


def pyplot():
    """matplotlib.pyplot on the Agg backend (PNG files, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def panels(plt, count: int, width: float = 4.2, height: float = 3.4):
    """A figure of ``count`` panels side by side and the list of their axes."""
    fig, axes = plt.subplots(1, count, figsize=(width * count, height), squeeze=False)
    return fig, list(axes[0])


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


def pareto_figure(means: pd.DataFrame, scenes: Sequence[str], time: MetricSpec, quality: MetricSpec, path: Path,
                  title: str) -> dict[str, list[str]]:
    """Cost (``means.time``, labelled by ``time``) against quality per scene, the Pareto
    front marked; returns scene -> front cells, cheapest first."""
    plt = pyplot()
    fig, axes = panels(plt, len(scenes), 4.6, 3.8)
    fronts: dict[str, list[str]] = {}
    for ax, scene in zip(axes, scenes):
        sub = means[means.scene == scene].reset_index(drop=True)
        idx = pareto_front(list(sub.time), list(sub.quality))
        fronts[scene] = [sub.cell[i] for i in idx]
        ax.scatter(sub.time, sub.quality, s=18, color="tab:blue", zorder=3)
        if "time_half" in sub.columns:
            ax.errorbar(sub.time, sub.quality, xerr=sub.time_half.fillna(0.0), yerr=sub.quality_half.fillna(0.0),
                        fmt="none", ecolor="tab:blue", elinewidth=0.8, capsize=2, alpha=0.7, zorder=2)
        finite = [t for t in sub.time if math.isfinite(t)]
        middle = (min(finite) + max(finite)) / 2 if finite else 0.0
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
    save_figure(fig, path)
    return fronts


def difference_figure(error, path: Path, *, tolerance: float, title: str) -> Path:
    """``error`` [H, W] (>= 0) on a log colour scale with its colour bar, from tolerance / 100
    (and below, zeros included) to its maximum; the ``tolerance`` is marked on the bar."""
    import numpy as np
    from matplotlib.colors import LogNorm

    plt = pyplot()
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
    return save_figure(fig, path)


__all__ = ["pyplot", "panels", "pareto_front", "pareto_figure", "difference_figure"]
