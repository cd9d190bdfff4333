"""Statistics of the reports: 95 % intervals over seeds, paired differences, their p-values
with Holm's correction, and a bootstrap interval of a median ratio.

Seeds are the unit of replication: run ``s`` of one grid cell pairs with run ``s`` of
another. An interval covers only what a seed varies (the train kind: torch / numpy state,
view order, random backgrounds, the strategy's draws, random initial points -- not the
points of ``init = surface`` nor the rendered dataset; each train report's header lists it
from the runs' configs, docs/reports.md "What an interval covers"). Where the seeds varied
nothing the report prints no interval (`splatbench.reports.findings.no_spread`).

* `t_interval`: the mean of n values with Student's t interval,
  ``mean ± t_{0.975, n-1} · s / sqrt(n)`` (s: sample standard deviation, ddof 1). It
  assumes the values are independent draws of a roughly normal quantity; with n = 1
  there is no interval (``low``/``high`` are NaN, `Interval.text` says so).
* `paired_difference`: the t interval of the per-seed differences ``b_s - a_s`` over
  the seeds both sides have -- far tighter than comparing two unpaired means when
  the seed moves both runs alike.
* `paired_ratio`: the same on ``log(b_s / a_s)``, exponentiated (a geometric-mean
  ratio; "no significant difference" when the interval contains 1).
* `bootstrap_median_ratio`: the median of per-pair ratios ``x_i / y_i`` (times taken
  alternately in one process) with a percentile bootstrap interval
  (`scipy.stats.bootstrap`, seeded, so a report rebuilt from its table gives the same
  numbers).
* `t_p_value`: the two-sided p-value of a t interval's test against a null value, from the
  interval's own numbers (``t = (estimate - null) / (half_width / t_{0.975, n-1})`` on n - 1
  degrees of freedom): below 0.05 exactly when the 95 % interval excludes the null.
* `holm`: Holm's step-down correction of a family of p-values (which stay significant at a
  family-wise error rate).
* `kendall_tau`: the rank agreement of two rankings of the same items (Kendall's tau-b, ties
  counted: `scipy.stats.kendalltau`), +1 the same order, -1 the reverse; NaN with fewer than
  two items or where one side ranks every item equal.

Example::

    t_interval([1.0, 2.0, 3.0])          # Interval(estimate=2.0, low=-0.484, high=4.484, n=3, method="t")
    paired_difference([1, 2, 3], [2, 4, 6]).excludes(0)   # True
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

#: Confidence level of every interval in the reports.
CONFIDENCE = 0.95
#: Resamples of `bootstrap_median_ratio` (percentile intervals settle to ~1e-3 here).
BOOTSTRAP_RESAMPLES = 4999


@dataclass(frozen=True)
class Interval:
    """An estimate with its 95 % interval.

    estimate: the mean (t), the mean difference (paired), the geometric-mean ratio
    (paired ratio) or the median ratio (bootstrap); low / high: the interval (NaN when
    it cannot be computed: fewer than two values, or no spread for a bootstrap); n:
    values (seeds or pairs) it is computed from; method: "t", "paired t",
    "paired t on log ratios" or "bootstrap".
    """

    estimate: float
    low: float
    high: float
    n: int
    method: str

    @property
    def defined(self) -> bool:
        """True when the interval could be computed (n >= 2 and finite ends)."""
        return math.isfinite(self.low) and math.isfinite(self.high)

    @property
    def half_width(self) -> float:
        """Half the interval's width (NaN when undefined)."""
        return (self.high - self.low) / 2.0 if self.defined else math.nan

    def excludes(self, value: float) -> bool:
        """True when the interval is defined and ``value`` lies outside it (a significant
        difference from ``value`` at the 95 % level)."""
        return self.defined and not (self.low <= value <= self.high)


def _finite(values: Sequence[float]) -> np.ndarray:
    v = np.asarray([float(x) for x in values], dtype=np.float64)
    return v[np.isfinite(v)]


def t_quantile(n: int) -> float:
    """``t_{0.975, n-1}``, the two-sided 95 % Student's t quantile for n values (n >= 2)."""
    from scipy import stats

    return float(stats.t.ppf(0.5 + CONFIDENCE / 2.0, n - 1))


def t_interval(values: Sequence[float], *, method: str = "t") -> Interval:
    """Mean of the finite ``values`` with its 95 % t interval (module doc)."""
    v = _finite(values)
    n = int(v.size)
    if n == 0:
        return Interval(math.nan, math.nan, math.nan, 0, method)
    mean = float(v.mean())
    if n < 2:
        return Interval(mean, math.nan, math.nan, n, method)
    half = t_quantile(n) * float(v.std(ddof=1)) / math.sqrt(n)
    return Interval(mean, mean - half, mean + half, n, method)


