"""Grid expansion: an `ExperimentSpec` -> a deterministic list of `RunSpec`.

Order: scenes (file order), then the grid's cells (axes in file order, then
variants; the last one varies fastest), then seeds. ``grid = "product"`` takes every
combination; ``grid = "one-at-a-time"`` takes the base alone, then each axis value
(or variant) alone on top of the base. Cells whose resolved configs are equal
(for example an axis value equal to the base) are one run, listed once, first
occurrence first. Each scene's grid cells are followed by its ``[extra.DIMENSION]`` cells
(file order): the base plus the cell's fields, crossed with nothing, labelled on their
dimension by their own label; one that is the same runs as another cell is an error.

Run id: the first 16 hex digits of the SHA-256 of the canonical JSON (sorted keys,
no spaces, ASCII) of ``{"kind": KIND, "config": CONFIG}``, where CONFIG is the full
resolved nested config of the run, ``scene`` and ``seed`` included. It does not
depend on the experiment's name, on the order of keys or axes, or on which axis
set a value: the same config is the same run, and changing any field changes it.

`load_experiment` reads a file, parses it (`splatbench.experiments.spec`) and checks it
by expanding the grid here (`check_experiment`), so a bad file fails before anything runs.
"""

from __future__ import annotations

import hashlib
import itertools
import tomllib
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from splatbench.errors import InputError
from splatbench.experiments.configs import canonical_json, flatten, override, unflatten
from splatbench.experiments.kinds import RunKind, check_config
from splatbench.experiments.spec import ExperimentSpec, PublishedSpec, parse_experiment, same_value
from splatbench.fsutil import read_text


@dataclass(frozen=True)
class RunSpec:
    """One run of an experiment.

    experiment: the experiment's name; kind: the run-kind name; scene, seed: this run's;
    config: the resolved nested config the kind runs (``scene`` and ``seed`` included);
    run_id: 16 hex digits (module doc); labels: axis name -> this run's value of it
    (a plain axis: the config's value at its path; a variant axis: the label, or None
    for a one-at-a-time cell that leaves it at the base).
    """

    experiment: str
    kind: str
    scene: str
    seed: int
    config: Mapping[str, Any]
    run_id: str
    labels: Mapping[str, Any]


def make_run_id(kind: str, config: Mapping[str, Any]) -> str:
    """First 16 hex digits of sha256(canonical_json({"kind": kind, "config": config}))."""
    text = canonical_json({"kind": kind, "config": config})
    return hashlib.sha256(text.encode("ascii")).hexdigest()[:16]


def _choices(spec: ExperimentSpec) -> list[tuple[str, list[tuple[Any, dict[str, Any], str]]]]:
    """Each dimension: (name, [(label, flat settings, where-in-file)])."""
    dims = []
    for path, values in spec.axes.items():
        opts = []
        for v in values:  # a table value stays whole: override() drops the base's sub-table
            opts.append((v, {path: v}, f"axes.{path} = {canonical_json(v)}"))
        dims.append((path, opts))
    for name, labels in spec.variants.items():
        dims.append((name, [(label, dict(s), f"variants.{name}.{label}") for label, s in labels.items()]))
    return dims


def _cells(spec: ExperimentSpec, dims) -> list[list[tuple[str, Any, dict[str, Any], str]]]:
    """Cells as lists of (dimension, label, settings, where)."""
    if spec.grid == "product":
        return [[(name, *choice) for (name, _), choice in zip(dims, combo)]
                for combo in itertools.product(*(opts for _, opts in dims))]
    cells: list[list] = [[]]
    for name, opts in dims:
        cells.extend([[(name, *choice)] for choice in opts])
    return cells


