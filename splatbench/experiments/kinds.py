"""Run kinds: what one run of an experiment is.

A `RunKind` is a small record of callables with one typed signature for every kind
(training, rasterizer timing, one of your own); the runner never needs to know which
kind it holds::

    validate(config) -> None                 raise a one-line InputError naming the dotted field
    resolve(config) -> dict                  optional: the config with every default filled in
    identity(config) -> dict                 optional: what the run id hashes of a resolved config
    run(config, workdir, prepared) -> RunOutput   one run, in a worker process
    scenes() -> set[str]                     optional: known scene names (None: any name)
    prepare(configs) -> Any                  optional: once, in the parent, before any run;
                                             what it returns is ``run``'s ``prepared``
    protocols                                optional `KindProtocols`: a cell rerun under a named
                                             protocol (an experiment's ``[check]``)

``config`` is the nested dict of one run: the experiment's base, overridden by its
axis values, plus ``scene`` and ``seed``. `resolve`'s output is what the run id
hashes and what `run` receives, so a kind that fills in defaults makes
``sh_degree = 3`` written out and left to the default the same run, and makes a
changed default a new run. ``prepared`` is how the parent tells every worker what it
settled (plain, picklable data, e.g. the folder it rendered datasets into; None for a
kind without ``prepare``): it travels with each run, never through the environment. `identity` (default: the resolved config itself) lets a kind
hash what a run depends on rather than where it was found: the train kind swaps a user's
dataset folder or model path for its content hash, so a committed report's run ids hold in
any clone.

Workers find a kind by name in a fresh process, so a kind must be reachable by
name there: a built-in (`BUILTIN_KINDS`, imported lazily) or ``"package.module:ATTR"``
naming a module-level `RunKind`. `register_kind` serves the current process only:
the local executor's workers are spawned, and Dask's live in other processes, so
neither sees a kind registered at run time. ``tests/kinds_for_tests.py`` is a small
complete kind (the one the runner's tests use).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from splatbench.errors import InputError
from splatbench.experiments.kind_report import KindReport

#: A table cell: what a metric may be.
Scalar = bool | int | float | str | None


@dataclass(frozen=True)
class RunOutput:
    """What a kind's ``run`` returns.

    metrics: flat ``name -> scalar`` (bool, int, float, str or None); each becomes a
        table column ``metric.<name>``.
    curves: any JSON-serialisable value (e.g. ``{"step": [...], "psnr": [...]}``), kept
        whole in the run's file and as one JSON string column ``curves``.
    warnings: one line each, what the run's own tool warned of (a training run's
        `TrainResult.warnings`, e.g. a budget not met); kept in the run's file, the
        table's ``warnings`` column (JSON) and the report's "Warnings" section, so that a
        grid never hides what a single run would have printed.
    """

    metrics: Mapping[str, Scalar]
    curves: Any = field(default_factory=dict)
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class KindProtocols:
    """How a kind reruns a cell of a grid under a named protocol: what an experiment's
    ``[check]`` runs (docs/reports.md, "The 7K check").

    apply(config, name) -> config: a run's nested, unresolved config under protocol ``name``
        (the train kind: ``protocol = name``, the protocol's own length and test-curve
        spacing); a one-line `InputError` for a name it does not know, or one a check cannot
        run at.
    describe(name) -> str: the protocol in words, for the report (what it stands beside).
    """

    apply: Callable[[dict[str, Any], str], dict[str, Any]]
    describe: Callable[[str], str]


@dataclass(frozen=True)
class RunKind:
    """One kind of run (see the module doc for each callable's contract)."""

    name: str
    validate: Callable[[dict[str, Any]], None]
    run: Callable[[dict[str, Any], Path, Any], RunOutput]
    resolve: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    identity: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    scenes: Callable[[], set[str]] | None = None
    prepare: Callable[[list[dict[str, Any]]], Any] | None = None
    description: str = ""
    #: What its reports show (None: every numeric metric, the first one compared).
    report: KindReport | None = None
    #: ``planned(config) -> {metric: number}``: the confound counts a run's config fixes in
    #: advance (e.g. opacity resets), which a report names for runs that did not record them
    #: (`KindReport.confounds`); None: none.
    planned: Callable[[dict[str, Any]], dict[str, float]] | None = None
    #: How a cell is rerun under a named protocol (an experiment's ``[check]``); None: the kind has
    #: no protocols, and an experiment of it with a ``[check]`` is refused.
    protocols: KindProtocols | None = None


#: Kinds known by name in every process: name -> "module:ATTR" (imported on first use).
BUILTIN_KINDS: dict[str, str] = {
    "train": "splatbench.experiments.train_kind:TRAIN",
    "raster": "splatbench.experiments.raster_kind:RASTER",
}
_REGISTERED: dict[str, RunKind] = {}


def register_kind(kind: RunKind) -> RunKind:
    """Make ``kind`` known by name in this process (not in spawned workers; see module doc)."""
    _REGISTERED[kind.name] = kind
    return kind


def get_kind(name: str) -> RunKind:
    """The kind called ``name``: registered here, built in, or ``"module:ATTR"``."""
    if name in _REGISTERED:
        return _REGISTERED[name]
    target = BUILTIN_KINDS.get(name, name if ":" in name else None)
    if target is None:
        known = ", ".join(sorted({*BUILTIN_KINDS, *_REGISTERED}))
        raise InputError(f"kind: unknown run kind {name!r} (known: {known}; or 'package.module:ATTR')")
    module, _, attr = target.partition(":")
    try:
        kind = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise InputError(f"kind: cannot load run kind {name!r} from {target!r} ({exc})") from None
    if not isinstance(kind, RunKind):
        raise InputError(f"kind: {target!r} is a {type(kind).__name__}, not a RunKind")
    return kind


def check_output(output: Any, kind: str) -> RunOutput:
    """``output`` as a `RunOutput` whose metrics are plain Python scalars (NumPy scalars
    are converted); `TypeError` for anything else."""
    if not isinstance(output, RunOutput):
        raise TypeError(f"run kind {kind!r} returned {type(output).__name__}, not RunOutput")
    metrics: dict[str, Scalar] = {}
    for key, value in output.metrics.items():
        if not isinstance(key, str) or not key:
            raise TypeError(f"run kind {kind!r}: metric name {key!r} is not a non-empty string")
        if hasattr(value, "item") and getattr(value, "shape", None) == ():
            value = value.item()  # NumPy / torch scalar
        if value is not None and not isinstance(value, (bool, int, float, str)):
            raise TypeError(f"run kind {kind!r}: metric {key!r} is a {type(value).__name__}, not a scalar")
        metrics[key] = value
    warnings = tuple(output.warnings)
    if not all(isinstance(w, str) for w in warnings):
        raise TypeError(f"run kind {kind!r}: warnings must be strings, got {list(warnings)!r:.80}")
    return RunOutput(metrics=metrics, curves=output.curves, warnings=tuple(" ".join(w.split()) for w in warnings))


__all__ = ["RunKind", "RunOutput", "KindProtocols", "Scalar", "BUILTIN_KINDS", "register_kind", "get_kind",
           "check_output"]
