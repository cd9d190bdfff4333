"""Training checkpoints that resume exactly: ``checkpoints/iteration_<step>.pt``.

A checkpoint holds everything a step reads or changes, so ``N`` steps straight and
``N/2`` steps, a checkpoint, then a fresh trainer that loads it and runs ``N/2`` more
give bit-identical parameters (tested, with densification on): the parameter groups, each Adam's state (moments, step count),
the strategy's state (accumulators, its random generator, refinement history), the SH
schedule, the view order (the permutation left in this epoch and the generator that
draws the next), the torch and numpy global random states, the step index, and the
training history and evaluations recorded so far. It is written with `torch.save`
(atomically: temporary file, then rename) beside the PLY of the same step.

Resuming checks the checkpoint against the run: the config must be the same in every
field but ``out`` and ``checkpoint_every`` (the schedules depend on ``iterations``, the
view order on ``seed``), and the dataset must have the same training views; anything
else is a one-line `InputError` naming the field.

Example::

    train(config)                                              # checkpoint_every=1000
    train(config, resume="runs/train/checkpoints/iteration_1000.pt")
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from splatbench.errors import InputError
from splatbench.strategies.base import PARAM_GROUPS
from splatbench.train.params import make_optimizers

#: Bump when the checkpoint's content changes.
CHECKPOINT_FORMAT = "splatbench-checkpoint/1"
#: Config fields that may differ between the run that wrote a checkpoint and the one resuming it.
FREE_FIELDS = ("out", "checkpoint_every")


def save_checkpoint(trainer: Any, path: str | Path, *, extra: dict[str, Any] | None = None) -> Path:
    """Write ``trainer``'s full state (and ``extra``, e.g. the history) to ``path``."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    state = {
        "format": CHECKPOINT_FORMAT,
        "config": trainer.config.to_dict(),
        "train_names": list(trainer.dataset.train.names),
        "step_index": trainer.step_index,
        "params": {name: trainer.params[name].detach().clone() for name in PARAM_GROUPS},
        "optimizers": {name: trainer.optimizers[name].state_dict() for name in PARAM_GROUPS},
        "strategy_state": trainer.state,
        "sh": trainer.sh,
        "order": list(trainer._order),
        "generator": trainer.generator.get_state(),
        "torch_rng": torch.get_rng_state(),
        "numpy_rng": np.random.get_state(),
        "extra": extra or {},
    }
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".pt", dir=p.parent)
    try:
        with os.fdopen(fd, "wb") as stream:
            torch.save(state, stream)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def resume_line(path: str | Path, step: int, iterations: int) -> str:
    """The one line a resumed run prints and keeps in its notes: ``resumed from PATH at step N of M``."""
    return f"resumed from {path} at step {step} of {iterations}"


def load_checkpoint(trainer: Any, path: str | Path) -> dict[str, Any]:
    """Put the state saved at ``path`` into ``trainer`` (built from the same config and
    dataset); return the checkpoint's ``extra``. One-line `InputError` on any mismatch."""
    p = Path(path)
    try:
        state = torch.load(p, map_location="cpu", weights_only=False)
    except FileNotFoundError:
        raise InputError(f"resume: no such checkpoint {str(p)!r}") from None
    except Exception as exc:  # noqa: BLE001 - any unpickling failure is a bad file
        pt = p.with_suffix(".pt")
        hint = (f"; the checkpoint is the .pt file beside it: --resume {pt}" if p.suffix != ".pt" and pt.is_file()
                else "; checkpoints are the checkpoints/iteration_<step>.pt files of a run's output folder")
        raise InputError(f"resume: {str(p)!r} is not a readable checkpoint ({type(exc).__name__}){hint}") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise InputError(f"resume: {str(p)!r} is not a {CHECKPOINT_FORMAT} checkpoint")
    saved, now = state["config"], trainer.config.to_dict()
    for key in now:
        if key not in FREE_FIELDS and saved.get(key) != now[key]:
            raise InputError(f"resume: {str(p)!r} was written with {key}={saved.get(key)!r}, this run has "
                             f"{key}={now[key]!r} (resume with the checkpoint's config)")
    if state["train_names"] != list(trainer.dataset.train.names):
        raise InputError(f"resume: {str(p)!r} was written on other training views than {str(trainer.dataset.root)!r}")
    trainer.params = {name: torch.nn.Parameter(state["params"][name], requires_grad=trainer.lrs[name] > 0)
                      for name in PARAM_GROUPS}
    trainer.optimizers = make_optimizers(trainer.params, trainer.lrs, trainer.config.adam_eps)
    for name in PARAM_GROUPS:
        trainer.optimizers[name].load_state_dict(state["optimizers"][name])
    trainer.state = state["strategy_state"]
    trainer.sh = state["sh"]
    trainer._order = list(state["order"])
    trainer.generator.set_state(state["generator"])
    torch.set_rng_state(state["torch_rng"])
    np.random.set_state(state["numpy_rng"])
    trainer.step_index = int(state["step_index"])
    return dict(state["extra"])


__all__ = ["save_checkpoint", "load_checkpoint", "resume_line", "CHECKPOINT_FORMAT"]
