"""Training protocols: how a run's schedule is laid out and where it is evaluated.

`TrainConfig.protocol` names one of `PROTOCOLS`:

``"quick"`` (the default)
    The schedule is laid over the run's own ``iterations``: under ``schedule =
    "scaled"`` graphdeco's step fields (refine 500..15,000 every 100, opacity reset
    every 3,000, SH band every 1,000) are multiplied by ``iterations / 30,000``, and the
    position learning rate decays over ``iterations``. The learning rates themselves
    are NOT scaled, so a 2,000-step run compresses graphdeco's schedule 15x while its
    positions can travel only about 1/15 as far. Evaluated at the end (and every
    ``eval.every`` steps). Cheap; stands beside no published column.
``"graphdeco-30k"``
    graphdeco-inria's schedule unscaled: every step field as written for a
    30,000-step run, the position learning rate decaying over 30,000 steps, 30,000
    iterations, and a full test evaluation (PSNR, SSIM, LPIPS in both input
    conventions, Gaussians) after 7,000 and 30,000 steps of that one run: the 3DGS
    paper's 7K and 30K columns are checkpoints of its 30K run, not scaled runs.
``"graphdeco-7k"``
    The same 30,000-step schedule stopped after 7,000 steps (identical, step for step,
    to the first 7,000 steps of a ``graphdeco-30k`` run of the same seed): the paper's
    7K column at under a quarter of the cost.

A grid's check (an experiment's ``[check]``: its headline rerun at a graphdeco protocol,
docs/reports.md "The protocol check") evaluates the test views every `Protocol.curve_every` steps:
700 under ``graphdeco-7k`` (ten points, the last the 7K column) and 2,500 under
``graphdeco-30k``, spacings on which no point falls on an opacity reset (every 3,000 steps
inside the refine window, 500..15,000): a point there would measure the model in the step
its opacities were clamped, not the model (1,000 or 500 would put one on 3,000 and 6,000).

Under a graphdeco protocol ``iterations`` defaults to the protocol's length and may be
set lower only to stop the same schedule early (a smoke test: the result records the
step it stopped at), never higher; the final-10 % check of `splatbench.train.schedule`
does not apply (graphdeco's 7K model is taken mid-refinement, 100 steps after a
densification, 1,000 after an opacity reset; that is the column it stands beside).

Example::

    TrainConfig(dataset="lego", protocol="graphdeco-30k")          # 30,000 steps, evaluated at 7,000 and 30,000
    apply_overrides(TrainConfig(), ["protocol=graphdeco-7k"])      # iterations 7,000, LR decay over 30,000
"""

from __future__ import annotations

from dataclasses import dataclass

from splatbench.errors import InputError

#: graphdeco's run length, in which its schedules are written (`splatbench.train.schedule`).
GRAPHDECO_ITERATIONS = 30_000


@dataclass(frozen=True)
class Protocol:
    """How a run's schedule is laid out and where it is evaluated (module doc)."""

    name: str
    schedule_length: int | None   # steps the schedules and the position LR decay span (None: the run's iterations)
    iterations: int | None        # iterations when the protocol is chosen without them (None: the config's)
    eval_steps: tuple[int, ...]   # steps of a full test evaluation (`TrainResult.step_evaluations`), besides the end
    final_window_check: bool      # the last topology change must precede the final 10 % of the run
    stands_beside: str            # the published numbers it is comparable with
    curve_every: int | None = None  # test-curve spacing of a grid's check at this protocol (`eval.every`; None:
    #                               # no check runs at it): no point on an opacity reset's step (module doc)

    def check_iterations(self, iterations: int) -> None:
        """One-line `InputError` when ``iterations`` exceeds the protocol's length."""
        if self.iterations is not None and iterations > self.iterations:
            raise InputError(f"iterations: protocol {self.name!r} runs {self.iterations} steps of graphdeco's "
                             f"{GRAPHDECO_ITERATIONS}-step schedule (fewer only to stop it early), got {iterations}")

    @property
    def schedule_advice(self) -> str | None:
        """What a warning about the schedule (a strategy that never refines in the run)
        advises under this protocol: its full length, the one fix that keeps its
        schedule as written; None under ``quick`` (the strategy's own advice: change the
        schedule, or train longer)."""
        if self.iterations is None:
            return None
        return (f"run the protocol's full length (iterations={self.iterations}, its default): its schedule is "
                f"graphdeco's as written, so changing refine_every would leave protocol {self.name!r}")

    def early_stop_note(self, iterations: int) -> str | None:
        """A note when a run of ``iterations`` steps stops this protocol before its length:
        its last evaluation is then not the published column it would stand beside; the
        columns it did reach (graphdeco-30k stopped after 7,000 steps: the 7K) still are.
        None when the run is full length or the protocol has no length (``quick``)."""
        if self.iterations is None or iterations >= self.iterations:
            return None
        missed = [s for s in self.eval_steps if s > iterations]
        reached = [s for s in self.eval_steps if s <= iterations]
        column = " and ".join(f"{s // 1000}K" for s in missed) + (" columns" if len(missed) > 1 else " column")
        kept = "".join(f"; its step-{s} evaluation is the {s // 1000}K column's" for s in reached)
        return (f"protocol {self.name!r} stopped early, after {iterations} of its {self.iterations} steps: its "
                f"step evaluation at {iterations} is not the 3DGS paper's {column} (run all {self.iterations} "
                f"steps for that){kept}")


#: Protocol name -> `Protocol`.
PROTOCOLS: dict[str, Protocol] = {
    "quick": Protocol("quick", None, None, (), True,
                      "no published column (graphdeco's step fields scaled to the run, learning rates not)"),
    "graphdeco-30k": Protocol("graphdeco-30k", GRAPHDECO_ITERATIONS, GRAPHDECO_ITERATIONS, (7_000, 30_000), False,
                              "the 3DGS paper's 7K and 30K columns (Kerbl et al. 2023, Table 1)", 2_500),
    "graphdeco-7k": Protocol("graphdeco-7k", GRAPHDECO_ITERATIONS, 7_000, (7_000,), False,
                             "the 3DGS paper's 7K column (Kerbl et al. 2023, Table 1)", 700),
}


def get_protocol(name: str) -> Protocol:
    """The `Protocol` called ``name`` (one-line `InputError` naming the known ones)."""
    if name not in PROTOCOLS:
        raise InputError(f"protocol: expected one of {', '.join(map(repr, PROTOCOLS))}, got {name!r}")
    return PROTOCOLS[name]


def evaluation_steps(protocol: str, eval_steps: list[int] | tuple[int, ...], iterations: int) -> list[int]:
    """The steps of a full test evaluation of a run: the protocol's and ``eval_steps``
    reached within ``iterations``, and the last step whenever there is any (empty for a
    quick run without ``eval_steps``: such a run records none)."""
    wanted = {s for s in (*get_protocol(protocol).eval_steps, *eval_steps) if 1 <= s <= iterations}
    if protocol != "quick" or eval_steps:
        wanted.add(iterations)
    return sorted(wanted)


__all__ = ["Protocol", "PROTOCOLS", "GRAPHDECO_ITERATIONS", "get_protocol", "evaluation_steps"]
