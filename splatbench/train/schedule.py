"""Schedules that scale with the run: absolute steps or graphdeco's proportions.

graphdeco-inria's 3DGS gives every schedule in steps of a 30,000-iteration run:
refinement from step 500 to 15,000 every 100, an opacity reset every 3,000, one SH
band more every 1,000, the position learning rate decaying over the whole run. A
600-iteration run that keeps those absolute numbers refines for the first time at
its last step, just before the final evaluation.

`TrainConfig.schedule` says how the step-valued fields are read:

``"scaled"`` (the default)
    Every schedule field is written in steps of graphdeco's 30,000-iteration run
    (`REFERENCE_ITERATIONS`) and multiplied by ``iterations / 30,000``: the defaults
    refine from 1/60 to 1/2 of the run, reset opacities every 1/10, raise the SH
    degree every 1/30. Positions round to the nearest step; intervals too, but never
    below 1. Which fields scale is each strategy's ``schedule_fields``, plus
    ``sh_interval``. ``refine_every`` does not scale: it is the number of views each
    gradient average is taken over (a sample size, not a place in the run), so a
    short run refines less often rather than on noisier statistics.
``"absolute"``
    The fields are steps, as written (graphdeco's numbers are then right only for a
    30,000-iteration run).

The position learning rate decays exponentially over the whole run in both forms
(graphdeco's ``position_lr_max_steps`` equals its 30,000 iterations).

**Fractions of the run.** Whatever ``schedule`` says, a step field of the strategy
named in its ``run_fraction_fields`` (refine start / stop / every, reset every) may
be written as a fraction of this run's iterations, a string ``"25%"`` or ``"1/4"``:
it becomes ``round(fraction x iterations)`` steps (a period at least 1) and is not
scaled again. So a one-at-a-time grid around the defaults reads as proportions at
any run length::

    [axes]
    strategy.refine_stop = ["25%", "50%", "75%"]
    strategy.reset_every = ["10%", "20%", 0]     # 0: never

Whatever the form, `check_final_window` rejects a run whose last topology change
(densify, prune, opacity reset, relocation) falls in the final 10 % of its steps, so
that the final evaluation always sees a model that has trained since its last change.

Example::

    scale_step(500, 600, "scaled")                 # 10
    scale_step(3000, 600, "scaled", interval=True)  # 60
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Any

from splatbench.errors import InputError
from splatbench.strategies.base import TopologyChange

#: Length of the run graphdeco's step numbers are written for.
REFERENCE_ITERATIONS = 30_000
#: The forms of `TrainConfig.schedule`.
SCHEDULES = ("scaled", "absolute")
#: Fraction of the run at the end in which no topology change may fall.
FINAL_FRACTION = 0.1


def scale_step(value: int, iterations: int, schedule: str, *, interval: bool = False) -> int:
    """``value`` (a step count) as the run uses it under ``schedule``.

    "absolute" returns ``value``; "scaled" returns ``value x iterations / 30,000``
    rounded half up, at least 1 when ``interval`` (a period must be a positive step;
    `scaled_strategy` leaves a period of 0, "never", alone).
    """
    if schedule == "absolute":
        return int(value)
    if schedule != "scaled":
        raise InputError(f"schedule: expected one of {', '.join(map(repr, SCHEDULES))}, got {schedule!r}")
    scaled = int(math.floor(value * iterations / REFERENCE_ITERATIONS + 0.5))
    return max(1, scaled) if interval else scaled


_PERCENT = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*%\s*$")
_RATIO = re.compile(r"^\s*(\d+)\s*/\s*(\d+)\s*$")


def parse_run_fraction(value: object, where: str) -> float | None:
    """The fraction of the run ``value`` names (``"25%"`` -> 0.25, ``"1/4"`` -> 0.25), or
    None when ``value`` is not a string. A string that is neither, or a fraction outside
    [0, 1], is a one-line `InputError` naming ``where``."""
    if not isinstance(value, str):
        return None
    m, r = _PERCENT.match(value), _RATIO.match(value)
    frac = float(m.group(1)) / 100.0 if m else (int(r.group(1)) / int(r.group(2)) if r and int(r.group(2)) else None)
    if frac is None or not 0.0 <= frac <= 1.0:
        raise InputError(f"{where}: expected steps (an integer) or a fraction of the run between 0 and 1 "
                         f"('25%' or '1/4'), got {value!r}")
    return frac


def resolve_run_fractions(fraction_fields: dict[str, bool], options: dict[str, Any], iterations: int
                          ) -> tuple[dict[str, Any], frozenset[str]]:
    """``options`` with each field of ``fraction_fields`` (name -> is-a-period) written as a
    fraction of the run (`parse_run_fraction`) replaced by ``round(fraction x iterations)``
    steps (a period at least 1), and the names so replaced. A fraction given for a field
    outside ``fraction_fields`` is left for the strategy to reject."""
    out, done = dict(options), set()
    for name, value in options.items():
        if name not in fraction_fields:
            continue
        frac = parse_run_fraction(value, f"strategy.{name}")
        if frac is None:
            continue
        steps = int(math.floor(frac * iterations + 0.5))
        out[name] = max(1, steps) if fraction_fields[name] else steps
        done.add(name)
    return out, frozenset(done)


def scaled_strategy(strategy, iterations: int, schedule: str, *, fixed: frozenset[str] = frozenset()):
    """A copy of ``strategy`` with its ``schedule_fields`` (name -> is-an-interval) in
    the steps of a run of ``iterations`` under ``schedule`` (unchanged when "absolute");
    the fields in ``fixed`` (already in run steps, e.g. given as fractions) stay as they are."""
    fields: dict[str, bool] = {k: v for k, v in strategy.schedule_fields.items()  # the Strategy protocol's
                               if k not in fixed}
    if schedule == "absolute" or not fields:
        scale_step(0, iterations, schedule)  # validates the name
        return strategy
    # a period of 0 means "never" (reset_every = 0) and stays 0
    return dataclasses.replace(strategy, **{name: scale_step(getattr(strategy, name), iterations, schedule,
                                                             interval=is_interval)
                                            for name, is_interval in fields.items()
                                            if not (is_interval and getattr(strategy, name) == 0)})


def final_window_start(iterations: int) -> int:
    """First step of the final 10 % of a run (at least the last step is in it)."""
    return iterations - max(1, math.ceil(FINAL_FRACTION * iterations))


def check_final_window(strategy, iterations: int, schedule: str) -> None:
    """Raise a one-line `InputError` when ``strategy`` (already in run steps) may change
    the topology in the final 10 % of ``iterations`` steps."""
    change: TopologyChange | None = strategy.last_topology_change(iterations)
    start = final_window_start(iterations)
    if change is None or change.step < start:
        return
    hint = ("use schedule='scaled' (graphdeco's proportions) or end the refine window earlier"
            if schedule == "absolute" else "end the refine window earlier (strategy.refine_stop)")
    raise InputError(f"strategy {strategy.name!r}: the last topology change, {change.what}, is at step {change.step}, "
                     f"in the final 10 % of {iterations} iterations (steps {start}..{iterations - 1}, {schedule} "
                     f"schedule), so the final evaluation would see a model that has not trained since; {hint}")



__all__ = ["REFERENCE_ITERATIONS", "SCHEDULES", "FINAL_FRACTION", "TopologyChange", "scale_step", "scaled_strategy",
           "final_window_start", "check_final_window", "parse_run_fraction", "resolve_run_fractions"]
