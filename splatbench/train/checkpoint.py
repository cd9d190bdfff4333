"""Training checkpoints that resume exactly: ``checkpoints/iteration_<step>.pt``.

A checkpoint holds everything a step reads or changes, so ``N`` steps straight and
``N/2`` steps, a checkpoint, then a fresh trainer that loads it and runs ``N/2`` more
give bit-identical parameters (tested, with densification on): the parameter groups, each Adam's state (moments, step count),
the strategy's state (accumulators, its random generator, refinement history), the SH
schedule, the view order (the permutation left in this epoch and the generator that
draws the next), the torch and numpy global random states, the step index, and the
training history and evaluations recorded so far. It is written with `torch.save`
(atomically, `report_files.write_binary`: temporary file, fsync, rename) beside the PLY
of the same step.

A checkpoint is data, never code: it holds only tensors, numbers, strings, lists and
dicts, and is read with ``torch.load(weights_only=True)``, which reconstructs nothing
else. The trainer's objects (the strategy's state, the SH schedule, history points)
are written as ``{"__object__": NAME, "fields": {...}}`` and rebuilt only for the names
in `_CLASSES`; generators and the numpy random state as tensors and lists. A file with
anything else in it (a pickle payload, a checkpoint of the older pickled format
``splatbench-checkpoint/1``) is refused in one line and nothing in it runs.

Resuming checks the checkpoint against the run: the config must be the same in every
field but ``out`` and ``checkpoint_every`` (the schedules depend on ``iterations``, the
view order on ``seed``), and the dataset must have the same training views; anything
else is a one-line `InputError` naming the field.

Example::

    train(config)                                              # checkpoint_every=1000
    train(config, resume="runs/train/checkpoints/iteration_1000.pt")
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from splatbench.errors import InputError
from splatbench.report_files import write_binary
from splatbench.strategies.base import PARAM_GROUPS
from splatbench.strategies.budget import BudgetState
from splatbench.strategies.default import DefaultState, LossPlateau, RefineStats
from splatbench.strategies.mcmc import MCMCState, MCMCStats
from splatbench.train.params import make_optimizers
from splatbench.train.result import EvalPoint, HistoryPoint, StepEvaluation
from splatbench.train.sh_schedule import ShDecision, ShSchedule

#: Bump when the checkpoint's content changes (2: plain data, read with weights_only=True).
CHECKPOINT_FORMAT = "splatbench-checkpoint/2"
#: The only classes a checkpoint may name; each is rebuilt from its fields, nothing is called.
_CLASSES = {cls.__name__: cls for cls in (DefaultState, BudgetState, LossPlateau, RefineStats, MCMCState, MCMCStats,
                                          ShSchedule, ShDecision, HistoryPoint, EvalPoint,
                                          StepEvaluation)}
_OBJECT, _TUPLE, _GENERATOR, _NUMPY_RNG = "__object__", "__tuple__", "__generator__", "__numpy_rng__"


def _encode(value: Any) -> Any:
    """``value`` as tensors, numbers, strings, lists and dicts (what weights_only loads)."""
    if value is None or isinstance(value, (bool, int, float, str, torch.Tensor)):
        return value
    if isinstance(value, torch.Generator):
        return {_GENERATOR: value.get_state(), "device": str(value.device)}
    if type(value).__name__ in _CLASSES and _CLASSES[type(value).__name__] is type(value):
        fields = value._asdict() if isinstance(value, tuple) else vars(value)
        return {_OBJECT: type(value).__name__, "fields": {k: _encode(v) for k, v in fields.items()}}
    if isinstance(value, tuple):
        return {_TUPLE: [_encode(v) for v in value]}
    if isinstance(value, list):
        return [_encode(v) for v in value]
    if isinstance(value, dict):
        return {k: _encode(v) for k, v in value.items()}
    raise TypeError(f"checkpoint: cannot store a {type(value).__qualname__} as data (add it to _CLASSES)")


def _decode(value: Any, device: torch.device | None = None) -> Any:
    """The inverse of `_encode`; a name outside `_CLASSES` is a `ValueError` (a bad file).
    ``device``: where the run's tensors live (they are read onto the CPU); a generator saved on
    another kind of device is a one-line `InputError` (its state does not carry over)."""
    if isinstance(value, torch.Tensor):
        return value if device is None else value.to(device)
    if isinstance(value, list):
        return [_decode(v, device) for v in value]
    if not isinstance(value, dict):
        return value
    if _GENERATOR in value:
        saved = torch.device(str(value["device"]))
        if device is not None and saved.type != device.type:
            raise InputError(f"resume: the checkpoint's strategy drew on {saved.type}; this run trains on "
                             f"{device.type} (resume with the device it was written on: --set device=...)")
        gen = torch.Generator(device=saved)
        gen.set_state(value[_GENERATOR])
        return gen
    if _TUPLE in value:
        return tuple(_decode(v, device) for v in value[_TUPLE])
    if _OBJECT in value:
        cls = _CLASSES.get(value[_OBJECT]) if isinstance(value[_OBJECT], str) else None
        if cls is None or not isinstance(value.get("fields"), dict):
            raise ValueError(f"unknown object {value[_OBJECT]!r}")
        fields = {k: _decode(v, device) for k, v in value["fields"].items()}
        if issubclass(cls, tuple):
            return cls(**fields)
        obj = object.__new__(cls)
        obj.__dict__.update(fields)
        return obj
    return {k: _decode(v, device) for k, v in value.items()}


def _numpy_rng_state() -> dict[str, Any]:
    name, keys, pos, has_gauss, cached = np.random.get_state()
    return {_NUMPY_RNG: name, "keys": keys.tolist(), "pos": int(pos), "has_gauss": int(has_gauss),
            "cached": float(cached)}


def _set_numpy_rng_state(state: dict[str, Any]) -> None:
    np.random.set_state((state[_NUMPY_RNG], np.asarray(state["keys"], dtype=np.uint32), int(state["pos"]),
                         int(state["has_gauss"]), float(state["cached"])))
#: Config fields that may differ between the run that wrote a checkpoint and the one resuming it.
FREE_FIELDS = ("out", "checkpoint_every", "dataset")  # dataset: a path; the training views' names are checked


def save_checkpoint(trainer: Any, path: str | Path, *, extra: dict[str, Any] | None = None) -> Path:
    """Write ``trainer``'s full state (and ``extra``, e.g. the history) to ``path``."""
    p = Path(path)
    state = {
        "format": CHECKPOINT_FORMAT,
        "config": trainer.config.to_dict(),
        "train_names": list(trainer.dataset.train.names),
        "step_index": trainer.step_index,
        "params": {name: trainer.params[name].detach().clone() for name in PARAM_GROUPS},
        "optimizers": {name: trainer.optimizers[name].state_dict() for name in PARAM_GROUPS},
        "strategy_state": _encode(trainer.state),
        "sh": _encode(trainer.sh),
        "order": [int(i) for i in trainer._order],
        "generator": trainer.generator.get_state(),
        "torch_rng": torch.get_rng_state(),
        "numpy_rng": _numpy_rng_state(),
        "extra": _encode(extra or {}),
    }
    return write_binary(p, lambda stream: torch.save(state, stream))  # whole or not at all


