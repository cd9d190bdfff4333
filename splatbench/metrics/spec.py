"""How a report shows one metric: `MetricSpec` (the run kinds' reports, ``compare``)."""

from __future__ import annotations

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


__all__ = ["MetricSpec"]
