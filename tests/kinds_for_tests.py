"""A run kind for the runner's tests, and an example of writing one's own kind.

An experiment names it as ``kind = "tests.kinds_for_tests:DUMMY"`` (`KIND`): workers
import ``tests.kinds_for_tests`` by that name, so it is importable wherever the tests
run the runner (the repository root on ``sys.path``: pytest puts it there, spawned
and Dask worker processes inherit the parent's ``sys.path``, and a ``python -m`` run
from the repository root has it as its working directory).

The kind computes deterministic numbers from its config, and sleeps, waits at a gate,
raises or kills its process on demand, so the runner's tests need no rendering.
`PROBE` reports what its worker was handed; `TRACE` appends a line to a file as each run
runs (the order a runner ran them in).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from splatbench.errors import InputError
from splatbench.experiments.kinds import KindProtocols, RunKind, RunResult, metric, read_config

#: What an experiment file writes in ``kind = "..."``.
KIND = "tests.kinds_for_tests:DUMMY"

@dataclass(frozen=True)
class DummyOpts:
    """A nested table of the dummy kind's config, for dotted keys (``opts.a``)."""

    a: int = 0       # folded into the metric a_plus_seed
    b: str = "p"     # folded into the metric scene_tag and the curve's seed


@dataclass(frozen=True)
class DummyConfig:
    """The dummy kind's Config: every key of a run's config is one of its fields (the engine checks
    them, `splatbench.experiments.kinds.check_config`); types are checked as the config is read
    (`read_config`), ranges here."""

    scene: str = ""
    seed: int = 0
    x: float = 0.0        # a number folded into the metrics
    n: int = 3            # curve length (>= 1)
    mode: str = "ok"      # "ok", "warn" (ok, with a warning), "warn-many" (its own and a shared one, given twice),
    #                       "fail" (raise) or "crash" (the worker exits at once)
    sleep: float = 0.0    # seconds to sleep before computing
    gate: str = ""        # a folder: the run waits there for a token (see `_pass_gate`); "" = no gate
    opts: DummyOpts = field(default_factory=DummyOpts)

    def __post_init__(self) -> None:
        if self.mode not in ("ok", "warn", "warn-many", "fail", "crash"):
            raise InputError(f"mode: expected 'ok', 'warn', 'fail' or 'crash' (or 'warn-many'), got {self.mode!r}")
        if not (math.isfinite(self.sleep) and self.sleep >= 0):
            raise InputError(f"sleep: expected seconds >= 0, got {self.sleep!r}")
        if self.n < 1:
            raise InputError(f"n: expected an int >= 1, got {self.n!r}")


DUMMY_SCENES = frozenset({"alpha", "beta", "gamma"})


@dataclass(frozen=True, kw_only=True)
class DummyRun(RunResult):
    """What a dummy run records: each field a column ``metric.<name>`` (`metric`: how a report
    shows it, what it means); ``warnings`` and ``curves`` come with `RunResult`."""

    value: float = metric("value", ".4g", better="higher", meaning="the curve's last point")
    total: float = metric("total", ".4g", meaning="the curve's sum")
    a_plus_seed: int = metric(meaning="opts.a + seed")
    scene_tag: str = metric(meaning="scene and opts.b")
    positive: bool = metric(meaning="whether value > 0")


def _validate(config: dict[str, Any]) -> None:
    read_config(DummyConfig, config)


def _resolve(config: dict[str, Any]) -> dict[str, Any]:
    return asdict(read_config(DummyConfig, config))


def _pass_gate(gate: Path) -> None:
    """Block until the test holding ``gate`` lets this run through: a file ``open`` there
    lets every run pass; a file ``token-*`` lets one run pass (the run takes it by
    renaming it). While waiting, the run marks itself ``waiting-<pid>``, so a test knows
    a run is in flight in this process before it injects a fault."""
    marker = gate / f"waiting-{os.getpid()}"
    marker.touch()
    while not (gate / "open").exists():
        for token in sorted(gate.glob("token-*")):
            try:
                os.rename(token, gate / f"used-{os.getpid()}-{token.name}")
            except FileNotFoundError:  # another run took it first
                continue
            marker.unlink(missing_ok=True)
            return
        time.sleep(0.02)
    marker.unlink(missing_ok=True)


def _run(config: dict[str, Any], workdir: Path, prepared: None) -> DummyRun:
    """Deterministic numbers from the config; sleeps, waits at a gate, raises or kills
    its process on demand. (No ``prepare``: ``prepared`` is None.)"""
    import numpy as np

    cfg = read_config(DummyConfig, config)
    time.sleep(cfg.sleep)
    if cfg.gate:
        _pass_gate(Path(cfg.gate))
    if cfg.mode == "fail":
        raise RuntimeError(f"dummy run told to fail (scene {cfg.scene}, seed {cfg.seed})")
    if cfg.mode == "crash":
        os._exit(70)
    tag = zlib.crc32(f"{cfg.scene}/{cfg.opts.b}".encode())
    rng = np.random.default_rng([cfg.seed, tag, cfg.n])
    curve = (cfg.x + rng.random(cfg.n)).round(12)
    (workdir / "note.txt").write_text(f"{cfg.scene} {cfg.seed}\n")
    warnings = (f"warning: dummy run told to warn (seed {cfg.seed})",) if cfg.mode in ("warn", "warn-many") else ()
    if cfg.mode == "warn-many":
        warnings += ("warning: dummy runs share this one",) * 2
    return DummyRun(value=float(curve[-1]), total=float(curve.sum()), a_plus_seed=cfg.opts.a + cfg.seed,
                    scene_tag=f"{cfg.scene}-{cfg.opts.b}", positive=bool(curve[-1] > 0),
                    curves={"step": list(range(cfg.n)), "value": curve.tolist()}, warnings=warnings)


