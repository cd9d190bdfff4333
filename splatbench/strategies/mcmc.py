"""3DGS-MCMC (Kheradmand et al. 2024, "3D Gaussian Splatting as Markov Chain Monte
Carlo"), with gsplat's ``MCMCStrategy`` semantics.

After every optimizer step the means get SGLD noise shaped by each Gaussian's
covariance and gated by its transparency (`ops.inject_noise`). When
``refine_start < it < refine_stop`` and ``it % refine_every == 0`` (``it = ctx.step + 1``,
completed iterations): dead Gaussians (opacity <= ``min_opacity``) are relocated
onto live ones sampled proportionally to opacity, then 5 % more are added the same
way, up to ``cap_max``. The loss gets ``opacity_reg`` x mean(opacity) +
``scale_reg`` x mean(scale).

Initialisation is the trainer's: with ``init.opacity = "auto"`` it starts from this
strategy's ``initial_opacity`` 0.5, as 3DGS-MCMC's ``create_from_pcd`` does; its scales
(0.1 x the nearest-neighbour distance there) stay graphdeco's (docs/training.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, NamedTuple

import torch

from splatbench.errors import InputError
import splatbench.strategies.ops as ops
from splatbench.strategies.base import (Optimizers, Params, StepContext, TopologyChange, TopologyCounts,
                                       check_fields, last_multiple, multiples, no_refinement_note, refines_at)
from splatbench.strategies.default import LossPlateau


class MCMCStats(NamedTuple):
    """What one MCMC refinement did."""

    step: int        # the ctx.step of the refinement
    relocated: int   # dead Gaussians moved onto live ones
    added: int       # new Gaussians
    num_gaussians: int  # N after the refinement


@dataclass
class MCMCState:
    """Running state of `MCMCStrategy`."""

    generator: torch.Generator  # relocation / addition sampling and the position noise
    plateau: LossPlateau | None  # early-stop bookkeeping (None when early_stop is off)
    stopped: bool = False       # relocation / addition stopped early (the noise goes on)
    last: MCMCStats | None = None
    history: list[MCMCStats] = field(default_factory=list)
    last_noise: torch.Tensor | None = None  # [N, 3] the latest noise added to the means
    initial: int = 0            # Gaussians at the start (`outcome_note`)


@dataclass(frozen=True)
class MCMCStrategy:
    """3DGS-MCMC: relocate dead Gaussians, grow by ``growth`` up to ``cap_max``, noisy means.

    Defaults and their sources (gsplat 1.5.3's ``MCMCStrategy`` field in brackets; the full
    table in docs/training.md, "Defaults and their sources"): ``cap_max`` 1,000,000
    [``cap_max``]; ``noise_lr`` 5e5 [``noise_lr``]; ``refine_start`` 500, ``refine_stop``
    25,000, ``refine_every`` 100 [``refine_start_iter``, ``refine_stop_iter``,
    ``refine_every``]; ``min_opacity`` 0.005 [``min_opacity``]; ``growth`` 0.05
    [``_add_new_gs``: ``int(1.05 * n)``]; ``opacity_reg`` 0.01 and ``scale_reg`` 0.01
    (3DGS-MCMC's training recipe; the loss terms are the trainer's in gsplat, not its
    strategy's); initial opacity 0.5 (ubc-vision/3dgs-mcmc ``create_from_pcd``).
    This project's extensions: ``early_stop`` False (``early_stop_rel_tol`` 0.005,
    ``early_stop_patience`` 2), and ``seed`` 0 for the sampling and the noise (the trainer
    passes the run's seed).
    """

    name: ClassVar[str] = "mcmc"
    absgrad: ClassVar[bool] = False  # the trainer never needs info.means2d_absgrad
    #: Relocation samples by opacity, the noise by opacity and covariance: no screen-space
    #: gradient is read (as in gsplat 1.5.3's MCMCStrategy).
    reads_mean_gradients: ClassVar[bool] = False
    initial_opacity: ClassVar[float] = 0.5  # init.opacity="auto" (ubc-vision/3dgs-mcmc create_from_pcd)
    #: Scaled by ``TrainConfig.schedule = "scaled"``; refine_every stays as written.
    schedule_fields: ClassVar[dict[str, bool]] = {"refine_start": False, "refine_stop": False}
    #: Step fields that may be written as a fraction of the run ("25%", "1/4"; True: a period).
    run_fraction_fields: ClassVar[dict[str, bool]] = {"refine_start": False, "refine_stop": False,
                                                      "refine_every": True}

    cap_max: int = 1_000_000      # most Gaussians ever (no addition beyond it)
    noise_lr: float = 5e5         # position noise = means_lr x noise_lr x gate(opacity) x covariance
    refine_start: int = 500       # relocate / add only after this many iterations
    refine_stop: int = 25_000     # ... and before this many
    refine_every: int = 100       # iterations between relocations
    min_opacity: float = 0.005    # dead at opacity <= this; relocated opacities are clamped to >= this
    growth: float = 0.05          # fraction added per refinement (N -> min(cap_max, int((1 + growth) N)))
    opacity_reg: float = 0.01     # weight of mean(opacity) in the loss
    scale_reg: float = 0.01       # weight of mean(scale) in the loss
    early_stop: bool = False      # stop relocating / adding once the loss stops falling
    early_stop_rel_tol: float = 0.005  # required relative drop of the mean loss per refine interval
    early_stop_patience: int = 2  # refinements in a row below that drop before stopping
    seed: int = 0                 # sampling and noise

    def __post_init__(self) -> None:
        check_fields(self, ("refine_every", "early_stop_patience"),
                      ("cap_max", "noise_lr", "refine_start", "refine_stop", "growth", "opacity_reg", "scale_reg",
                       "early_stop_rel_tol"))
        if isinstance(self.cap_max, bool) or not isinstance(self.cap_max, int):
            raise InputError(f"MCMCStrategy.cap_max: expected an integer, got {self.cap_max!r}")
        if not 0.0 < self.min_opacity < 1.0:
            raise InputError(f"MCMCStrategy.min_opacity: expected a number in (0, 1), got {self.min_opacity!r}")

    def last_topology_change(self, iterations: int) -> TopologyChange | None:
        """The last relocation / addition of a run (the position noise moves, never adds)."""
        it = last_multiple(self.refine_every, self.refine_start, min(iterations, self.refine_stop - 1))
        if it is None:
            return None
        return TopologyChange(it - 1, f"a relocation (refine window {self.refine_start}..{self.refine_stop}, "
                                      f"every {self.refine_every})")

    def planned_counts(self, iterations: int) -> TopologyCounts:
        """The relocation / addition steps this schedule makes in a run of ``iterations`` steps
        (an early stop makes fewer); MCMC never resets opacities."""
        return TopologyCounts(refinements=multiples(self.refine_every, self.refine_start,
                                                    min(iterations, self.refine_stop - 1)))

    def schedule_note(self, iterations: int, advice: str | None = None) -> str | None:
        """A warning when no refinement step falls in the refine window of this run."""
        return no_refinement_note(self.name, self.refine_every, self.refine_start, self.refine_stop, iterations,
                                  advice)

    def initialize_state(self, params: Params) -> MCMCState:
        gen = torch.Generator(device=params["means"].device)
        gen.manual_seed(self.seed)
        plateau = LossPlateau(self.early_stop_rel_tol, self.early_stop_patience) if self.early_stop else None
        return MCMCState(gen, plateau, initial=int(params["means"].shape[0]))

    def outcome_note(self, state: MCMCState) -> str | None:
        """A warning when ``cap_max`` is below the initial count: MCMC adds up to its cap and
        never removes, so such a cap is never met; None otherwise."""
        if self.cap_max >= state.initial:
            return None
        return (f"warning: strategy 'mcmc': cap_max {self.cap_max:,} is below the initial {state.initial:,} "
                f"Gaussians, and 3DGS-MCMC only relocates and adds, never removes, so the model kept "
                f"{state.initial:,}; give cap_max at least the initial count, or start from fewer points")

    def regularization(self, params: Params, step: int) -> torch.Tensor:
        """opacity_reg x mean(sigmoid(opacity_logits)) + scale_reg x mean(exp(log_scales))."""
        return (self.opacity_reg * torch.sigmoid(params["opacity_logits"]).mean()
                + self.scale_reg * torch.exp(params["log_scales"]).mean())

    def pre_backward(self, params: Params, optimizers: Optimizers, state: MCMCState, ctx: StepContext) -> None:
        return None

    def post_backward(self, params: Params, optimizers: Optimizers, state: MCMCState, ctx: StepContext) -> None:
        it = ctx.step + 1
        if state.plateau is not None and not state.stopped:
            state.plateau.add(ctx.loss)
        if not state.stopped and refines_at(it, self.refine_start, self.refine_stop, self.refine_every):
            if state.plateau is not None and state.plateau.should_stop(ctx.step):
                state.stopped = True
            else:
                self.refine(params, optimizers, state, ctx.step)
        state.last_noise = ops.inject_noise(params, ctx.means_lr * self.noise_lr, generator=state.generator)

    @torch.no_grad()
    def refine(self, params: Params, optimizers: Optimizers, state: MCMCState, step: int) -> MCMCStats:
        """Relocate the dead, then add up to ``growth`` x N (at most ``cap_max`` in all)."""
        dead = torch.sigmoid(params["opacity_logits"].detach()) <= self.min_opacity
        relocated = ops.relocate(params, optimizers, dead, min_opacity=self.min_opacity, generator=state.generator)
        n = params["means"].shape[0]
        target = min(self.cap_max, int(math.floor((1.0 + self.growth) * n)))
        added = ops.sample_add(params, optimizers, max(0, target - n), min_opacity=self.min_opacity,
                               generator=state.generator)
        stats = MCMCStats(step, relocated, added, params["means"].shape[0])
        state.last = stats
        state.history.append(stats)
        return stats
