"""How a report shows one metric: `MetricSpec` (the run kinds' reports, ``compare``)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class MetricSpec:
    """How a report shows one metric (``metric.<name>`` in a run table)."""

    name: str          # metric name, without the "metric." prefix
    label: str         # column heading
    fmt: str           # format spec of one value, e.g. ".2f"
    unit: str = ""     # unit written after differences ("dB", "ms"; "" for none)
    better: str = ""   # "higher", "lower" or "" (no preferred direction)
    interval: bool = True  # False: the table shows the mean alone (a fraction, a count of its own)
    meaning: str = ""  # what the metric is, in words (a report's "Metrics" section)
    bounds: tuple[float, float] = (-math.inf, math.inf)  # the range its values lie in (SSIM <= 1, LPIPS >= 0):
    #   a printed interval is cut at it (`clip`)


def clip(low: float, high: float, how: str, spec: MetricSpec) -> tuple[float, float]:
    """A 95 % interval ``[low, high]`` of ``spec``'s mean (``how`` "mean"), paired difference ("diff")
    or ratio ("ratio"), cut at the values such a number can take: the metric's `MetricSpec.bounds`
    ``[lo, hi]`` for a mean, ``[lo - hi, hi - lo]`` for a difference, ``[0, inf)`` for a ratio of a
    metric that is never negative. A Student's t interval assumes a normal mean and may cross a
    bound (an SSIM mean near 1, an LPIPS near 0); the part beyond it holds no value the mean can
    take, so cutting it keeps the interval's coverage (the standard answer for a bounded parameter,
    e.g. Mandelkern, Statistical Science 17, 2002). The one place a report clips an interval
    (docs/reports.md, "What an interval covers")."""
    lo, hi = spec.bounds
    if how == "diff":
        lo, hi = lo - hi, hi - lo
    elif how == "ratio":
        lo, hi = (0.0, math.inf) if lo >= 0 else (-math.inf, math.inf)
    return max(low, lo), min(high, hi)


__all__ = ["MetricSpec", "clip"]
