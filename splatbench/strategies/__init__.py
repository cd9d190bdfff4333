"""Densification strategies, one small frozen dataclass each, all with the
`splatbench.strategies.base.Strategy` interface.

    strategy = make_strategy("mcmc", cap_max=50_000)
    state = strategy.initialize_state(params)
    # per step: rasterize(..., absgrad=strategy.absgrad); strategy.pre_backward(...);
    # (loss + strategy.regularization(params, step)).backward(); optimizer steps;
    # strategy.post_backward(params, optimizers, state, ctx)

Names: "none", "default" (3DGS adaptive density control; ``revised_opacity = true``
gives split children the revised opacity of Rota Bulo et al.), "absgrad" (the same with
AbsGS's gradient and threshold 8e-4), "mcmc" (3DGS-MCMC), "budget" (3DGS's candidates,
grown toward a final count as Taming 3DGS does).
"""

from __future__ import annotations

import dataclasses

from splatbench.guards import dataclass_from_mapping
from splatbench.errors import InputError
from splatbench.strategies.base import (PARAM_GROUPS, Optimizers, Params, StepContext, Strategy, TopologyChange,
                                       TopologyCounts, refines_at)
from splatbench.strategies.budget import BudgetState, BudgetStrategy
from splatbench.strategies.default import DefaultState, DefaultStrategy, RefineStats
from splatbench.strategies.mcmc import MCMCState, MCMCStats, MCMCStrategy
from splatbench.strategies.none import NoneStrategy

# name -> (class, preset fields the overrides apply on top of)
STRATEGIES: dict[str, tuple[type, dict[str, object]]] = {
    "none": (NoneStrategy, {}),
    "default": (DefaultStrategy, {}),
    "absgrad": (DefaultStrategy, {"absgrad": True, "grad_threshold": 8e-4}),
    "mcmc": (MCMCStrategy, {}),
    "budget": (BudgetStrategy, {}),
}


def strategy_fields(name: str) -> tuple[str, ...]:
    """The field names ``make_strategy(name, ...)`` accepts."""
    cls, _ = _lookup(name)
    return tuple(f.name for f in dataclasses.fields(cls))


def make_strategy(name: str, **overrides) -> Strategy:
    """The strategy registered as ``name`` with ``overrides`` applied to its fields.

    Raises:
        InputError: (one line) for an unknown name, an unknown field
            (``strategy.KEY: unknown key (did you mean ...)``), or a bad value.
    """
    cls, preset = _lookup(name)
    return dataclass_from_mapping(cls, overrides, base=preset, prefix="strategy.",
                                  source=f"strategy {name!r}")


def topology_counts(state: object) -> TopologyCounts:
    """What the strategy whose state is ``state`` did to the Gaussians so far (`TopologyCounts`):
    the refinement histories of `DefaultState` (and `BudgetState`) and `MCMCState`, the opacity
    resets; all zero for the `none` strategy (no state)."""
    if isinstance(state, DefaultState):
        h = state.history
        return TopologyCounts(refinements=len(h), opacity_resets=int(getattr(state, "resets", 0)),
                              cloned=sum(r.cloned for r in h), split=sum(r.split for r in h),
                              pruned=sum(r.pruned for r in h), pruned_size=sum(r.pruned_size for r in h))
    if isinstance(state, MCMCState):
        h = state.history
        return TopologyCounts(refinements=len(h), relocated=sum(r.relocated for r in h),
                              added=sum(r.added for r in h))
    return TopologyCounts()


def planned_counts(strategy: Strategy, iterations: int) -> TopologyCounts:
    """The refinements and opacity resets ``strategy``'s schedule makes in a run of
    ``iterations`` steps (its optional ``planned_counts``; none for a strategy without one)."""
    planned = getattr(strategy, "planned_counts", None)
    return planned(iterations) if planned is not None else TopologyCounts()


def _lookup(name: str) -> tuple[type, dict[str, object]]:
    if name not in STRATEGIES:
        raise InputError(f"strategy: unknown name {name!r} (expected one of: {', '.join(STRATEGIES)})")
    return STRATEGIES[name]


__all__ = [
    "PARAM_GROUPS", "STRATEGIES", "BudgetState", "BudgetStrategy", "DefaultState", "DefaultStrategy", "MCMCState", "MCMCStats", "MCMCStrategy",
    "NoneStrategy", "Optimizers", "Params", "RefineStats", "StepContext", "Strategy", "TopologyChange", "TopologyCounts",
    "make_strategy", "planned_counts", "refines_at", "strategy_fields", "topology_counts",
]
