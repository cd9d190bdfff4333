"""The `none` strategy: a fixed set of Gaussians (no densification, no pruning)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from splatbench.strategies.base import Optimizers, Params, StepContext, TopologyChange


@dataclass(frozen=True)
class NoneStrategy:
    """Leaves the Gaussians alone; every hook is a no-op (no gsplat counterpart: a gsplat
    trainer without a strategy). Its one default, the initial opacity 0.1
    (``init.opacity = "auto"``), is graphdeco's ``create_from_pcd``."""

    name: ClassVar[str] = "none"
    absgrad: ClassVar[bool] = False  # the trainer never needs info.means2d_absgrad
    reads_mean_gradients: ClassVar[bool] = False  # no hook reads anything
    initial_opacity: ClassVar[float] = 0.1  # init.opacity="auto" (graphdeco create_from_pcd)
    schedule_fields: ClassVar[dict[str, bool]] = {}
    run_fraction_fields: ClassVar[dict[str, bool]] = {}

    def last_topology_change(self, iterations: int) -> TopologyChange | None:
        return None

    def initialize_state(self, params: Params) -> None:
        return None

    def regularization(self, params: Params, step: int) -> float:
        return 0.0

    def pre_backward(self, params: Params, optimizers: Optimizers, state: object, ctx: StepContext) -> None:
        return None

    def post_backward(self, params: Params, optimizers: Optimizers, state: object, ctx: StepContext) -> None:
        return None