def expand(spec: ExperimentSpec, *, known_scenes: Callable[[], set[str]] | None = None) -> list[RunSpec]:
    """Every run of ``spec``, in order, each config checked by the kind's ``validate``.

    Raises one `InputError` line (``SOURCE: WHERE: problem``) for an unknown kind, an
    unknown scene (``known_scenes`` or the kind's ``scenes``; neither: any name) or a
    config the kind rejects; nothing runs.
    """
    kind = spec.run_kind
    scene_source = known_scenes or kind.scenes
    if scene_source is not None:
        known = scene_source()
        for scene in spec.scenes:
            if scene in known and scene in spec.scene_sources:
                raise InputError(f"{spec.source}: scenes.{scene}: the name of a catalog scene; give the table "
                                 f"another name (its runs and results are told apart by it)")
            if scene not in known and scene not in spec.scene_sources:
                hint = ""
                if "/" in scene or scene.endswith(".ply"):  # a path given where a table is needed
                    key = "model" if scene.endswith(".ply") else "path"
                    hint = (f"; a {'model' if key == 'model' else 'dataset folder'} is given as a table: "
                            f'{{ name = "NAME", {key} = "{scene}" }}')
                raise InputError(f"{spec.source}: scenes: unknown scene {scene!r} "
                                 f"(known: {', '.join(sorted(known)) or 'none'}){hint}")

    dims = _choices(spec)
    make = _run_maker(spec, kind)
    runs: list[RunSpec] = []
    seen: dict[str, str] = {}  # run id -> where its cell is written (an extra cell's: extra.DIM.LABEL)
    extras = [[(dim, label, dict(s), f"extra.{dim}.{label}")] for dim, labels in spec.extra.items()
              for label, s in labels.items()]
    for scene in spec.scenes:
        for cell in _cells(spec, dims):
            for seed in spec.seeds:
                run = make(cell, scene, seed)
                if run.run_id in seen:
                    continue
                seen[run.run_id] = "a cell of the grid"
                runs.append(run)
        for cell in extras:
            if not spec.extra_runs_at(cell[0][0], cell[0][1], scene):
                continue
            for seed in spec.seeds:
                run = make(cell, scene, seed, extra=True)
                if run.run_id in seen:
                    raise InputError(f"{spec.source}: {cell[0][3]}: the same runs as {seen[run.run_id]} (the same "
                                     f"config); give it fields that make it a cell of its own")
                seen[run.run_id] = cell[0][3]
                runs.append(run)
    return runs


def _run_maker(spec: ExperimentSpec, kind, protocol: str | None = None
               ) -> Callable[..., RunSpec]:
    """``make(cell, scene, seed, extra=False) -> RunSpec``: one run of a cell (as `_cells` lists
    them; ``extra``: an ``[extra.DIMENSION]`` cell, labelled by its own label on a plain axis too),
    its config checked by the kind (one `InputError` line naming where in the file a bad value
    comes from), resolved and named by its run id; under ``protocol`` (an experiment's ``[check]``),
    the kind's `KindProtocols.apply` rewrites the cell's config first."""
    variant_names = set(spec.variants)
    checked: dict[str, str | None] = {}

    def check(flat: dict[str, Any]) -> str | None:
        key = canonical_json(flat)
        if key not in checked:
            try:
                nested = unflatten(flat)
                check_config(kind.config, nested)  # every key a field of the kind's Config
                kind.validate(nested)
                checked[key] = None
            except InputError as exc:
                checked[key] = str(exc)
        return checked[key]

    def make(cell, scene: str, seed: int, extra: bool = False) -> RunSpec:
        flat = dict(spec.base)
        for _, _, settings, where in cell:
            for path in settings:  # a base value an axis would set keys inside: never dropped silently
                above = next((key for key in spec.base if path.startswith(key + ".")), None)
                if above is not None:
                    raise InputError(f"{spec.source}: base.{above}: a value ({canonical_json(spec.base[above])}), but "
                                     f"{where} sets {path} inside it; write [base.{above}] as a table, or leave it out")
            flat = override(flat, settings)
        flat = {**flat, **_source(spec, scene), "scene": scene, "seed": seed}
        if protocol is not None:
            try:
                flat = flatten(kind.protocols.apply(unflatten(flat), protocol))
            except InputError as exc:
                raise InputError(f"{spec.source}: check.{exc}") from None
        problem = check(flat)
        if problem is not None:
            where = "check" if protocol is not None else _culprit(spec, cell, scene, seed, check, problem)
            raise InputError(f"{spec.source}: {where}: {problem}")
        config = unflatten(flat)
        if kind.resolve is not None:
            try:
                config = kind.resolve(config)
            except InputError as exc:
                where = "check" if protocol is not None else _culprit(spec, cell, scene, seed, check)
                raise InputError(f"{spec.source}: {where}: {exc}") from None
        rid = make_run_id(spec.kind, kind.identity(config) if kind.identity is not None else config)
        resolved = flatten(config) if config else {}
        chosen = {name: label for name, label, _, _ in cell}
        labels = {name: (chosen.get(name) if name in variant_names or (extra and name in chosen)
                         else _label(resolved, name)) for name in spec.dimensions}
        return RunSpec(experiment=spec.name, kind=spec.kind, scene=scene, seed=seed, config=config, run_id=rid,
                       labels=labels)

    return make


