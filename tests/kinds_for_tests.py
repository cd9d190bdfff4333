"""A run kind for the runner's tests, and an example of writing one's own kind.

An experiment names it as ``kind = "tests.kinds_for_tests:DUMMY"`` (`KIND`): workers
import ``tests.kinds_for_tests`` by that name, so it is importable wherever the tests
run the runner (the repository root on ``sys.path``: pytest puts it there, spawned
and Dask worker processes inherit the parent's ``sys.path``, and a ``python -m`` run
from the repository root has it as its working directory).

The kind computes deterministic numbers from its config, and sleeps, waits at a gate,
raises or kills its process on demand, so the runner's tests need no rendering.
"""

from __future__ import annotations

import math
import os
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from splatbench.checks import check_keys
from splatbench.errors import InputError
from splatbench.experiments.configs import flatten, override, unflatten
from splatbench.experiments.kinds import KindProtocols, RunKind, RunResult, metric

#: What an experiment file writes in ``kind = "..."``.
KIND = "tests.kinds_for_tests:DUMMY"

#: The dummy kind's fields and defaults.
DUMMY_DEFAULTS: dict[str, Any] = {
    "x": 0.0,        # a number folded into the metrics
    "n": 3,          # curve length (>= 1)
    "mode": "ok",    # "ok", "warn" (ok, with a warning), "fail" (raise) or "crash" (the worker exits at once)
    "sleep": 0.0,    # seconds to sleep before computing
    "gate": "",      # a folder: the run waits there for a token (see `_pass_gate`); "" = no gate
    "opts": {"a": 0, "b": "p"},  # a nested table, for dotted keys
}
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
    known = {**flatten(DUMMY_DEFAULTS), "scene": "", "seed": 0}
    check_keys(flatten(config), known)
    for key, value in flatten(config).items():
        expected = type(known[key])
        ok = (isinstance(value, (int, float)) and not isinstance(value, bool)) if expected is float \
            else isinstance(value, expected) and not (expected is int and isinstance(value, bool))
        if not ok:
            raise InputError(f"{key}: expected {expected.__name__}, got {value!r}")
    if config.get("mode", "ok") not in ("ok", "warn", "fail", "crash"):
        raise InputError(f"mode: expected 'ok', 'warn', 'fail' or 'crash', got {config['mode']!r}")
    if not (math.isfinite(config.get("sleep", 0.0)) and config.get("sleep", 0.0) >= 0):
        raise InputError(f"sleep: expected seconds >= 0, got {config['sleep']!r}")
    if config.get("n", 1) < 1:
        raise InputError(f"n: expected an int >= 1, got {config['n']!r}")


def _resolve(config: dict[str, Any]) -> dict[str, Any]:
    out = unflatten(override(flatten(DUMMY_DEFAULTS), flatten(config)))
    out["x"] = float(out["x"])
    out["sleep"] = float(out["sleep"])
    return out


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

    time.sleep(config["sleep"])
    if config["gate"]:
        _pass_gate(Path(config["gate"]))
    if config["mode"] == "fail":
        raise RuntimeError(f"dummy run told to fail (scene {config['scene']}, seed {config['seed']})")
    if config["mode"] == "crash":
        os._exit(70)
    tag = zlib.crc32(f"{config['scene']}/{config['opts']['b']}".encode())
    rng = np.random.default_rng([config["seed"], tag, config["n"]])
    curve = (config["x"] + rng.random(config["n"])).round(12)
    (workdir / "note.txt").write_text(f"{config['scene']} {config['seed']}\n")
    warnings = (f"warning: dummy run told to warn (seed {config['seed']})",) if config["mode"] == "warn" else ()
    return DummyRun(value=float(curve[-1]), total=float(curve.sum()), a_plus_seed=config["opts"]["a"] + config["seed"],
                    scene_tag=f"{config['scene']}-{config['opts']['b']}", positive=bool(curve[-1] > 0),
                    curves={"step": list(range(config["n"])), "value": curve.tolist()}, warnings=warnings)


def _scenes() -> set[str]:
    return set(DUMMY_SCENES)


#: The dummy kind's one protocol (an experiment's ``[check]``): its curves 7 points long.
DUMMY_PROTOCOL = "long"


def _with_protocol(config: dict[str, Any], name: str) -> dict[str, Any]:
    """The cell under the dummy protocol ``"long"``: ``n = 7`` (a new run id); one-line error otherwise."""
    if name != DUMMY_PROTOCOL:
        raise InputError(f"protocol: expected {DUMMY_PROTOCOL!r}, got {name!r}")
    return {**config, "n": 7}


#: Deterministic metrics computed from the config (see `DUMMY_DEFAULTS`).
DUMMY = RunKind(name=KIND, validate=_validate, run=_run, result=DummyRun, resolve=_resolve, scenes=_scenes,
                description="for tests: deterministic numbers, configurable sleep, gate and failure",
                protocols=KindProtocols(_with_protocol, lambda name: "curves 7 points long"))


# --------------------------------------------------------------------------- probe
def _probe_validate(config: dict[str, Any]) -> None:
    check_keys(flatten(config), {"scene": "", "seed": 0})


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
PROBE = RunKind(name="tests.kinds_for_tests:PROBE", validate=_probe_validate, run=_probe_run, result=ProbeRun,
                prepare=_probe_prepare, description="for tests: what a worker gets from the runner")
