"""The reports' statistics (issue 11 §2) on numbers that can be checked by hand."""

from __future__ import annotations

import math

import pytest
from scipy import stats as sps

from splatbench.metrics.stats import (bootstrap_median_ratio, paired_difference, paired_ratio, t_interval,
                                      t_quantile)
from splatbench.reports.tables import Stat


def test_t_interval_of_three_values():
    # the table value of t_{0.975, 2} is 4.303 (two-sided 95 %, 2 degrees of freedom)
    assert t_quantile(3) == pytest.approx(4.30265272974946, rel=1e-12)
    iv = t_interval([1.0, 2.0, 3.0])           # mean 2, s = 1, half-width 4.3027 / sqrt(3) = 2.4841
    assert iv.estimate == 2.0 and iv.n == 3 and iv.method == "t"
    assert (iv.low, iv.high) == pytest.approx((2.0 - 2.484138, 2.0 + 2.484138), abs=1e-6)
    assert iv.excludes(5.0) and not iv.excludes(0.0)
    # the same interval as scipy's own
    lo, hi = sps.t.interval(0.95, 2, loc=2.0, scale=1.0 / math.sqrt(3))
    assert (iv.low, iv.high) == pytest.approx((lo, hi), rel=1e-12)
    assert Stat(2.0, 1.0, 3).text(".2f") == "2.00 ± 2.48"


def test_one_value_has_no_interval():
    iv = t_interval([7.5, math.nan])             # NaN is not a value
    assert iv.n == 1 and iv.estimate == 7.5 and not iv.defined and math.isnan(iv.half_width)
    assert not iv.excludes(0.0)                 # never "significant" without an interval
    assert Stat(7.5, math.nan, 1).text(".1f") == "7.5"
    assert t_interval([]).n == 0


def test_paired_difference_pairs_seeds():
    a = {0: 10.0, 1: 12.0, 2: 14.0, 3: 99.0}    # seed 3 has no partner: left out
    b = {0: 11.0, 1: 13.1, 2: 14.9}             # differences 1.0, 1.1, 0.9: mean 1, s = 0.1
    iv = paired_difference(a, b)
    assert iv.n == 3 and iv.estimate == pytest.approx(1.0)
    assert iv.half_width == pytest.approx(4.30265272974946 * 0.1 / math.sqrt(3), rel=1e-9)   # 0.2484
    assert iv.excludes(0.0)
    # the unpaired means (12 and 13) differ by the same 1.0, but spread 2 per row: pairing is what resolves it
    noisy = paired_difference([10.0, 12.0, 14.0], [11.0, 13.5, 14.5])     # differences 1, 1.5, 0.5: s = 0.5
    assert noisy.estimate == pytest.approx(1.0) and not noisy.excludes(0.0)


def test_paired_ratio_is_geometric():
    iv = paired_ratio([1.0, 2.0, 4.0], [2.0, 4.0, 8.0])      # every ratio 2: no spread
    assert iv.estimate == pytest.approx(2.0) and iv.low == pytest.approx(2.0) and iv.excludes(1.0)
    iv = paired_ratio([1.0, 1.0], [2.0, 0.5])                # log ratios +-log 2: geometric mean 1
    assert iv.estimate == pytest.approx(1.0) and not iv.excludes(1.0)


def test_bootstrap_median_ratio():
    same = bootstrap_median_ratio([2.0] * 7, [1.0] * 7)
    assert same.estimate == 2.0 and same.n == 7 and not same.defined     # no spread: no interval
    x, y = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0], [1.0] * 7
    iv = bootstrap_median_ratio(x, y)
    assert iv.estimate == 4.0 and iv.method == "bootstrap"
    # a resampled median of 7 values is one of them: the percentile ends are sample values
    assert iv.low in x and iv.high in x and iv.low <= 4.0 <= iv.high and iv.low < iv.high
    assert bootstrap_median_ratio(x, y) == iv                            # seeded: a rebuilt report agrees
    with pytest.raises(ValueError):
        bootstrap_median_ratio([1.0, 2.0], [1.0])
