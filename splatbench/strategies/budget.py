"""Budget-driven densification after Taming 3DGS (Mallick et al., SIGGRAPH Asia 2024,
"Taming 3DGS: High-Quality Radiance Fields with Limited Resources").

3DGS's adaptive density control decides *which* Gaussians may grow (the same
candidates: averaged screen-space gradient >= ``grad_threshold``, clone when small,
split when large); Taming 3DGS decides *how many* do, so that the model ends at a
budget chosen in advance. Its rule (humansensinglab/taming-3dgs
``utils/taming_utils.py``, ``scene/gaussian_model.py`` ``densify_with_score``):

1. **Target count per refinement** (the paper's Eq. 2, ``get_count_array``): with
   N0 Gaussians at the start, a budget B and S refinements, the k-th refinement aims
   at f(k) = a k^2 + b k + N0 with b = 2 (B - N0) / S and a = -(B - N0) / S^2: a
   concave curve that grows twice as fast as a straight line at first and flattens
   into B at k = S.
2. **How many grow**: headroom = min(f(k), N + candidates) - N, shared between the
   clone and the split candidates in proportion to their numbers.
3. **Which grow**: that many of each group drawn without replacement with probability
   proportional to a per-Gaussian score (``torch.multinomial``).
4. Pruning and opacity resets as 3DGS (`DefaultStrategy`).

The budget is ``budget`` Gaussians (``budget_mode = "final_count"``) or ``budget`` x
the initial count (``"multiplier"``; taming-3dgs's ``--mode`` and ``--budget``).

Deliberate differences from taming-3dgs, and why:

- **Score.** Taming's score sums, over 10 sampled training views, per-Gaussian terms
  (gradient 25, opacity 100, depth 5, screen radius 10, volume 25) and pixel terms
  weighted by an edge and loss map (distance 50, loss 10, count 0.1, blending 50),
  each normalised by its median, times the view's photometric loss x 50
  (``compute_gaussian_score``; coefficients from its ``train.py``). The pixel terms
  and depth need extra renders with per-Gaussian pixel accumulators that this
  rasterizer does not have, so the score here keeps the per-Gaussian terms it has,
  with Taming's coefficients and median normalisation: averaged gradient x
  ``score_grad``, opacity x ``score_opacity``, largest screen radius since the last
  refinement x ``score_radius``, volume (product of scales) x ``score_volume``. (The
  per-view photometric factor scales every Gaussian alike and does not change the
  draw.)
- **Schedule index.** taming-3dgs takes S = (densify_until - densify_from) //
  interval and reads f at k + 1 of a list for k = 0..S-1, which can stop short of B;
  here S is the number of refinements this schedule really makes and the k-th
  (1-based) refinement aims at f(k), so the last one aims at B exactly.
- Randomness comes from the state's seeded generator (determinism).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import torch

from splatbench.errors import InputError
from splatbench.strategies.base import Params
from splatbench.strategies.default import DefaultState, DefaultStrategy

#: Values of `BudgetStrategy.budget_mode`.
BUDGET_MODES = ("multiplier", "final_count")


def count_schedule(start: int, budget: int, steps: int) -> list[int]:
    """Taming 3DGS's Eq. 2: the target count after each of ``steps`` refinements
    (k = 1..steps), from ``start`` Gaussians to ``budget`` at the last.

    Example: ``count_schedule(100, 500, 4)`` -> ``[275, 400, 475, 500]``.
    """
    if steps < 1:
        return []
    b = 2.0 * (budget - start) / steps
    a = -(budget - start) / (steps * steps)
    return [int(math.floor(a * k * k + b * k + start + 1e-9)) for k in range(1, steps + 1)]


def refinement_count(refine_start: int, refine_stop: int, refine_every: int) -> int:
    """How many refinements 3DGS's schedule makes: completed iterations ``it`` with
    ``refine_start < it < refine_stop`` and ``it % refine_every == 0``."""
    hi = refine_stop - 1
    if hi <= refine_start:
        return 0
    return hi // refine_every - refine_start // refine_every


def median_normalized(weight: float, values: torch.Tensor) -> torch.Tensor:
    """Taming's ``normalize``: ``weight x v / median(v[v > 0])`` where v > 0, else 0."""
    values = torch.nan_to_num(values.float(), nan=0.0)
    out = torch.zeros_like(values)
    pos = values > 0
    if bool(pos.any()):
        out[pos] = weight * values[pos] / values[pos].median()
    return out