def check_cells(spec: ExperimentSpec, *, at_protocol: bool = True) -> tuple[list[RunSpec], list[RunSpec]]:
    """The runs of the experiment's ``[check]`` (`CheckSpec`), one list per cell (reference
    first), one run per seed, at its scene: under the check's protocol (the kind's
    `KindProtocols.apply`: their own run ids, since their configs differ), or with
    ``at_protocol=False`` as the grid runs those cells (the grid's own runs of them: the
    quick side of the comparison). ``([], [])`` for an experiment without a check. One
    `InputError` line for a kind without protocols, a protocol it does not know, or a check
    whose runs are the grid's (a protocol the grid already runs)."""
    if spec.check is None:
        return [], []
    kind = spec.run_kind
    if kind.protocols is None:
        raise InputError(f"{spec.source}: check: run kind {spec.kind!r} has no protocols to check a headline at "
                         f"(remove the [check] table)")
    make = _run_maker(spec, kind, spec.check.protocol if at_protocol else None)
    a, b = ([make(cell, spec.check.scene, seed) for seed in spec.seeds]
            for cell in _named_cells(spec, spec.check.cells))
    if {r.run_id for r in a} == {r.run_id for r in b}:
        raise InputError(f"{spec.source}: check.cells: both cells are the same runs (a value equal to the base is "
                         f"the base)")
    if at_protocol:
        grid = {r.run_id for r in expand(spec)}
        if any(r.run_id in grid for r in (*a, *b)):
            raise InputError(f"{spec.source}: check.protocol: the grid already runs {spec.check.protocol!r}; a check "
                             f"reruns its headline at another protocol")
    return a, b


def _named_cells(spec: ExperimentSpec, cells) -> list[list[tuple[str, Any, dict[str, Any], str]]]:
    """Cells named as ``dimension -> value`` (`CheckSpec.cells`, `PublishedSpec.cells`; spec.py checked
    each is a cell of the grid) as `_cells` lists them: each value's choice, whose label is the value."""
    dims = dict(_choices(spec))
    return [[(name, *next((lab, s, w) for lab, s, w in dims[name] if same_value(value, lab)))
             for name, value in values.items()] for values in cells]


def published_runs(spec: ExperimentSpec, entry: PublishedSpec) -> tuple[list[RunSpec], ...]:
    """The grid's runs of a ``[report] published`` entry's cells (`PublishedSpec`), one list per cell
    (A first), each of every seed at the entry's scene (a difference: at every scene of the grid, in
    file order). One `InputError` line for a metric the kind's reports do not show, or two cells
    that are the same runs (a value equal to a one-at-a-time grid's base is its base)."""
    kind = spec.run_kind
    at = next((f"[{i}]" for i, e in enumerate(spec.published) if e is entry), "")
    where = f"{spec.source}: report.published{at}"
    shown = reported_metrics(kind)
    if entry.metric is not None and entry.metric not in shown:
        raise InputError(f"{where}.metric: {entry.metric!r} is not a metric {spec.kind!r} reports "
                         f"(expected one of: {', '.join(shown)})")
    if entry.metric is None and kind.report is not None and kind.report.rules is None:
        raise InputError(f"{where}.metric: missing ({spec.kind!r} has no headline metric; name one of: "
                         f"{', '.join(shown)})")
    scenes = spec.scenes if entry.scene is None else (entry.scene,)
    make = _run_maker(spec, kind)
    out = tuple([make(cell, scene, seed) for scene in scenes for seed in spec.seeds]
                for cell in _named_cells(spec, entry.cells))
    if len(out) == 2 and {r.run_id for r in out[0]} == {r.run_id for r in out[1]}:
        raise InputError(f"{where}.cells: both cells are the same runs (a value equal to the base is the base)")
    return out