def _scenes() -> set[str]:
    return set(DUMMY_SCENES)


#: The dummy kind's one protocol (an experiment's ``[check]``): its curves 7 points long.
DUMMY_PROTOCOL = "long"


def _with_protocol(config: dict[str, Any], name: str) -> dict[str, Any]:
    """The cell under the dummy protocol ``"long"``: ``n = 7`` (a new run id); one-line error otherwise."""
    if name != DUMMY_PROTOCOL:
        raise InputError(f"protocol: expected {DUMMY_PROTOCOL!r}, got {name!r}")
    return {**config, "n": 7}


#: Deterministic metrics computed from the config (`DummyConfig`).
DUMMY = RunKind(name=KIND, validate=_validate, run=_run, config=DummyConfig, result=DummyRun, resolve=_resolve,
                scenes=_scenes,
                description="for tests: deterministic numbers, configurable sleep, gate and failure",
                protocols=KindProtocols(_with_protocol, lambda name: "curves 7 points long"))


# --------------------------------------------------------------------------- probe
@dataclass(frozen=True)
class ProbeConfig:
    """A probe run takes no settings of its own (its ``scene`` and ``seed`` only)."""


def _probe_validate(config: dict[str, Any]) -> None:
    read_config(ProbeConfig, config)


def _probe_prepare(configs: list[dict[str, Any]]) -> dict[str, int]:
    return {"runs": len(configs), "parent": os.getpid()}


@dataclass(frozen=True, kw_only=True)
class ProbeRun(RunResult):
    """What reached a probe run's worker."""

    drjit_threads: int = metric(meaning="the worker's Dr.Jit thread budget")
    prepared_runs: int = metric(meaning="runs `prepare` was handed, in the parent")
    prepared_parent: int = metric(meaning="the parent's process id, as `prepare` saw it")
    pid: int = metric(meaning="the worker's process id")
    env: str = metric(meaning="the SPLATBENCH_* variables of the worker's environment")


def _probe_run(config: dict[str, Any], workdir: Path, prepared: dict[str, int]) -> ProbeRun:
    """What reached the worker from the runner: its Dr.Jit thread budget, what ``prepare``
    returned, and the ``SPLATBENCH_*`` variables of its environment."""
    import drjit as dr

    return ProbeRun(drjit_threads=dr.thread_count(), prepared_runs=prepared["runs"],
                    prepared_parent=prepared["parent"], pid=os.getpid(),
                    env=",".join(sorted(k for k in os.environ if k.startswith("SPLATBENCH_"))))


#: A kind that reports what its worker was handed (``kind = "tests.kinds_for_tests:PROBE"``).
PROBE = RunKind(name="tests.kinds_for_tests:PROBE", validate=_probe_validate, run=_probe_run, config=ProbeConfig,
                result=ProbeRun,
                prepare=_probe_prepare, description="for tests: what a worker gets from the runner")


# --------------------------------------------------------------------------- trace
@dataclass(frozen=True)
class TraceConfig:
    """A trace run's settings: ``cell`` names its cell, ``log`` the file it appends to."""

    scene: str = ""
    seed: int = 0
    cell: str = ""
    log: str = ""         # a file: the run appends "SCENE CELL SEED PROTOCOL" to it, one line
    protocol: str = ""    # "" in the grid; the protocol's name in an experiment's [check]


def _trace_validate(config: dict[str, Any]) -> None:
    read_config(TraceConfig, config)


@dataclass(frozen=True, kw_only=True)
class TraceRun(RunResult):
    """What a trace run records: its line of the log."""

    line: str = metric(meaning="the line the run appended to its log")


def _trace_run(config: dict[str, Any], workdir: Path, prepared: None) -> TraceRun:
    """Append one line naming this run to ``log``: the order runs ran in (one worker: one at a time)."""
    cfg = read_config(TraceConfig, config)
    line = f"{cfg.scene} {cfg.cell} {cfg.seed} {cfg.protocol or '-'}"
    with open(cfg.log, "a") as f:
        f.write(line + "\n")
    return TraceRun(line=line)


def _trace_protocol(config: dict[str, Any], name: str) -> dict[str, Any]:
    """The cell under the protocol ``"long"``: marked with its name (a new run id); one-line error otherwise."""
    if name != DUMMY_PROTOCOL:
        raise InputError(f"protocol: expected {DUMMY_PROTOCOL!r}, got {name!r}")
    return {**config, "protocol": name}


#: A kind whose runs append a line to a file as they run (``kind = "tests.kinds_for_tests:TRACE"``),
#: so that a test sees the order a runner ran them in; any scene name; protocol "long" (a [check]).
TRACE = RunKind(name="tests.kinds_for_tests:TRACE", validate=_trace_validate, run=_trace_run, config=TraceConfig,
                result=TraceRun, description="for tests: each run appends a line to a log as it runs",
                protocols=KindProtocols(_trace_protocol, lambda name: "the run marked with the protocol's name"))


# --------------------------------------------------------------------------- reusable
#: The dummy kind declared ``reusable`` (as training is): a run another experiment in the same
#: results folder finished is copied, not run again (``kind = "tests.kinds_for_tests:REUSABLE"``).
REUSABLE = dataclasses.replace(DUMMY, name="tests.kinds_for_tests:REUSABLE", reusable=True)
