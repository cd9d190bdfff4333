"""Run kinds: what one run of an experiment is.

A `RunKind` is a typed contract, the same for every kind (training, rasterizer timing,
one of your own); the runner never needs to know which kind it holds::

    config                                   its Config: the frozen dataclass of one run's
                                             settings, each dotted key of a run's config a field
                                             (`check_config`, `read_config`)
    result                                   its `RunResult` subclass: each metric a field made
                                             by `metric` (a ``metric.<name>`` column, with how a
                                             report shows it), plus ``warnings`` and ``curves``
    validate(config) -> None                 raise a one-line InputError naming the dotted field
    resolve(config) -> dict                  optional: the config with every default filled in
    identity(config) -> dict                 optional: what the run id hashes of a resolved config
    run(config, workdir, prepared) -> result one run, in a worker process
    scenes() -> set[str]                     optional: known scene names (None: any name)
    prepare(configs) -> Any                  optional: once, in the parent, before any run;
                                             what it returns is ``run``'s ``prepared``
    check_inputs(configs) -> list[str]       optional: cheap checks of what the runs will read
                                             (files, headers; nothing decoded or rendered), in the
                                             parent before anything runs and in ``--dry-run``: one
                                             InputError line, else a line per input checked
    protocols                                optional `KindProtocols`: a cell rerun under a named
                                             protocol (an experiment's ``[check]``)
    report                                   optional `KindReport`: what its reports show, and
                                             its report hooks (a report is handed the kind)

``config`` is the nested dict of one run: the experiment's base, overridden by its
axis values, plus ``scene`` and ``seed`` (`RUN_KEYS`). The engine checks every key of it
against the kind's Config before ``validate`` (`check_config`: a field, a field of a
dataclass-typed field such as ``raster.tile_size``, or an `INLINE` field's own at the top
level; an unknown key is one `InputError` line naming it), and a kind reads it onto its
Config with `read_config` (types, then the Config's own ``__post_init__`` checks).
`resolve`'s output is what the run id hashes and what `run` receives, so a kind that
fills in defaults makes ``sh_degree = 3`` written out and left to the default the same
run, and makes a changed default a new run. ``prepared`` is how the parent tells every
worker what it settled (plain, picklable data, e.g. the folder it rendered datasets into;
None for a kind without ``prepare``): it travels with each run, never through the
environment. `identity` (default: the resolved config itself) lets a kind hash what a run
depends on rather than where it was found: the train kind swaps a user's dataset folder or
model path for its content hash, so a committed report's run ids hold in any clone.

Workers find a kind by name in a fresh process, so a kind must be reachable by
name there: a built-in (`BUILTIN_KINDS`, imported lazily) or ``"package.module:ATTR"``
naming a module-level `RunKind`. `register_kind` serves the current process only:
the local executor's workers are spawned, and Dask's live in other processes, so
neither sees a kind registered at run time. ``tests/kinds_for_tests.py`` is a small
complete kind (the one the runner's tests use).
"""

from __future__ import annotations

import dataclasses
import math
import importlib
import typing
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from splatbench.guards import check_keys, dataclass_from_mapping
from splatbench.errors import InputError
from splatbench.experiments.kind_report import KindReport
from splatbench.metrics.spec import MetricSpec

#: A table cell: what a metric may be.
Scalar = bool | int | float | str | None


C = TypeVar("C")

#: The key of a `RunResult` field's metadata that holds its `MetricSpec` (`metric`).
METRIC = "splatbench.metric"


def metric(label: str = "", fmt: str = ".4g", unit: str = "", better: str = "", meaning: str = "", *,
           interval: bool = True, bounds: tuple[float, float] = (-math.inf, math.inf), default: Any = MISSING) -> Any:
    """A field of a kind's `RunResult` that is a metric: a table column ``metric.<field name>``,
    shown by a report as `MetricSpec` (``label``: the column heading, the field's name when
    empty; ``fmt``: one value's format; ``unit``; ``better``: "higher", "lower" or "";
    ``meaning``: what it is, in words; ``interval``: False where a table shows the mean alone;
    ``bounds``: the range its values lie in, where a printed interval is cut, `splatbench.metrics.spec.clip`).
    The field's value is a scalar: bool, int, float, str or None."""
    spec = MetricSpec("", label, fmt, unit, better, interval, meaning, bounds)
    return field(default=default, metadata={METRIC: spec})