def reported_metrics(kind: RunKind) -> list[str]:
    """The metrics a report of ``kind`` can show: those its `KindReport` names, else its result's
    numeric metric fields (`splatbench.reports.tables.metric_specs` keeps those a table holds)."""
    if kind.report is not None:
        return list(kind.report.metrics)
    hints = typing.get_type_hints(kind.result)
    return [name for name in kind.specs if hints.get(name) in (int, float)]


def check_runs(spec: ExperimentSpec) -> list[RunSpec]:
    """Every run of the experiment's ``[check]`` (`check_cells` under its protocol): the
    reference cell's seeds, then the other's; [] without a check."""
    a, b = check_cells(spec)
    return [*a, *b]


def _source(spec: ExperimentSpec, scene: str) -> dict[str, Any]:
    """A scene table's fields as flat ``data.*`` keys (they win over the base's)."""
    return {f"data.{k}": v for k, v in spec.scene_sources.get(scene, {}).items()}


def _label(resolved: Mapping[str, Any], path: str) -> Any:
    """A plain axis's label: the resolved config's value at its path (a sub-table as JSON)."""
    if path in resolved:
        value = resolved[path]
        return value if value is None or isinstance(value, (bool, int, float, str)) else canonical_json(value)
    sub = {k[len(path) + 1:]: v for k, v in resolved.items() if k.startswith(path + ".")}
    return canonical_json(unflatten(sub)) if sub else None


def _culprit(spec: ExperimentSpec, cell, scene: str, seed: int, check, problem: str | None = None) -> str:
    """Where in the file a rejected config comes from: base, one axis value, or the cell. With
    ``problem`` (the cell's own message), the base or a value is named only when it alone gives
    that same problem: a base that fails otherwise by itself (a strategy it never runs with, say)
    is not blamed for what one value brings."""
    def fails(flat: dict[str, Any]) -> bool:
        found = check(flat)
        return found is not None and (problem is None or found == problem)

    base = {**spec.base, **_source(spec, scene), "scene": scene, "seed": seed}
    if fails(base):
        return "base"
    for _, _, settings, where in cell:
        if fails(override(base, settings)):
            return where
    return "combination " + ", ".join(where for *_, where in cell)


# --------------------------------------------------------------------------- loading
def load_experiment(path: str | Path, *, known_scenes: Callable[[], set[str]] | None = None) -> ExperimentSpec:
    """Read, parse and fully check an experiment file (see `check_experiment`)."""
    p = Path(path)
    text = read_text(p, "experiment")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: invalid TOML ({exc})") from None
    spec = parse_experiment(data, source=str(p), default_name=p.stem, base_dir=p.parent)
    check_experiment(spec, known_scenes=known_scenes)
    return spec


def check_experiment(spec: ExperimentSpec, *, known_scenes: Callable[[], set[str]] | None = None) -> None:
    """Check the kind exists, every scene is known (``known_scenes``, else the kind's
    ``scenes``; neither: any name) and every run's config passes the kind's
    ``validate``, by expanding the grid and its check, and the runs of each ``[report] published``
    entry (`published_runs`). Raises one `InputError` line; runs nothing."""
    expand(spec, known_scenes=known_scenes)
    check_runs(spec)
    for entry in spec.published:
        published_runs(spec, entry)


__all__ = ["RunSpec", "expand", "check_cells", "check_runs", "published_runs", "reported_metrics",
           "make_run_id", "load_experiment", "check_experiment"]