def resume_line(path: str | Path, step: int, iterations: int) -> str:
    """The one line a resumed run prints and keeps in its notes: ``resumed from PATH at step N of M``."""
    return f"resumed from {path} at step {step} of {iterations}"


def _where_checkpoints_are(p: Path) -> str:
    """The end of a refusal's line: the .pt file beside a file given in its place (a run's PLY), or
    where checkpoints are."""
    pt = p.with_suffix(".pt")
    return (f"; the checkpoint is the .pt file beside it: --resume {pt}" if p.suffix != ".pt" and pt.is_file()
            else "; checkpoints are the checkpoints/iteration_<step>.pt files of a run's output folder")


def _check_archive(p: Path) -> None:
    """One-line `InputError` unless ``p`` is what `save_checkpoint` writes: torch's zip archive
    with every member stored uncompressed and no larger than the file. torch.load also reads its
    legacy (pre-zip) format, whose storage sizes are counts in the file that it allocates before
    reading (a 27 KB file asked for 84 MB), and a compressed member can inflate without bound: a
    file the project never writes is refused before any of its counts is used."""
    size = p.stat().st_size  # FileNotFoundError: the caller's one line
    try:
        with open(p, "rb") as stream:  # torch.load takes a file for a zip by these 4 bytes, not by its directory
            if stream.read(4) != b"PK\x03\x04":
                raise zipfile.BadZipFile("it does not start as one")
        with zipfile.ZipFile(p) as archive:
            members = archive.infolist()
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise InputError(f"resume: {str(p)!r} is not a readable checkpoint (not torch's zip archive: "
                         f"{type(exc).__name__}){_where_checkpoints_are(p)}") from None
    for member in members:
        if member.compress_type != zipfile.ZIP_STORED or member.file_size > size:
            raise InputError(f"resume: {str(p)!r} is not a readable checkpoint (member {member.filename!r:.60} "
                             f"is compressed or claims {member.file_size} bytes of a {size}-byte file; "
                             f"torch.save stores its members as they are)")