def t_p_value(iv: Interval, null: float = 0.0) -> float:
    """Two-sided p-value of the t test of ``iv`` (a `t_interval`, `paired_difference` or `paired_ratio`)
    against ``null``, from the interval's own estimate, bounds and n: its standard error is the
    half-width over ``t_{0.975, n-1}`` (`t_quantile`), so ``p < 1 - CONFIDENCE`` exactly when the
    interval excludes ``null``; a ratio's (method "paired t on log ratios") on the logs. NaN where the
    interval is undefined; 0 or 1 where it has no width (the values do or do not all differ from
    ``null``)."""
    from scipy import stats

    if not iv.defined:
        return math.nan
    est, low, high = iv.estimate, iv.low, iv.high
    if iv.method == "paired t on log ratios":
        if min(est, low, high, null) <= 0:
            return math.nan
        est, low, high, null = (math.log(x) for x in (est, low, high, null))
    se = (high - low) / 2.0 / t_quantile(iv.n)
    if se <= 0:
        return 0.0 if est != null else 1.0
    return float(2.0 * stats.t.sf(abs(est - null) / se, iv.n - 1))


def holm(p_values: Sequence[float], alpha: float = round(1.0 - CONFIDENCE, 12)) -> list[bool]:
    """Holm's step-down correction: which of the m hypotheses with these ``p_values`` are rejected at
    family-wise error rate ``alpha``. The p-values sorted ascending, the i-th (i = 0 ... m - 1) is rejected
    while ``p_(i) <= alpha / (m - i)``; the first that is not stops it, and every larger one stays
    (a tie with a rejected one is rejected with it). NaN counts as 1. Example: ``holm([0.01, 0.04, 0.03,
    0.005])`` compares 0.005 with 0.05/4, 0.01 with 0.05/3, 0.03 with 0.05/2 and stops there:
    ``[True, False, False, True]``."""
    p = [1.0 if not math.isfinite(float(x)) else float(x) for x in p_values]
    m = len(p)
    rejected = [False] * m
    for i, k in enumerate(sorted(range(m), key=lambda j: p[j])):
        if p[k] > alpha / (m - i):
            break
        rejected[k] = True
    return rejected


def _pairs(a: Mapping[int, float], b: Mapping[int, float]) -> list[tuple[float, float]]:
    return [(float(a[k]), float(b[k])) for k in sorted(set(a) & set(b))
            if math.isfinite(float(a[k])) and math.isfinite(float(b[k]))]


def paired_difference(a: Mapping[int, float] | Sequence[float], b: Mapping[int, float] | Sequence[float]) -> Interval:
    """Mean of ``b_s - a_s`` over the seeds (keys, or positions of two sequences) both
    have, with its 95 % t interval."""
    pairs = _pairs(_as_map(a), _as_map(b))
    return t_interval([y - x for x, y in pairs], method="paired t")


def paired_ratio(a: Mapping[int, float] | Sequence[float], b: Mapping[int, float] | Sequence[float]) -> Interval:
    """Geometric mean of ``b_s / a_s`` over the paired seeds with its 95 % interval (the t
    interval of the log ratios, exponentiated); pairs with a value <= 0 are left out."""
    pairs = [(x, y) for x, y in _pairs(_as_map(a), _as_map(b)) if x > 0 and y > 0]
    t = t_interval([math.log(y / x) for x, y in pairs])
    return Interval(math.exp(t.estimate) if t.n else math.nan, math.exp(t.low) if t.defined else math.nan,
                    math.exp(t.high) if t.defined else math.nan, t.n, "paired t on log ratios")


def bootstrap_median_ratio(x: Sequence[float], y: Sequence[float], *, seed: int = 0) -> Interval:
    """Median of ``x_i / y_i`` over pairs i with a 95 % percentile-bootstrap interval
    (`scipy.stats.bootstrap`, ``BOOTSTRAP_RESAMPLES`` resamples, seeded)."""
    from scipy import stats

    r = _finite([a / b if b > 0 else math.nan for a, b in zip(x, y, strict=True)])
    n = int(r.size)
    if n == 0:
        return Interval(math.nan, math.nan, math.nan, 0, "bootstrap")
    median = float(np.median(r))
    if n < 2 or float(r.max()) == float(r.min()):
        return Interval(median, math.nan, math.nan, n, "bootstrap")
    res = stats.bootstrap((r,), np.median, confidence_level=CONFIDENCE, n_resamples=BOOTSTRAP_RESAMPLES,
                          method="percentile", random_state=np.random.default_rng(seed))
    return Interval(median, float(res.confidence_interval.low), float(res.confidence_interval.high), n, "bootstrap")


def kendall_tau(a: Mapping[str, float], b: Mapping[str, float]) -> tuple[float, int]:
    """(Kendall's tau-b of the values of ``a`` and ``b`` over the keys both have, the number of such
    keys); NaN where fewer than two keys are shared or either side is constant."""
    from scipy import stats

    keys = [k for k in a if k in b and math.isfinite(a[k]) and math.isfinite(b[k])]
    if len(keys) < 2:
        return math.nan, len(keys)
    x, y = [a[k] for k in keys], [b[k] for k in keys]
    if len(set(x)) < 2 or len(set(y)) < 2:
        return math.nan, len(keys)
    return float(stats.kendalltau(x, y, variant="b").statistic), len(keys)


def _as_map(values: Mapping[int, float] | Sequence[float]) -> Mapping[int, float]:
    return values if isinstance(values, Mapping) else dict(enumerate(values))


__all__ = ["CONFIDENCE", "BOOTSTRAP_RESAMPLES", "Interval", "t_quantile", "t_interval", "paired_difference", "kendall_tau",
           "t_p_value", "holm",
           "paired_ratio", "bootstrap_median_ratio"]
