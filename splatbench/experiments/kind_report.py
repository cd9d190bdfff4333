"""What a run kind declares about its reports, as plain data: metrics, findings rules,
the Pareto figures of a cost (time, the number of Gaussians) against quality, the
metrics' meanings.

A kind's module builds one `KindReport` and passes it to its `RunKind` (``report=``),
so adding a kind touches that one file: the report code (`splatbench.reports`) reads
it and names no kind. A kind without a `KindReport` (or a results folder of an unknown
kind) gets every numeric metric and a comparison of the first one. Findings that need
code of their own register with the reports by kind name (`splatbench.reports.notes`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from splatbench.metrics.spec import MetricSpec


@dataclass(frozen=True)
class Comparison:
    """How one metric of a row is set against the reference row.

    how: "diff", "ratio" or "mean" (`splatbench.reports.findings`); null: the value that
    means "no difference" for a "mean" comparison (None: no significance statement);
    min_effect: the smallest difference that matters in practice, in the comparison's
    units (a difference in the metric's unit for "diff" and "mean"; a relative change for
    "ratio": 0.05 means ×1.05 or ×1/1.05). A significant difference smaller than it reads
    "no practical difference"; None: no practical threshold (significance alone). An
    experiment file may set its own (``[report] min_effect = { test_psnr = 0.2 }``).
    """

    metric: str
    how: str
    null: float | None = None
    min_effect: float | None = None


@dataclass(frozen=True)
class FindingRules:
    """A kind's primary metric (best-of) and its comparisons.

    size: a metric counting the model's size (the train kind's ``num_gaussians``; None: the kind
    records none): the best-of names a cell only when it is not larger than the runner-up by more
    than that metric's comparison's minimum effect (docs/reports.md, "Best")."""

    primary: str
    comparisons: tuple[Comparison, ...]
    size: str | None = None


@dataclass(frozen=True)
class Tradeoff:
    """A Pareto figure: a cost metric across (lower is better), a quality metric up, one
    point per grid cell; the report draws it when the results hold both metrics.

    cheaper: what a lower cost means, in words ("faster", "smaller"); order: how the
    front's cells are listed, in words ("fastest first").
    """

    cost: str      # metric on the x axis (e.g. "train_seconds", "num_gaussians")
    quality: str   # metric on the y axis (e.g. "test_psnr")
    stem: str      # figure file stem under figures/
    title: str
    cheaper: str = "faster"
    order: str = "fastest first"


@dataclass(frozen=True)
class SettlingCurves:
    """The curves (keys of a run's ``curves``) whose last quarter decides whether a cell had
    settled (`splatbench.reports.settling`): the test curve of ``metric`` (steps and values)
    and, where recorded, the training-view curve of the same quantity (overfitting)."""

    metric: str
    test_step: str
    test_value: str
    train_step: str = ""
    train_value: str = ""


@dataclass(frozen=True)
class KindReport:
    """A kind's report declarations.

    metrics: the table's metrics, in column order; rules: the findings' primary metric
    and comparisons (None: no findings); tradeoffs: the Pareto figures, in report order;
    meanings: metric name -> meaning (the report's "Metrics" section); timed: metrics that
    are times: a run whose ``metric.time_loaded`` is 1 (timed while other processes
    loaded the machine) is left out of their comparisons only.
    """

    metrics: tuple[MetricSpec, ...]
    rules: FindingRules | None = None
    tradeoffs: tuple[Tradeoff, ...] = ()
    meanings: Mapping[str, str] = field(default_factory=dict)
    timed: tuple[str, ...] = ()
    settling: SettlingCurves | None = None
    confounds: tuple[MetricSpec, ...] = ()


__all__ = ["Comparison", "FindingRules", "Tradeoff", "SettlingCurves", "KindReport"]