@dataclass
class BudgetState(DefaultState):
    """`DefaultState` plus the count schedule (filled at the first refinement)."""

    targets: list[int] = field(default_factory=list)  # target count after refinement k = 1..S
    refinements: int = 0                              # refinements made so far
    # (k, target, count + candidates) of each refinement whose candidates could not meet its target
    short: list[tuple[int, int, int]] = field(default_factory=list)
    initial: int = 0                                  # Gaussians at the start


@dataclass(frozen=True)
class BudgetStrategy(DefaultStrategy):
    """3DGS adaptive density control that grows toward a budget (Taming 3DGS).

    Every field of `DefaultStrategy` keeps its meaning and default (``grad_threshold``
    2e-4 is Taming's fixed qualifier); the budget fields follow taming-3dgs:
    ``budget`` 20 and ``budget_mode`` "multiplier" are its command-line defaults
    (``--budget 20 --mode multiplier``); the score weights ``score_grad`` 25,
    ``score_opacity`` 100, ``score_radius`` 10 and ``score_volume`` 25 are its
    ``score_coefficients`` (``grad_importance``, ``opac_importance``, ``radii_importance``,
    ``scale_importance``, in its ``train.py``).
    """

    name: ClassVar[str] = "budget"  # type: ignore[misc]
    #: Candidates and the score read the averaged screen-space gradient, as 3DGS's do.
    reads_mean_gradients: ClassVar[bool] = True

    budget: float = 20.0              # final count, or multiple of the initial count (budget_mode)
    budget_mode: str = "multiplier"   # "multiplier" (budget x initial count) or "final_count"
    score_grad: float = 25.0          # weight of the averaged gradient (taming grad_importance)
    score_opacity: float = 100.0      # weight of the opacity (opac_importance)
    score_radius: float = 10.0        # weight of the largest screen radius (radii_importance)
    score_volume: float = 25.0        # weight of the product of the scales (scale_importance)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.budget_mode not in BUDGET_MODES:
            raise InputError(f"BudgetStrategy.budget_mode: expected one of {', '.join(map(repr, BUDGET_MODES))}, "
                             f"got {self.budget_mode!r}")
        ok = isinstance(self.budget, (int, float)) and not isinstance(self.budget, bool) and math.isfinite(self.budget)
        if not ok or self.budget <= 0 or (self.budget_mode == "final_count" and self.budget != int(self.budget)):
            what = "a whole number of Gaussians" if self.budget_mode == "final_count" else "a multiple > 0"
            raise InputError(f"BudgetStrategy.budget: expected {what}, got {self.budget!r}")
        for f in ("score_grad", "score_opacity", "score_radius", "score_volume"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0 or not math.isfinite(v):
                raise InputError(f"BudgetStrategy.{f}: expected a finite number >= 0, got {v!r}")
        if self.absgrad:
            raise InputError("BudgetStrategy.absgrad: not supported (Taming 3DGS scores the 3DGS gradient)")

    def final_count(self, initial: int) -> int:
        """The budget in Gaussians for a model that starts with ``initial``."""
        return int(self.budget) if self.budget_mode == "final_count" else int(round(self.budget * initial))

    def initialize_state(self, params: Params) -> BudgetState:
        base = super().initialize_state(params)
        state = BudgetState(**vars(base))
        n0 = params["means"].shape[0]
        steps = refinement_count(self.refine_start, self.refine_stop, self.refine_every)
        state.targets = count_schedule(n0, self.final_count(n0), steps)
        state.initial = n0
        return state

    def outcome_note(self, state: BudgetState) -> str | None:
        """How the run ended against its budget, when not at it:

        - a warning when the budget is below the initial count (Taming grows toward a budget
          and never prunes down to one);
        - a warning when the last refinement had too few candidates to meet its target
          (Taming grows only Gaussians whose averaged gradient passes ``grad_threshold``);
        - a plain note when the last refinement met its target and then pruned below it in
          the same step (Taming prunes right after growing), or when early_stop ended the
          schedule before its last refinement;

        None when the model ended at its budget, or the schedule made no refinement."""
        if not state.targets:
            return None
        budget = state.targets[-1]
        end = state.last.num_gaussians if state.last is not None else state.initial
        mode = (f"; budget_mode is 'multiplier', so the budget is {self.budget:g} x the initial {state.initial:,}: "
                f"for a number of Gaussians set strategy.budget_mode=final_count"
                if self.budget_mode == "multiplier" else "")
        if budget < state.initial:
            return (f"warning: strategy 'budget': its budget of {budget:,} is below the initial {state.initial:,} "
                    f"Gaussians, and Taming 3DGS grows toward a budget but never prunes down to one, so the "
                    f"model ended at {end:,}; give a budget above the initial count, or start from fewer points{mode}")
        if state.short and state.short[-1][0] == state.refinements:
            _, target, reach = state.short[-1]
            return (f"warning: strategy 'budget' ended at {end:,} Gaussians, below its budget of {budget:,}: "
                    f"at {len(state.short)} of {state.refinements} refinements fewer Gaussians passed grad_threshold "
                    f"{self.grad_threshold:g} than its count schedule asked for (the last: {reach:,} within reach of "
                    f"a target of {target:,}); Taming 3DGS grows only those, so a smaller budget or a lower "
                    f"strategy.grad_threshold meets it{mode}")
        if end < budget and state.refinements < len(state.targets):
            return (f"strategy 'budget' ended at {end:,} Gaussians, below its budget of {budget:,}: it made "
                    f"{state.refinements} of the {len(state.targets)} refinements its count schedule plans "
                    + ("(early_stop ended densification)" if self.early_stop else
                       "(the run ended before the schedule's last refinement)"))
        if state.last is not None and end < budget and state.last.pruned > 0:
            # (without pruning the last refinement ends at most 1 short: each of the clone and split
            # shares of the headroom is floored, as in taming-3dgs; no note for that)
            return (f"strategy 'budget' ended at {end:,} Gaussians, {budget - end:,} below its budget of {budget:,}: "
                    f"its last refinement grew to {end + state.last.pruned:,} and pruned {state.last.pruned:,} "
                    f"(opacity below prune_opacity, or too large) in the same step, as Taming 3DGS does")
        return None

    def score(self, params: Params, state: DefaultState, avg_grad: torch.Tensor) -> torch.Tensor:
        """The per-Gaussian score [N] the draw is proportional to (module docstring)."""
        opacity = torch.sigmoid(params["opacity_logits"].detach()).to(avg_grad.device)
        volume = torch.exp(params["log_scales"].detach().sum(dim=-1)).to(avg_grad.device)
        return (median_normalized(self.score_grad, avg_grad) + median_normalized(self.score_opacity, opacity)
                + median_normalized(self.score_radius, state.max_radii)
                + median_normalized(self.score_volume, volume))

    def select(self, params: Params, state: BudgetState, scene_extent: float  # type: ignore[override]
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """Taming's rule: the target of this refinement, the headroom shared between clone
        and split candidates, each group drawn by score without replacement."""
        avg, clone_ok, split_ok = self.candidates(params, state, scene_extent)
        n = avg.shape[0]
        state.refinements += 1
        if not state.targets:
            return torch.zeros_like(clone_ok), torch.zeros_like(split_ok)
        target = state.targets[min(state.refinements, len(state.targets)) - 1]
        n_clone, n_split = int(clone_ok.sum()), int(split_ok.sum())
        reach = n + n_clone + n_split  # the most this refinement can grow to
        if reach < target:
            state.short.append((state.refinements, target, reach))
        headroom = max(0, min(target, reach) - n)
        total = max(1, n_clone + n_split)
        score = self.score(params, state, avg)
        picks = []
        for ok, count in ((clone_ok, headroom * n_clone // total), (split_ok, headroom * n_split // total)):
            chosen = torch.zeros_like(ok)
            if count > 0:
                # candidates with a zero score stay drawable (after every positive one), as a draw
                # without replacement needs count non-zero weights
                weights = torch.where(ok, score.clamp_min(0) + 1e-12, torch.zeros_like(score))
                chosen[torch.multinomial(weights, count, replacement=False, generator=state.generator)] = True
            picks.append(chosen)
        return picks[0], picks[1]


__all__ = ["BUDGET_MODES", "BudgetState", "BudgetStrategy", "count_schedule", "median_normalized",
           "refinement_count"]
