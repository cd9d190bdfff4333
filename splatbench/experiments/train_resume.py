"""A train run that continues where a killed attempt of it stopped (the ``train`` kind's `run`).

A runner's worker dies without writing anything when it is stopped: SIGKILL, or the SIGTERM a
runner's `LocalExecutor.close` sends (a worker installs no stop handler, so SIGTERM's default
action ends it), or its watchdog when the runner dies (`splatbench.experiments.workers`). Only
``splatbench train`` itself, whose CLI turns SIGTERM / SIGINT into `splatbench.interrupt.Interrupted`,
writes a checkpoint when stopped. So a long run writes its own, every `CHECKPOINT_EVERY` steps:

- A run of at least `CHECKPOINT_FROM` steps whose config leaves ``checkpoint_every`` at 0 trains
  with ``checkpoint_every = CHECKPOINT_EVERY`` (`with_checkpoints`). Only the TrainConfig it
  trains with changes, never the run's config: its run id, record and comparisons are as
  before, and ``checkpoint_every`` changes no number of a run (`splatbench.train.checkpoint`:
  writing one draws no random number; tested). It keeps the latest checkpoint alone (each is
  written whole before the one before it is removed: a ``.pt`` with Adam's moments is ~100 MB
  for 130k Gaussians) and removes it when the run finishes. A config that sets
  ``checkpoint_every`` itself keeps every checkpoint it asked for.
- A run whose work folder holds a checkpoint (``checkpoints/iteration_<step>.pt``, the latest
  step) continues from it (`train_resuming`), bit-identically to a run that was never stopped,
  and says ``resumed from step N of M (PATH)`` once its first step is done. A checkpoint the
  trainer refuses (another config, other training views, a damaged or foreign file: its
  one-line ``resume: ...`` `InputError`) is removed with every other checkpoint of the folder,
  and the run starts over, saying why in one line, which its record's notes keep too.

A resumed run's ``resumed_step`` (`TrainResult.resumed_step`, a `TrainRun` metric) is the step
it continued from; its ``train_seconds`` and ``cpu_seconds`` are the sums over the attempts of
the steps kept (the killed attempt's loop time up to its checkpoint, saved in it, plus this
one's), so they stay comparable with a straight run's; the steps a killed attempt ran after its
last checkpoint are run again and counted once. Its load marks, warm-up, peak memory and the
record's ``seconds`` are this attempt's alone.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from pathlib import Path

from splatbench.errors import InputError
from splatbench.train.config import TrainConfig

#: A run of at least this many steps writes checkpoints (when its config sets none).
CHECKPOINT_FROM = 5_000
#: ... every this many steps: at most this many steps are lost when its worker is killed.
CHECKPOINT_EVERY = 1_000
#: The folder of a run's checkpoints and what the trainer writes there (`splatbench.train.loop.checkpoint_path`,
#: the ``.pt`` beside it, and a killed write's temporary, `splatbench.fsutil.atomic_write`'s
#: ``.iteration_<step>.<ply|pt>.<pid>.<hex>.tmp``).
CHECKPOINTS = "checkpoints"
_FILE = re.compile(r"\.?iteration_(\d+)\.(?:ply|pt)(?:\.\d+\.[0-9a-f]+\.tmp)?")


def with_checkpoints(cfg: TrainConfig) -> tuple[TrainConfig, bool]:
    """(``cfg`` as the kind trains it, whether the kind set its ``checkpoint_every``): a run of
    `CHECKPOINT_FROM` steps or more with ``checkpoint_every = 0`` writes one every
    `CHECKPOINT_EVERY` steps; any other config is returned as it is."""
    if cfg.checkpoint_every or cfg.iterations < CHECKPOINT_FROM:
        return cfg, False
    return dataclasses.replace(cfg, checkpoint_every=CHECKPOINT_EVERY), True


def checkpoint_files(out: Path) -> dict[Path, int]:
    """Every file the trainer writes in ``out/checkpoints`` (PLYs, ``.pt`` files, temporaries),
    with its step."""
    folder = Path(out) / CHECKPOINTS
    if not folder.is_dir():
        return {}
    return {p: int(m.group(1)) for p in folder.iterdir() if p.is_file() and (m := _FILE.fullmatch(p.name))}


def latest_checkpoint(out: Path) -> Path | None:
    """The ``.pt`` of the latest step in ``out/checkpoints`` (None: none there)."""
    found = {step: p for p, step in checkpoint_files(out).items() if p.name == f"iteration_{step}.pt"}
    return found[max(found)] if found else None


def remove_checkpoints(out: Path, keep: int | None = None) -> None:
    """Remove the checkpoint files of ``out`` but step ``keep``'s (None: all; then the folder too,
    when nothing else is in it)."""
    for path, step in checkpoint_files(out).items():
        if step != keep:
            path.unlink(missing_ok=True)
    folder = Path(out) / CHECKPOINTS
    if keep is None and folder.is_dir() and not any(folder.iterdir()):
        folder.rmdir()


def train_resuming(cfg: TrainConfig, say: Callable[[str], None]):
    """`splatbench.train.train` of ``cfg`` into ``cfg.out``, resumed from the latest checkpoint
    there where one is (module doc); the `TrainResult`, whose notes name the checkpoint it
    resumed from, or the one it refused and why."""
    from splatbench.train import train

    out = Path(cfg.out)
    cfg, own = with_checkpoints(cfg)
    resume = latest_checkpoint(out)
    first = True

    def progress(status) -> None:  # after each step (status.step: its 0-based index), before its checkpoint
        nonlocal first
        if first and resume is not None:  # the first step after the checkpoint's
            say(f"resumed from step {status.step} of {cfg.iterations} ({resume})")
        first = False
        if own and status.step and status.step % cfg.checkpoint_every == 0:
            remove_checkpoints(out, keep=status.step)  # written, whole, after the step before this one

    refused = None
    if resume is not None:
        try:
            result = train(cfg, resume=resume, progress=progress)
        except InputError as exc:
            if not str(exc).startswith("resume:"):  # the dataset, the config: a fresh start fails the same way
                raise
            refused = f"started over: the checkpoint left by an earlier attempt was refused ({exc})"
            say(refused)
            remove_checkpoints(out)
            resume, first = None, False
    if resume is None:
        result = train(cfg, progress=progress)
    if own:
        remove_checkpoints(out)  # the run is done: its final model is point_cloud.ply
    return result if refused is None else dataclasses.replace(result, notes=[refused, *result.notes])


__all__ = ["CHECKPOINT_FROM", "CHECKPOINT_EVERY", "with_checkpoints", "checkpoint_files", "latest_checkpoint",
           "remove_checkpoints", "train_resuming"]
