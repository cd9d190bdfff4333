"""The densification-strategy interface (after gsplat's `strategy/base.py`).

Every strategy has the *same typed signature*: a dataclass of hyperparameters, an
explicit state object it creates, and hooks before and after the backward pass.
Everything a hook may need (step, learning rate, screen-space gradients, scene
extent) arrives in one `StepContext`, so the trainer never needs to know which
strategy it holds. Strategies edit parameters and Adam moments together through
`splatbench.strategies.ops`.

Parameter groups (`Params`, torch leaf tensors with requires_grad):
    means [N, 3], log_scales [N, 3], quats [N, 4], opacity_logits [N],
    sh_dc [N, 1, 3], sh_rest [N, K-1, 3]
`Optimizers` maps each group name to its own Adam: the trainer's
`splatbench.train.adam.FusedAdam` or a ``torch.optim.Adam``; the strategies read and
replace only its ``param_groups`` and ``state`` (`AdamLike`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, NamedTuple, Protocol

import torch

from splatbench.errors import InputError
from splatbench.raster.torch_bridge import RasterInfo

PARAM_GROUPS = ("means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest")
Params = dict[str, torch.Tensor]


class AdamLike(Protocol):
    """What strategies use of an optimizer: one group holding its parameter, and the
    per-tensor state (``exp_avg``, ``exp_avg_sq``, ``step``) keyed by that tensor."""

    param_groups: list[dict]
    state: dict


Optimizers = dict[str, AdamLike]


@dataclass(frozen=True)
class StepContext:
    """What a strategy hook may read about the current training step.

    step: iteration index (0-based); info: the rasterizer's `RasterInfo` of this
    step (``means2d_grad`` / ``means2d_absgrad`` are set only after backward);
    scene_extent: radius of the training cameras (3DGS's "cameras_extent");
    means_lr: current learning rate of the means (MCMC scales its noise by it);
    loss: the scalar training loss of this step (for early stopping).
    """

    step: int
    info: RasterInfo
    scene_extent: float
    means_lr: float
    loss: float


class TopologyChange(NamedTuple):
    """The last step at which a strategy may change the set of Gaussians or reset them."""

    step: int   # 0-based step (the ``ctx.step`` of the hook that makes it)
    what: str   # what happens there and which settings put it there, e.g.
                # "refinement (refine window 500..15000, every 100)"


@dataclass(frozen=True)
class TopologyCounts:
    """What a strategy did to the set of Gaussians over a run, besides what its settings name:
    what a report names when a setting also changed these (docs/reports.md, "Confounds").

    refinements: refinement steps made (densify / prune, or MCMC relocate / add);
    opacity_resets: opacity resets; cloned / split / pruned: totals over the refinements
    (split counts the Gaussians replaced by two children); pruned_size: of ``pruned``, those
    removed for their size (none when size pruning is off: ``reset_every = 0`` turns it off);
    relocated / added: MCMC's totals.
    """

    refinements: int = 0
    opacity_resets: int = 0
    cloned: int = 0
    split: int = 0
    pruned: int = 0
    pruned_size: int = 0
    relocated: int = 0
    added: int = 0


def refines_at(it: int, refine_start: int, refine_stop: int, refine_every: int) -> bool:
    """Whether 3DGS's schedule refines after ``it`` completed iterations: ``refine_start < it <
    refine_stop`` and ``it % refine_every == 0`` (graphdeco-inria's densify_from_iter, densify_until_iter,
    densification_interval; False for a period < 1). The one test the strategies' `post_backward` and
    the reports (`splatbench.experiments.train_report.refined_at_end`) share."""
    return refine_every >= 1 and refine_start < it < refine_stop and it % refine_every == 0


def last_multiple(period: int, lo: int, hi: int) -> int | None:
    """The largest multiple of ``period`` in ``(lo, hi]`` (None if there is none)."""
    if hi <= lo or period < 1:
        return None
    m = (hi // period) * period
    return m if m > lo else None


def multiples(period: int, lo: int, hi: int) -> int:
    """How many multiples of ``period`` lie in ``(lo, hi]`` (0 for a period < 1)."""
    if period < 1 or hi <= lo:
        return 0
    return hi // period - lo // period


def check_fields(obj, positive_ints: tuple[str, ...], nonneg: tuple[str, ...]) -> None:
    """One-line `InputError` naming ``Class.field`` unless each ``positive_ints`` field is an
    int >= 1 and each ``nonneg`` field a finite number >= 0 (strategies' ``__post_init__``)."""
    name = type(obj).__name__
    for f in positive_ints:
        v = getattr(obj, f)
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise InputError(f"{name}.{f}: expected a positive integer, got {v!r}")
    for f in nonneg:
        v = getattr(obj, f)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0 or not math.isfinite(v):
            raise InputError(f"{name}.{f}: expected a finite number >= 0, got {v!r}")


class Strategy(Protocol):
    """One densification strategy. Implementations are small frozen dataclasses."""

    name: str
    #: Step-valued fields that `TrainConfig.schedule = "scaled"` multiplies by
    #: iterations / 30,000 (name -> True for a period, kept >= 1); see splatbench.train.schedule.
    schedule_fields: ClassVar[dict[str, bool]]
    #: Step-valued fields that `TrainConfig.strategy` (its options) may also give as a fraction of
    #: the run ("25%" or "1/4", name -> True for a period, kept >= 1); see splatbench.train.schedule.
    run_fraction_fields: ClassVar[dict[str, bool]]
    #: The initial opacity of the reference implementation (`TrainConfig.init.opacity = "auto"`).
    initial_opacity: ClassVar[float]
    #: Whether `post_backward` reads ``info.means2d_absgrad`` (AbsGS): the trainer
    #: rasterizes with ``absgrad=strategy.absgrad`` (the extra accumulation costs time).
    absgrad: bool
    #: Whether the hooks read the screen-space mean gradients (``info.means2d_grad`` or
    #: ``info.means2d_absgrad``), as graphdeco's adaptive density control does. Frozen means
    #: (``optim.lr_means = 0``) have none, so `TrainConfig` refuses them with such a strategy.
    reads_mean_gradients: ClassVar[bool]

    def last_topology_change(self, iterations: int) -> TopologyChange | None:
        """The last step of a run of ``iterations`` steps at which this strategy may
        densify, prune, reset opacities or relocate (None: never). Read by the config's
        check that no change falls in the final 10 % of the run."""
        ...

    def schedule_note(self, iterations: int, advice: str | None = None) -> str | None:
        """A warning when this strategy, as scaled to a run of ``iterations`` steps, never does what
        its name says (e.g. no refinement step falls in its refine window); None when it does.
        ``advice``: what to do about it instead of the strategy's own (a named protocol fixes
        the schedule, so only its full length keeps it). Optional, as is ``advice``: the
        trainer reads it only where a strategy has it, and passes ``advice`` only where the
        method takes it."""
        ...

    def outcome_note(self, state: object) -> str | None:
        """A warning ("warning: ..."), read once a run ends, when this strategy did not do what its
        settings ask (e.g. a budget strategy ended below its budget), or a note (no such prefix: the run
        records it among its notes) of how it met them; None when there is nothing to say. Optional,
        as `schedule_note`."""
        ...

    def initialize_state(self, params: Params) -> object:
        """A fresh state object for ``params`` (e.g. gradient accumulators)."""
        ...

    def regularization(self, params: Params, step: int) -> torch.Tensor | float:
        """Extra loss terms (MCMC's opacity and scale regularisers); 0 for most."""
        ...

    def pre_backward(self, params: Params, optimizers: Optimizers, state: object, ctx: StepContext) -> None:
        """Called after the forward pass, before ``loss.backward()``."""
        ...

    def post_backward(self, params: Params, optimizers: Optimizers, state: object, ctx: StepContext) -> None:
        """Called after ``loss.backward()`` and ``optimizer.step()``: accumulate
        statistics and densify / prune / relocate in place."""
        ...


#: What `no_refinement_note` advises by default: the run's own schedule may change.
REFINE_ADVICE = 'give strategy.refine_every a smaller value or a fraction of the run ("5%"), or train longer'


def no_refinement_note(name: str, refine_every: int, refine_start: int, refine_stop: int,
                       iterations: int, advice: str | None = None) -> str | None:
    """`Strategy.schedule_note` of a strategy that refines every ``refine_every`` steps after
    ``refine_start`` and before ``refine_stop``: a warning when no such step falls in a run of
    ``iterations`` steps, else None. ``advice``: the fix it ends with (default
    `REFINE_ADVICE`; a named protocol gives its own, which keeps the protocol)."""
    if last_multiple(refine_every, refine_start, min(iterations, refine_stop - 1)) is not None:
        return None
    return (f"warning: strategy {name!r} never refines in this run: no multiple of refine_every {refine_every} "
            f"falls in its refine window, steps {refine_start} to {refine_stop - 1}, of {iterations} iterations; "
            f"{advice or REFINE_ADVICE}")