@dataclass(frozen=True, kw_only=True)
class RunResult:
    """What a kind's ``run`` returns: a frozen dataclass subclassing this one, each metric a field
    made by `metric` (the kind's ``result``; `metric_specs` reads them), and

    warnings: one line each, what the run's own tool warned of (a training run's
        `TrainResult.warnings`, e.g. a budget not met); kept in the run's file, the table's
        ``warnings`` column (JSON) and the report's "Warnings" section, so that a grid never
        hides what a single run would have printed.
    curves: any JSON-serialisable value (e.g. ``{"step": [...], "psnr": [...]}``), kept whole in
        the run's file and as one JSON string column ``curves``.
    notes: one line each, what the run's tool noted of how it read its inputs (a training run's
        `TrainResult.notes`: the dataset loader's lines, the start's, the background's); kept in
        the run's file (`RunRecord.notes`) and the table's ``notes`` column, where a report reads them.
    """

    warnings: tuple[str, ...] = ()
    curves: Any = field(default_factory=dict)
    notes: tuple[str, ...] = ()


def metric_specs(result: type[RunResult]) -> tuple[MetricSpec, ...]:
    """The `MetricSpec` of each metric field of the `RunResult` class ``result``, in field order."""
    out = []
    for f in dataclasses.fields(result):
        spec = f.metadata.get(METRIC)
        if spec is not None:
            out.append(dataclasses.replace(spec, name=f.name, label=spec.label or f.name))
    return tuple(out)


# --------------------------------------------------------------------------- configs
#: Keys of every run's config, set by the engine from the experiment's ``scenes`` and ``seeds``
#: (a kind's Config may have fields of those names too).
RUN_KEYS = ("scene", "seed")
#: Field metadata of a Config field whose type is a dataclass read from keys at the field's own level
#: (``metadata={INLINE: True}``): a raster run's ``alpha_min``, not ``options.alpha_min``.
INLINE = "splatbench.inline"


def config_keys(config: type) -> dict[str, Any]:
    """Key -> its annotated type, every key a table of the dataclass ``config`` takes: its fields
    by name, an `INLINE` field's own fields in its place."""
    hints = _hints(config)
    out: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        if f.metadata.get(INLINE):
            out.update(config_keys(hints[f.name]))
        else:
            out[f.name] = hints[f.name]
    return out


def check_config(config: type, table: Mapping[str, Any], *, prefix: str = "") -> None:
    """A one-line `InputError` ``PREFIXKEY: unknown key (...)`` for the first key of ``table`` (a
    run's nested config) that the dataclass ``config`` does not take (`config_keys`, and at the top
    `RUN_KEYS`); a table under a field whose type is a dataclass is checked against that class
    (``raster.tile_sise`` against `RasterOptions`); a mapping field's keys, and those of a dataclass
    that reads its own table (a ``from_table`` classmethod: the train config's groups, whose ``data``
    table a grid shares with the scene's keys and whose ``strategy`` table holds the strategy's
    fields), are the kind's to check in ``validate``."""
    keys = config_keys(config)
    check_keys(table, {*keys, *(() if prefix else RUN_KEYS)}, prefix=prefix)
    for key, value in table.items():
        if isinstance(value, Mapping) and _is_dataclass_type(keys.get(key)) and \
                not hasattr(keys[key], "from_table"):
            check_config(keys[key], value, prefix=f"{prefix}{key}.")


def read_config(config: type[C], table: Mapping[str, Any], *, prefix: str = "") -> C:
    """The dataclass ``config`` of a run's nested config ``table``: each key onto the field of its
    name (`check_config` first), an `INLINE` field's keys onto that field's own, a table under a
    dataclass-typed field read the same way; `RUN_KEYS` the class has no field for are left out.
    Types are checked by `splatbench.guards.dataclass_from_mapping`, ranges by each class's
    ``__post_init__``: one `InputError` line naming the dotted key as the file writes it."""
    check_config(config, table, prefix=prefix)
    hints = _hints(config)
    values: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        tp = hints[f.name]
        if f.metadata.get(INLINE):
            own = config_keys(tp)
            values[f.name] = read_config(tp, {k: v for k, v in table.items() if k in own}, prefix=prefix)
        elif f.name in table:
            value = table[f.name]
            nested = _is_dataclass_type(tp) and isinstance(value, Mapping)
            values[f.name] = read_config(tp, value, prefix=f"{prefix}{f.name}.") if nested else value
    return dataclass_from_mapping(config, values, prefix=prefix)


