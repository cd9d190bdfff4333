"""What a run kind declares about its reports: metrics, findings rules, figure axes.

A kind's module builds one `KindReport` and passes it to its `RunKind` (``report=``),
so adding a kind touches that one file: the report code (``tables.py``,
``findings.py``, ``report.py``) asks `kind_report` and names no kind. A kind without
a `KindReport` (or a results folder of an unknown kind) gets every numeric metric and
a comparison of the first one.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class MetricSpec:
    """How a report shows one metric (``metric.<name>`` in the table)."""

    name: str          # metric name, without the "metric." prefix
    label: str         # column heading
    fmt: str           # format spec of one value, e.g. ".2f"
    unit: str = ""     # unit written after differences ("dB", "ms"; "" for none)
    better: str = ""   # "higher", "lower" or "" (no preferred direction)
    interval: bool = True  # False: the table shows the mean alone (a fraction, a count of its own)


@dataclass(frozen=True)
class Comparison:
    """How one metric of a row is set against the reference row.

    how: "diff", "ratio" or "mean" (module doc); null: the value that means "no
    difference" for a "mean" comparison (None: no significance statement).
    """

    metric: str
    how: str
    null: float | None = None


@dataclass(frozen=True)
class FindingRules:
    """A kind's primary metric (best-of) and its comparisons."""

    primary: str
    comparisons: tuple[Comparison, ...]


@dataclass(frozen=True)
class TimeQuality:
    """The time-against-quality (Pareto) figure: its two metrics, file stem and title."""

    time: str      # metric on the x axis (e.g. "train_seconds")
    quality: str   # metric on the y axis (e.g. "test_psnr")
    stem: str      # figure file stem under figures/
    title: str


@dataclass(frozen=True)
class KindReport:
    """A kind's report declarations.

    metrics: the table's metrics, in column order; rules: the findings' primary metric
    and comparisons (None: no findings); time_quality: the Pareto figure (None: none);
    meanings: metric name -> meaning (the report's "Metrics" section); axis_notes:
    ``fn(axis_table, runs, scenes) -> (lines, claims)`` appended to each axis finding;
    run_findings: ``(name, fn(runs) -> Finding | None)`` findings over all runs;
    timed: metrics that are times: a run whose ``metric.time_loaded`` is 1 (timed while
    others loaded the machine) is left out of their comparisons only; metric_notes:
    ``fn(runs) -> lines`` appended to the report's "Metrics" section (e.g. which LPIPS).
    """

    metrics: tuple[MetricSpec, ...]
    rules: FindingRules | None = None
    time_quality: TimeQuality | None = None
    meanings: Mapping[str, str] = field(default_factory=dict)
    axis_notes: tuple[Callable[..., tuple[list, list]], ...] = ()
    run_findings: tuple[tuple[str, Callable[[Any], Any]], ...] = ()
    timed: tuple[str, ...] = ()
    metric_notes: tuple[Callable[[Any], list[str]], ...] = ()


def kind_report(kind: str) -> KindReport | None:
    """The `KindReport` of ``kind`` (None for a kind without one or an unknown kind)."""
    from splatbench.errors import InputError
    from splatbench.experiments.kinds import get_kind

    try:
        return get_kind(kind).report
    except InputError:
        return None


__all__ = ["MetricSpec", "Comparison", "FindingRules", "TimeQuality", "KindReport", "kind_report"]