def read_checkpoint(path: str | Path, *, mmap: bool = False, device: torch.device | None = None) -> dict[str, Any]:
    """The state saved at ``path`` with its objects rebuilt (`_CLASSES` only), read as data
    (``weights_only=True``): nothing in the file is executed. A missing, damaged, foreign
    or older-format file is a one-line `InputError`. ``mmap``: tensors stay in the file until
    read (for a caller that wants the config alone, not a second copy of the model).
    ``device``: where the strategy state's tensors go (the rest stays on the CPU)."""
    p = Path(path)
    try:
        _check_archive(p)
        # tensors and plain containers only
        state = torch.load(p, map_location="cpu", weights_only=True, mmap=mmap)
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"resume: no such checkpoint {str(p)!r}") from None
    except Exception as exc:  # noqa: BLE001 - a refused global, a damaged zip: a bad file, nothing executed
        if mmap:  # a file mmap cannot map (not a zip): the plain read names what is wrong with it
            return read_checkpoint(p, device=device)
        hint = _where_checkpoints_are(p)
        refused = "unsupported global" in str(exc).lower()  # torch named a class or function it would not call
        reason = ("it holds objects other than tensors and plain data (a checkpoint of an older splatbench, "
                  f"before {CHECKPOINT_FORMAT}, or not a splatbench checkpoint), refused without running them"
                  if refused else f"{type(exc).__name__}")
        raise InputError(f"resume: {str(p)!r} is not a readable checkpoint ({reason}){hint}") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise InputError(f"resume: {str(p)!r} is not a {CHECKPOINT_FORMAT} checkpoint")
    try:
        for key in ("strategy_state", "sh", "extra"):
            state[key] = _decode(state[key], device if key == "strategy_state" else None)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - unknown names, missing keys, bad generator states
        raise InputError(f"resume: {str(p)!r} is a damaged {CHECKPOINT_FORMAT} checkpoint "
                         f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]})") from None
    return state


def checkpoint_config(path: str | Path) -> Any:
    """The `TrainConfig` a checkpoint was written with (read as data, `read_checkpoint`):
    what ``splatbench train --resume CKPT`` continues with when no --config is given."""
    from splatbench.train.config import TrainConfig

    saved = read_checkpoint(path, mmap=True)["config"]  # the parameters are read once, by the resume itself
    return TrainConfig.from_dict(dict(saved), source=f"resume: {path}: config")


def load_checkpoint(trainer: Any, path: str | Path) -> dict[str, Any]:
    """Put the state saved at ``path`` into ``trainer`` (built from the same config and
    dataset); return the checkpoint's ``extra``. One-line `InputError` on any mismatch
    or damage; the file is read as data (`read_checkpoint`)."""
    p = Path(path)
    state = read_checkpoint(p, device=trainer.device)
    try:
        return _apply(trainer, state, p)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - missing keys, wrong types or shapes: a damaged checkpoint
        raise InputError(f"resume: {str(p)!r} is a damaged {CHECKPOINT_FORMAT} checkpoint "
                         f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]})") from None


def _dotted(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A config's TOML tables as ``group.key -> value`` (so that a difference names its field)."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        if isinstance(value, dict) and value:
            out.update(_dotted(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _apply(trainer: Any, state: dict[str, Any], p: Path) -> dict[str, Any]:
    saved, now = _dotted(state["config"]), _dotted(trainer.config.to_dict())
    defaults = _dotted(type(trainer.config)().to_dict())  # a field added since the checkpoint was written: its default
    differ = [key for key in now if key not in FREE_FIELDS and saved.get(key, defaults.get(key)) != now[key]]
    if differ:
        raise InputError(f"resume: {str(p)!r} was written with "
                         + ", ".join(f"{key}={saved.get(key)!r}" for key in differ) + "; this run has "
                         + ", ".join(f"{key}={now[key]!r}" for key in differ)
                         + f" (--resume {p} alone, with no --config or --set, continues with the checkpoint's own config)")
    if state["train_names"] != list(trainer.dataset.train.names):
        raise InputError(f"resume: {str(p)!r} was written on other training views than {str(trainer.dataset.root)!r}")
    params = {name: state["params"][name] for name in PARAM_GROUPS}
    for name, value in params.items():
        if not isinstance(value, torch.Tensor) or not torch.isfinite(value).all():
            raise InputError(f"resume: {str(p)!r}: params.{name}: expected a finite tensor")
    device = trainer.device  # the parameters are read onto the CPU (`read_checkpoint`); the run's live here
    trainer.params = {name: torch.nn.Parameter(params[name].to(device), requires_grad=trainer.lrs[name] > 0)
                      for name in PARAM_GROUPS}
    trainer.optimizers = make_optimizers(trainer.params, trainer.lrs, trainer.config.optim.adam_eps)
    for name in PARAM_GROUPS:
        trainer.optimizers[name].load_state_dict(state["optimizers"][name])  # moments follow their tensor
    trainer.state = state["strategy_state"]  # on ``device`` (`read_checkpoint`)
    trainer.sh = state["sh"]
    trainer._order = [int(i) for i in state["order"]]
    trainer.generator.set_state(state["generator"])
    torch.set_rng_state(state["torch_rng"])
    _set_numpy_rng_state(state["numpy_rng"])
    trainer.step_index = int(state["step_index"])
    return dict(state["extra"])


__all__ = ["save_checkpoint", "load_checkpoint", "read_checkpoint", "resume_line", "CHECKPOINT_FORMAT"]