def _hints(config: type) -> dict[str, Any]:
    """Field name -> its evaluated annotation (`typing.get_type_hints`)."""
    if not (isinstance(config, type) and dataclasses.is_dataclass(config)):
        raise TypeError(f"a run kind's config must be a dataclass, got {config!r}")
    return typing.get_type_hints(config)


def _is_dataclass_type(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


@dataclass(frozen=True)
class KindProtocols:
    """How a kind reruns a cell of a grid under a named protocol: what an experiment's
    ``[check]`` runs (docs/reports.md, "The protocol check").

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
    run: Callable[[dict[str, Any], Path, Any], RunResult]
    #: The `RunResult` subclass ``run`` returns: its metric fields are the table's ``metric.*`` columns.
    result: type[RunResult]
    #: The frozen dataclass of one run's settings: a run's config is read onto its fields (`read_config`;
    #: the engine checks every key against it, `check_config`, before ``validate``).
    config: type
    resolve: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    identity: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    scenes: Callable[[], set[str]] | None = None
    prepare: Callable[[list[dict[str, Any]]], Any] | None = None
    check_inputs: Callable[[list[dict[str, Any]]], list[str]] | None = None
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
    #: Whether a run finished for another experiment in the same results folder, under the same run
    #: id and config, stands for this experiment's run (the runner copies its record instead of
    #: running it again): True for a kind whose result depends only on its config (training), False
    #: where it depends on when it ran (timings taken side by side, alternately).
    reusable: bool = False

    def __post_init__(self) -> None:
        _hints(self.config)  # a dataclass whose annotations resolve (TypeError otherwise)
        if not (isinstance(self.result, type) and issubclass(self.result, RunResult)):
            raise TypeError(f"run kind {self.name!r}: result must be a RunResult subclass, got {self.result!r}")
        if self.report is not None:
            self.report.check(self.specs)

    @property
    def specs(self) -> dict[str, MetricSpec]:
        """Metric name -> `MetricSpec`, every metric of its ``result`` in field order."""
        return {m.name: m for m in metric_specs(self.result)}


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


def check_output(output: Any, kind: RunKind) -> RunResult:
    """``output`` if it is the kind's `RunResult` (its warnings made one line each); `TypeError`
    for anything else."""
    if not isinstance(output, kind.result):
        raise TypeError(f"run kind {kind.name!r} returned {type(output).__name__}, not {kind.result.__name__}")
    warnings, notes = tuple(output.warnings), tuple(output.notes)
    for name, lines in (("warnings", warnings), ("notes", notes)):
        if not all(isinstance(w, str) for w in lines):
            raise TypeError(f"run kind {kind.name!r}: {name} must be strings, got {list(lines)!r:.80}")
    return dataclasses.replace(output, warnings=tuple(" ".join(w.split()) for w in warnings),
                               notes=tuple(" ".join(n.split()) for n in notes))


def metric_values(result: RunResult) -> dict[str, Scalar]:
    """The metric fields of ``result`` as ``name -> scalar`` (NumPy / torch scalars made plain);
    `TypeError` naming a field that is not a scalar."""
    out: dict[str, Scalar] = {}
    for spec in metric_specs(type(result)):
        value = getattr(result, spec.name)
        if hasattr(value, "item") and getattr(value, "shape", None) == ():
            value = value.item()  # NumPy / torch scalar
        if value is not None and not isinstance(value, (bool, int, float, str)):
            raise TypeError(f"{type(result).__name__}.{spec.name} is a {type(value).__name__}, not a scalar")
        out[spec.name] = value
    return out


__all__ = ["RunKind", "RunResult", "metric", "metric_specs", "metric_values", "METRIC", "KindProtocols", "Scalar",
           "BUILTIN_KINDS", "register_kind", "get_kind", "check_output", "RUN_KEYS", "INLINE", "config_keys",
           "check_config", "read_config"]
