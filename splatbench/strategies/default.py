"""3DGS adaptive density control (Kerbl et al. 2023), with AbsGS's gradient (Ye et al.
2024) and the revised split opacity (Rota Bulo et al. 2024) as options.

Schedule (graphdeco-inria semantics, counted in completed iterations
``it = ctx.step + 1``, since `post_backward` runs after ``optimizer.step()``):
while ``it < refine_stop`` the screen-space gradient norm of every visible Gaussian
is accumulated; when ``refine_start < it`` and ``it % refine_every == 0`` the
Gaussians are cloned, split and pruned and the accumulators are cleared; when
``it % reset_every == 0`` (and ``it < refine_stop``) opacities are clamped to
``reset_value`` (``reset_every = 0``: never).
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


#: `DefaultStrategy.outcome_note` warns when one refinement's size prune removes this fraction of the model.
SIZE_PRUNE_WARNING = 0.25


class RefineStats(NamedTuple):
    """What one refinement did (counted on the set before it)."""

    step: int     # the ctx.step of the refinement
    cloned: int   # Gaussians duplicated (small, high gradient)
    split: int    # Gaussians replaced by two children (large, high gradient)
    pruned: int   # Gaussians removed after growing (transparent or too large)
    num_gaussians: int  # N after the refinement
    pruned_size: int = 0  # of `pruned`, those removed for their size alone (not transparent)


@dataclass
class LossPlateau:
    """Early stop of densification: the mean training loss over each refine interval
    must drop by at least ``rel_tol`` (relative) from the previous interval's; after
    ``patience`` refinements in a row that fail, densification stops for good."""

    rel_tol: float
    patience: int
    total: float = 0.0      # loss summed since the last refinement
    count: int = 0
    previous: float | None = None  # mean of the previous interval (None after an opacity reset)
    misses: int = 0
    stopped_at: int | None = None  # ctx.step at which densification stopped

    def add(self, loss: float) -> None:
        if math.isfinite(loss):
            self.total += float(loss)
            self.count += 1

    def should_stop(self, step: int) -> bool:
        """Close the current interval; True when densification must stop now."""
        if self.count == 0:
            return False
        mean = self.total / self.count
        self.total, self.count = 0.0, 0
        if self.previous is not None:
            self.misses = self.misses + 1 if self.previous - mean < self.rel_tol * self.previous else 0
        self.previous = mean
        if self.misses >= self.patience:
            self.stopped_at = step
            return True
        return False

    def forget(self) -> None:
        """An opacity reset makes the next interval incomparable with the last."""
        self.previous = None


@dataclass
class DefaultState:
    """Running state of `DefaultStrategy` (per-Gaussian tensors have N rows)."""

    grad_accum: torch.Tensor   # [N] summed NDC gradient norms over visible views
    count: torch.Tensor        # [N] number of views in which each Gaussian was visible
    max_radii: torch.Tensor    # [N] largest screen radius (px) since the last refinement
    generator: torch.Generator  # split's children positions
    plateau: LossPlateau | None  # early-stop bookkeeping (None when early_stop is off)
    stopped: bool = False      # densification stopped early
    last: RefineStats | None = None  # the latest refinement
    history: list[RefineStats] = field(default_factory=list)
    resets: int = 0            # opacity resets made so far
    scene_extent: float = 0.0  # the extent the refinements measured sizes against


@dataclass(frozen=True)
class DefaultStrategy:
    """3DGS adaptive density control; ``absgrad=True`` is AbsGS (registry name "absgrad"),
    ``revised_opacity=True`` gives split children opacity 1 - sqrt(1 - o) (gsplat's option
    of the same name, after "Revising Densification in Gaussian Splatting").

    Clone where the averaged gradient >= ``grad_threshold`` and max scale <=
    ``percent_dense`` x scene extent; split (two children, scale / 1.6) where the
    gradient is as high and the Gaussian larger; then prune opacity < ``prune_opacity``
    and, after the first opacity reset, Gaussians whose max scale exceeds
    ``max_world_size`` x scene extent or (when ``max_screen_size`` > 0; off by
    default, as in effect in graphdeco and gsplat: docs/training.md) whose screen
    radius since the last refinement exceeds ``max_screen_size`` px.

    The trainer must rasterize with ``absgrad=self.absgrad``.

    Defaults and their sources (graphdeco-inria/gaussian-splatting's ``OptimizationParams``
    and ``train.py``; gsplat 1.5.3's ``DefaultStrategy`` field in brackets; the full table
    with the deliberate differences is in docs/training.md, "Defaults and their sources"):
    ``refine_start`` 500 = ``densify_from_iter`` [``refine_start_iter``]; ``refine_stop``
    15,000 = ``densify_until_iter`` [``refine_stop_iter``]; ``refine_every`` 100 =
    ``densification_interval`` [``refine_every``]; ``grad_threshold`` 2e-4 =
    ``densify_grad_threshold`` [``grow_grad2d``; 8e-4 for AbsGS, gsplat's suggested
    value for ``absgrad``]; ``percent_dense`` 0.01 [``grow_scale3d``]; ``prune_opacity``
    0.005 (``train.py``) [``prune_opa``]; ``max_world_size`` 0.1 (``densify_and_prune``)
    [``prune_scale3d``]; ``max_screen_size`` 0, off (graphdeco's 20 px never fires: its
    ``max_radii2D`` is cleared before it is read) [``refine_scale2d_stop_iter = 0``];
    ``reset_every`` 3,000 = ``opacity_reset_interval`` [``reset_every``];
    ``reset_value`` 0.01 (``reset_opacity``) [``2 * prune_opa``]; split into 2 children
    at scale / 1.6 (``densify_and_split``, N = 2) [``ops.split``]; ``revised_opacity``
    False [``revised_opacity``]; ``absgrad`` False [``absgrad``]. This project's
    extensions: ``early_stop`` False (``early_stop_rel_tol`` 0.005, ``early_stop_patience``
    2), and ``seed`` 0 for the split's children (the trainer passes the run's seed).
    """

    #: Scaled by ``TrainConfig.schedule = "scaled"`` (True: a period); refine_every is a
    #: sample size (views per gradient average) and stays as written.
    schedule_fields: ClassVar[dict[str, bool]] = {"refine_start": False, "refine_stop": False, "reset_every": True}
    #: Step fields that may be written as a fraction of the run ("25%", "1/4"; True: a period).
    run_fraction_fields: ClassVar[dict[str, bool]] = {"refine_start": False, "refine_stop": False,
                                                      "refine_every": True, "reset_every": True}
    #: TrainConfig.init.opacity='auto' (graphdeco create_from_pcd: inverse_sigmoid(0.1))
    initial_opacity: ClassVar[float] = 0.1
    #: Clone / split from the averaged info.means2d_grad (AbsGS: info.means2d_absgrad).
    reads_mean_gradients: ClassVar[bool] = True

    refine_start: int = 500       # refine only after this many iterations
    refine_stop: int = 15_000     # no accumulation, refinement or opacity reset from here on
    refine_every: int = 100       # iterations between refinements
    grad_threshold: float = 2e-4  # averaged NDC gradient norm that triggers clone / split (AbsGS: 8e-4)
    percent_dense: float = 0.01   # clone at max scale <= this x scene extent, split above
    prune_opacity: float = 0.005  # prune opacity below this
    max_screen_size: float = 0.0  # prune screen radius (px) above this after the first reset; 0 = off
                                  # (graphdeco passes 20 but clears max_radii2D in densification_postfix
                                  # before pruning reads it, so its rule never fires; gsplat: refine_scale2d_stop=0)
    max_world_size: float = 0.1   # prune max scale above this x scene extent after the first reset; 0 = off
    reset_every: int = 3000       # clamp opacities every this many iterations; 0 = never (and no size pruning)
    reset_value: float = 0.01     # ... to at most this opacity
    absgrad: bool = False         # accumulate AbsGS's |gradient| (info.means2d_absgrad) instead
    revised_opacity: bool = False  # split children get opacity 1 - sqrt(1 - o) (gsplat revised_opacity)
    early_stop: bool = False      # stop densifying once the loss stops falling (off in 3DGS)
    early_stop_rel_tol: float = 0.005  # required relative drop of the mean loss per refine interval
    early_stop_patience: int = 2  # refinements in a row below that drop before stopping
    seed: int = 0                 # the split's random children

    def __post_init__(self) -> None:
        check_fields(self, ("refine_every", "early_stop_patience"),
                      ("refine_start", "refine_stop", "reset_every", "grad_threshold", "percent_dense", "prune_opacity",
                       "max_screen_size", "max_world_size", "early_stop_rel_tol"))
        if not isinstance(self.reset_every, int) or isinstance(self.reset_every, bool):
            raise InputError(f"{type(self).__name__}.reset_every: expected an integer >= 0 (0 = never), "
                             f"got {self.reset_every!r}")
        if not 0.0 < self.reset_value < 1.0:
            raise InputError(f"DefaultStrategy.reset_value: expected a number in (0, 1), got {self.reset_value!r}")

    @property
    def name(self) -> str:
        return "absgrad" if self.absgrad else "default"

    def last_topology_change(self, iterations: int) -> TopologyChange | None:
        """The last refinement or opacity reset of a run (an early stop only ends it sooner)."""
        hi = min(iterations, self.refine_stop - 1)  # completed iterations it = step + 1 < refine_stop
        refine = last_multiple(self.refine_every, self.refine_start, hi)
        reset = last_multiple(self.reset_every, 0, hi)  # None when reset_every is 0 (never)
        window = f"refine window {self.refine_start}..{self.refine_stop}, every {self.refine_every}"
        if refine is not None and (reset is None or refine >= reset):
            return TopologyChange(refine - 1, f"a refinement ({window})")
        if reset is not None:
            return TopologyChange(reset - 1, f"an opacity reset (every {self.reset_every}; {window})")
        return None

    def schedule_note(self, iterations: int, advice: str | None = None) -> str | None:
        """A warning when no refinement step falls in the refine window of this run."""
        return no_refinement_note(self.name, self.refine_every, self.refine_start, self.refine_stop, iterations,
                                  advice)

    def planned_counts(self, iterations: int) -> TopologyCounts:
        """The refinements and opacity resets this schedule makes in a run of ``iterations``
        steps (`post_backward`'s conditions; an early stop makes fewer): what a report names
        when the runs did not record them."""
        hi = min(iterations, self.refine_stop - 1)  # completed iterations it = step + 1 < refine_stop
        return TopologyCounts(refinements=multiples(self.refine_every, self.refine_start, hi),
                              opacity_resets=len(self.reset_steps(iterations)))

    def reset_steps(self, iterations: int) -> tuple[int, ...]:
        """The completed-iteration counts at which this schedule resets opacities in a run of
        ``iterations`` steps (every ``reset_every`` while ``it < refine_stop``; `post_backward`'s
        condition): the training step logged at such a count is the first after the reset."""
        hi = min(iterations, self.refine_stop - 1)
        return tuple(range(self.reset_every, hi + 1, self.reset_every)) if self.reset_every > 0 else ()

    def outcome_note(self, state: DefaultState) -> str | None:
        """A warning when one refinement's size prune removed at least a quarter of the model
        (`SIZE_PRUNE_WARNING`); None otherwise.

        The world-size rule (max scale > ``max_world_size`` x scene extent, from the first
        opacity reset on) is graphdeco's and gsplat's, and the scene extent is 1.1 x the
        spread of the camera centres. Where the scene lies far beyond the cameras (a
        forward-facing capture: ``far``'s backdrop is 150 units away, the extent 1.38) or the
        start is sparse (a few SfM points: 3-NN scales of a large fraction of the scene), every
        Gaussian counts as too big, and a short run (whose first reset comes after one or two
        refinements under ``schedule = "scaled"``) loses the model at once."""
        worst = max((h for h in state.history if h.pruned_size), default=None,
                    key=lambda h: h.pruned_size / max(1, h.num_gaussians + h.pruned))
        if worst is None:
            return None
        before = worst.num_gaussians + worst.pruned
        if worst.pruned_size < SIZE_PRUNE_WARNING * before:
            return None
        return (f"warning: strategy '{self.name}': the size prune removed {worst.pruned_size:,} of {before:,} Gaussians "
                f"at step {worst.step + 1} (max scale > max_world_size {self.max_world_size:g} x the scene extent "
                f"{state.scene_extent:.3g}, from the first opacity reset on, as graphdeco and gsplat): the extent "
                f"comes from the camera spread, so a scene far beyond the cameras or a sparse start counts as too "
                f"big; strategy.max_world_size=0 turns the rule off")

    def initialize_state(self, params: Params) -> DefaultState:
        n, device = params["means"].shape[0], params["means"].device
        gen = torch.Generator(device=device)
        gen.manual_seed(self.seed)
        zeros = lambda: torch.zeros(n, device=device)  # noqa: E731
        plateau = LossPlateau(self.early_stop_rel_tol, self.early_stop_patience) if self.early_stop else None
        return DefaultState(zeros(), zeros(), zeros(), gen, plateau)

    def regularization(self, params: Params, step: int) -> float:
        return 0.0

    def pre_backward(self, params: Params, optimizers: Optimizers, state: DefaultState, ctx: StepContext) -> None:
        return None

    def post_backward(self, params: Params, optimizers: Optimizers, state: DefaultState, ctx: StepContext) -> None:
        it = ctx.step + 1
        if state.stopped or it >= self.refine_stop:
            return
        self._accumulate(params, state, ctx)
        if state.plateau is not None:
            state.plateau.add(ctx.loss)
        if refines_at(it, self.refine_start, self.refine_stop, self.refine_every):
            if state.plateau is not None and state.plateau.should_stop(ctx.step):
                state.stopped = True
                return
            self.refine(params, optimizers, state, ctx.step, ctx.scene_extent)
        if self.reset_every > 0 and it % self.reset_every == 0:
            ops.reset_opacity(params, optimizers, self.reset_value)
            state.resets += 1
            if state.plateau is not None:
                state.plateau.forget()

    @torch.no_grad()
    def _accumulate(self, params: Params, state: DefaultState, ctx: StepContext) -> None:
        info = ctx.info
        grad = info.means2d_absgrad if self.absgrad else info.means2d_grad
        if grad is None:
            what = ("info.means2d_absgrad is None: rasterize with absgrad=True" if self.absgrad else
                    "info.means2d_grad is None")
            raise InputError(f"{self.name} strategy: {what} and call post_backward after loss.backward()")
        n = state.count.shape[0]
        if tuple(grad.shape) != (n, 2) or params["means"].shape[0] != n:
            raise InputError(f"{self.name} strategy: screen-space gradient has shape {list(grad.shape)}, state has "
                             f"N={n}, params have N={params['means'].shape[0]}")
        device = state.count.device
        grad = grad.to(device=device, dtype=torch.float32)
        # pixels -> NDC units, like 3DGS's rasterizer and gsplat (x W/2, y H/2)
        ndc = grad * torch.tensor([info.width / 2.0, info.height / 2.0], device=device)
        vis = info.visible.to(device=device, dtype=torch.bool)
        state.grad_accum[vis] += ndc.norm(dim=-1)[vis]
        state.count[vis] += 1
        radii = info.radii.to(device=device, dtype=torch.float32)
        state.max_radii[vis] = torch.maximum(state.max_radii[vis], radii[vis])

    def candidates(self, params: Params, state: DefaultState, scene_extent: float
                   ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The averaged gradient [N] and the clone and split candidates ([N] bool each):
        averaged gradient >= ``grad_threshold``, max scale <= / > ``percent_dense`` x extent."""
        avg = state.grad_accum / state.count.clamp_min(1)
        high = avg >= self.grad_threshold
        max_scale = torch.exp(params["log_scales"].detach()).amax(dim=-1).to(avg.device)
        small = max_scale <= self.percent_dense * scene_extent
        return avg, high & small, high & ~small

    def select(self, params: Params, state: DefaultState, scene_extent: float
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """The Gaussians to clone and to split ([N] bool each): every candidate (3DGS)."""
        _, clone, grow = self.candidates(params, state, scene_extent)
        return clone, grow

    @torch.no_grad()
    def refine(self, params: Params, optimizers: Optimizers, state: DefaultState, step: int,
               scene_extent: float) -> RefineStats:
        """Clone (``select``), split and prune from the accumulated statistics, then clear
        them. ``step`` is the ctx.step (pruning by size applies once ``step + 1 >
        reset_every``, never when ``reset_every`` is 0)."""
        n = params["means"].shape[0]
        device = state.grad_accum.device
        clone, grow = self.select(params, state, scene_extent)
        size_prune = self.reset_every > 0 and step + 1 > self.reset_every
        # too large on screen, known before growing: clones inherit it, split children do not
        big_screen = (state.max_radii > self.max_screen_size) if size_prune and self.max_screen_size > 0 \
            else torch.zeros(n, dtype=torch.bool, device=device)
        # flags that follow the Gaussians through growing: clones copy their parent's
        # (a clone is never split: clone and split are disjoint), split children get False
        buffers = {"big_screen": big_screen & ~grow, "split": grow}
        n_clone = ops.duplicate(params, optimizers, clone, buffers=buffers)
        split_mask = buffers.pop("split")
        n_split = ops.split(params, optimizers, split_mask, n=2, generator=state.generator, buffers=buffers,
                            revised_opacity=self.revised_opacity)
        big = buffers["big_screen"]
        prune = torch.sigmoid(params["opacity_logits"].detach()).to(device) < self.prune_opacity
        n_size = 0
        if size_prune:
            by_size = big.clone()
            if self.max_world_size > 0:
                by_size |= torch.exp(params["log_scales"].detach()).amax(dim=-1).to(device) \
                    > self.max_world_size * scene_extent
            n_size = int((by_size & ~prune).sum())
            prune |= by_size
        n_prune = ops.remove(params, optimizers, prune)
        m = params["means"].shape[0]
        state.grad_accum = torch.zeros(m, device=device)
        state.count = torch.zeros(m, device=device)
        state.max_radii = torch.zeros(m, device=device)
        stats = RefineStats(step, n_clone, n_split, n_prune, m, n_size)
        state.scene_extent = float(scene_extent)
        state.last = stats
        state.history.append(stats)
        return stats
