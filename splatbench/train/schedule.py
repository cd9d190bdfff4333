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
    rounded half up, at least 1 when ``interval`` (a period must be a positive step).
    """
    if schedule == "absolute":
        return int(value)
    if schedule != "scaled":
        raise InputError(f"schedule: expected one of {', '.join(map(repr, SCHEDULES))}, got {schedule!r}")
    scaled = int(math.floor(value * iterations / REFERENCE_ITERATIONS + 0.5))
    return max(1, scaled) if interval else scaled


def scaled_strategy(strategy, iterations: int, schedule: str):
    """A copy of ``strategy`` with its ``schedule_fields`` (name -> is-an-interval) in
    the steps of a run of ``iterations`` under ``schedule`` (unchanged when "absolute")."""
    fields: dict[str, bool] = dict(strategy.schedule_fields)  # declared by the Strategy protocol
    if schedule == "absolute" or not fields:
        scale_step(0, iterations, schedule)  # validates the name
        return strategy
    return dataclasses.replace(strategy, **{name: scale_step(getattr(strategy, name), iterations, schedule,
                                                             interval=is_interval)
                                            for name, is_interval in fields.items()})


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
            if schedule == "absolute" else "end the refine window earlier (strategy_options.refine_stop)")
    raise InputError(f"strategy {strategy.name!r}: the last topology change, {change.what}, is at step {change.step}, "
                     f"in the final 10 % of {iterations} iterations (steps {start}..{iterations - 1}, {schedule} "
                     f"schedule), so the final evaluation would see a model that has not trained since; {hint}")



__all__ = ["REFERENCE_ITERATIONS", "SCHEDULES", "FINAL_FRACTION", "TopologyChange", "scale_step", "scaled_strategy",
           "final_window_start", "check_final_window"]
