"""`ExperimentSpec`: an experiment file (TOML) parsed and checked.

An experiment names a run kind, scenes, seeds, a base config and the axes that
sweep it (docs/experiments.md has the full format)::

    name = "densification"            # results/<name>/ (default: the file's stem)
    kind = "train"                    # a registered run kind (splatbench.experiments.kinds)
    scenes = ["diffuse", "glossy",    # catalog names, dataset folders, teacher models:
              { name = "fox", path = "../shared/data/fox", downscale = 8 },
              { name = "guitar", model = "../splatbench/data/models/pc_guitar.ply", views = 64, resolution = 128 }]
    seeds = [0, 1, 2]
    grid = "product"                  # or "one-at-a-time"

    [base]                            # config fields shared by every run
    iterations = 2000

    [axes]                            # field -> values; the grid is their cartesian product
    ssim_lambda = [0.0, 0.2]

    [variants.densify]                # one axis whose values set several fields together
    none = { strategy = "none" }
    mcmc = { strategy = "mcmc", strategy.cap_max = 50000 }   # dotted: a nested field

    [extra.ssim_lambda]               # cells outside the grid, each a labelled row of one of its
    "0.2 at 6k" = { ssim_lambda = 0.2, strategy.name = "budget", strategy.budget = 6000 }
                                      # dimensions: the base plus these fields, crossed with nothing

    [runner]                          # defaults of `splatbench run` (the command line wins)
    workers = 2

    [report]                          # how `splatbench report` reads the results (changes no run)
    min_effect = { test_psnr = 0.2 }  # the smallest difference that matters (docs/reports.md)
    matched = { size = "matched" }    # cells at one matched model size (a value, or a list of
                                      # values matched to each other: { densify = ["mcmc", "budget"] })
    quick = "../reports/x_quick"      # the same grid at the quick protocol (a report folder or a
                                      # run table, relative to this file): its ranks beside these
    [[report.published]]              # a published number the report sets this grid's beside:
    cells = [{ densify = "mcmc" }, { densify = "none" }]   # A against B (or cell = {...}, scene = "x":
    value = 0.5                       # one cell's value on one scene); value: A - B as published;
    source = "where it is published"  # metric (default: the kind's headline), source and protocol
    protocol = "graphdeco-30k, ..."   # (both required) as docs/reports.md, "Beside published numbers"
    notes = ["maryrose's test view 8: ..."]  # what the author knows of the data that no number shows
                                      # (a defective mask, ...): printed as the author's, not computed

    [check]                           # the headline rerun at the field's protocol (docs/reports.md,
    protocol = "graphdeco-7k"         # "The protocol check"): two cells of the grid, one of its scenes,
    scene = "textured"                # every seed; `splatbench run` runs them after the grid
    cells = [{ densify = "none" }, { densify = "mcmc" }]   # reference first: one value per axis

Dotted keys: a config is held *flat*, as ``dotted.path -> value``. A TOML sub-table
(``[base.raster]``), a TOML dotted key (``raster.tile_size = 8``) and a quoted key
with dots (``"raster.tile_size" = 8``) all name the same field ``raster.tile_size``;
the kind receives the nested form (``{"raster": {"tile_size": 8}}``). A value set by
an axis or a variant replaces the base value at its path; no two of them (axes, variant
tables, a scene table's ``data.*`` field) may set overlapping paths, since in a cell
with both the later would drop the other's value: a one-line error naming both. An axis value that is a
table (``opts = [{a = 1}, {a = 2, b = 3}]``) replaces the whole sub-table: no key of
the base's sub-table survives. Inside a variant, a nested table is read as dotted
keys: each leaf is set on its own and the base's other keys stay.

Parsing checks the file's structure (`parse_experiment`); `grid.load_experiment` also
checks the kind, the scenes and every run's config against the kind (by expanding
the grid), so that a bad file fails with one `InputError` line before anything runs.
The dotted-key helpers (`flatten`, `unflatten`, `override`) and `canonical_json` live
in `splatbench.experiments.configs`, shared by this module, the grid and the kinds.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from splatbench.guards import unknown_key_problem
from splatbench.errors import InputError
from splatbench.experiments.configs import FIELD_KEY, canonical_json, check_value, flatten, overlaps
from splatbench.experiments.kinds import RunKind, get_kind

#: Fields an experiment file may hold at its top level.
TOP_LEVEL_FIELDS = ("name", "description", "kind", "grid", "scenes", "seeds", "base", "axes", "variants", "extra",
                    "runner", "report", "check")
#: Fields of its ``[check]`` table.
CHECK_FIELDS = ("protocol", "scene", "cells")
#: Fields of its ``[runner]`` table.
RUNNER_FIELDS = ("workers", "executor", "scheduler", "results")
#: Why two dimensions (axes, variants) may not set overlapping paths, in their error lines.
DROPS = "in a cell with both, the later would drop the other's value"
#: How axes combine: every combination, or each value alone against the base.
GRID_MODES = ("product", "one-at-a-time")
EXECUTORS = ("local", "dask")
#: Config keys the runner sets itself from ``scenes`` and ``seeds``.
RESERVED_KEYS = ("scene", "seed")

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_SCHEDULER = re.compile(r"^(tcp|tls|ucx|inproc)://\S+$")


@dataclass(frozen=True)
class RunnerDefaults:
    """The ``[runner]`` table: defaults of `splatbench run`, overridden by its options.

    workers: parallel runs (None: one per CPU); executor: "local" or "dask";
    scheduler: a Dask scheduler address ``tcp://HOST:PORT`` (dask only);
    results: results folder (relative paths resolve against the experiment file).
    """

    workers: int | None = None
    executor: str | None = None
    scheduler: str | None = None
    results: Path | None = None


@dataclass(frozen=True)
class CheckSpec:
    """The ``[check]`` table: the grid's headline comparison rerun under another protocol
    (docs/reports.md, "The protocol check").

    protocol: the protocol's name (the kind applies it: `KindProtocols`); scene: one of the
    grid's scenes; cells: (reference, compared), each ``dimension -> value`` (a plain axis's
    value, a variant's label) naming one cell of the grid: every dimension of a product grid,
    at most one of a one-at-a-time grid (none: its base). The check's difference is
    compared minus reference, paired over every seed of the grid.
    """

    protocol: str
    scene: str
    cells: tuple[Mapping[str, Any], Mapping[str, Any]]


@dataclass(frozen=True)
class PublishedSpec:
    """One entry of ``[report] published``: a published number the report sets the grid's own beside
    (docs/reports.md, "Beside published numbers").

    cells: (A, B) for a published difference A − B, or (A,) for a published value of one cell; each
    ``dimension -> value`` naming one cell of the grid, as `CheckSpec.cells`; scene: the grid's scene
    an absolute value is of (None for a difference: every scene of the grid stands beside it);
    value: the published number; metric: the metric it is of (None: the kind's headline, its
    findings' primary metric); source: where it is published; protocol: its protocol (free text or
    a protocol's name).
    """

    cells: tuple[Mapping[str, Any], ...]
    value: float
    source: str
    protocol: str
    metric: str | None = None
    scene: str | None = None

    @property
    def is_difference(self) -> bool:
        return len(self.cells) == 2


@dataclass(frozen=True)
class ExperimentSpec:
    """One experiment. Configs are flat (``dotted.path -> value``, see the module doc).

    name: results folder name; kind: run-kind name; scenes, seeds: the outer axes;
    base: fields shared by every run; axes: path -> values swept (file order);
    variants: axis name -> label -> fields set together; grid: "product" or
    "one-at-a-time"; source: the file it came from (for messages), if any.
    """

    name: str
    kind: str
    scenes: tuple[str, ...]
    seeds: tuple[int, ...] = (0,)
    base: Mapping[str, Any] = field(default_factory=dict)
    axes: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    variants: Mapping[str, Mapping[str, Mapping[str, Any]]] = field(default_factory=dict)
    grid: str = "product"
    description: str = ""
    runner: RunnerDefaults = field(default_factory=RunnerDefaults)
    source: str = "experiment"
    scene_sources: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)  # name -> its table's
    #   ``data`` fields (``path``/``downscale`` or ``model``/``views``/``resolution``/``up``), paths absolute
    scene_tables: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)  # name -> its table as written
    #   (paths as the file gives them, relative to it): what a report shows, the same in every clone
    min_effect: Mapping[str, float] = field(default_factory=dict)  # ``[report] min_effect``: metric -> the
    #   smallest difference that matters (overrides the kind's; docs/reports.md, "Minimum effects")
    check: CheckSpec | None = None  # ``[check]``: the headline at another protocol (None: none declared)
    matched: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)  # ``[report] matched``: a dimension
    #   -> the values whose cells end at one matched model size (docs/reports.md, "Model size")
    quick: str | None = None  # ``[report] quick``: the same grid's quick-protocol results, as written
    #   (relative to the file; docs/reports.md, "Rank agreement")
    published: tuple[PublishedSpec, ...] = ()  # ``[report] published``: published numbers to stand beside
    #   (docs/reports.md, "Beside published numbers")
    extra: Mapping[str, Mapping[str, Mapping[str, Any]]] = field(default_factory=dict)  # ``[extra.DIMENSION]``:
    #   dimension -> label -> fields: cells outside the grid (the base plus those fields, crossed with nothing),
    #   each its own row of that dimension's table, compared only where ``[report] matched`` names it
    extra_scenes: Mapping[str, Mapping[str, tuple[str, ...]]] = field(default_factory=dict)  # dimension -> label
    #   -> the scenes an extra cell runs at (its ``scenes = [...]``); a cell not listed runs at every scene
    notes: tuple[str, ...] = ()  # ``[report] notes``: the author's notes on the data, printed as stated

    def extra_runs_at(self, dim: str, label: str, scene: str) -> bool:
        """Whether the extra cell ``label`` of ``dim`` runs at ``scene`` (its ``scenes``; every scene without)."""
        at = self.extra_scenes.get(dim, {}).get(label)
        return at is None or scene in at

    @property
    def run_kind(self) -> RunKind:
        """The run kind ``kind`` names (`splatbench.experiments.kinds.get_kind`: a worker finds it
        the same way, by name); a one-line `InputError` ``SOURCE: kind: ...`` for an unknown one.
        What a report is handed (it never looks a kind up by name)."""
        try:
            return get_kind(self.kind)
        except InputError as exc:
            raise InputError(f"{self.source}: {exc}") from None

    @property
    def dimensions(self) -> list[str]:
        """Axis names in grid order: plain axes (their dotted paths), then variants."""
        return [*self.axes, *self.variants]


# --------------------------------------------------------------------------- parsing
def parse_experiment(data: Mapping[str, Any], *, source: str = "experiment",
                     default_name: str | None = None, base_dir: Path | None = None) -> ExperimentSpec:
    """An `ExperimentSpec` from a parsed TOML table; structure only (the kind, scenes
    and configs are checked by `check_experiment`). Errors are one `InputError` line
    ``SOURCE: FIELD: problem``."""

    def fail(where: str, problem: str) -> InputError:
        return InputError(f"{source}: {where}: {problem}")

    for key in data:
        if key not in TOP_LEVEL_FIELDS:
            raise fail(key, unknown_key_problem(key, TOP_LEVEL_FIELDS))

    name = data.get("name", default_name)
    if not isinstance(name, str) or not _NAME.match(name):
        raise fail("name", f"expected a folder-safe name (letters, digits, '_', '-', '.'), got {name!r}")
    kind = data.get("kind")
    if not isinstance(kind, str) or not kind:
        raise fail("kind", f"expected the name of a run kind, got {kind!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise fail("description", f"expected a string, got {description!r}")
    grid = data.get("grid", "product")
    if grid not in GRID_MODES:
        raise fail("grid", f"expected one of {', '.join(map(repr, GRID_MODES))}, got {grid!r}")

    entries = data.get("scenes")
    if not isinstance(entries, list) or not entries:
        raise fail("scenes", f"expected a non-empty list of scene names or tables, got {entries!r}")
    scenes, scene_sources, scene_tables = [], {}, {}
    for i, s in enumerate(entries):
        if isinstance(s, Mapping):
            scene_name, fields = _scene_table(s, f"scenes[{i}]", fail, base_dir)
            scenes.append(scene_name)
            scene_sources[scene_name] = fields
            scene_tables[scene_name] = {k: v for k, v in s.items() if k != "name"}
        elif isinstance(s, str) and s:
            scenes.append(s)
        else:
            raise fail("scenes", f"expected scene names (strings) or tables, got {s!r}")
    _no_duplicates(scenes, "scenes", fail)
    seeds = data.get("seeds", [0])
    if not isinstance(seeds, list) or not seeds:
        raise fail("seeds", f"expected a non-empty list of ints, got {seeds!r}")
    for s in seeds:
        if not isinstance(s, int) or isinstance(s, bool):
            raise fail("seeds", f"expected ints, got {s!r}")
    _no_duplicates(seeds, "seeds", fail)

    base_table = data.get("base", {})
    if not isinstance(base_table, Mapping):
        raise fail("base", f"expected a table of config fields, got {base_table!r}")
    base = flatten(base_table, where=f"{source}: base")
    for path, value in base.items():
        check_value(value, f"{source}: base.{path}")

    axes_table = data.get("axes", {})
    if not isinstance(axes_table, Mapping):
        raise fail("axes", f"expected a table of field = [values], got {axes_table!r}")
    axes: dict[str, tuple[Any, ...]] = {}
    for path, values in _flatten_axes(axes_table, "", fail).items():
        if not values:
            raise fail(f"axes.{path}", "empty axis (an axis needs at least one value)")
        for i, v in enumerate(values):
            check_value(v, f"{source}: axes.{path}[{i}]")
        _no_duplicates(values, f"axes.{path}", fail)
        axes[path] = tuple(values)

    variants_table = data.get("variants", {})
    if not isinstance(variants_table, Mapping):
        raise fail("variants", f"expected [variants.NAME] tables, got {variants_table!r}")
    variants: dict[str, dict[str, dict[str, Any]]] = {}
    for vname, labels in variants_table.items():
        where = f"variants.{vname}"
        if not isinstance(labels, Mapping):
            raise fail(where, f"expected a table of label = {{ field = value, ... }}, got {labels!r}")
        if not labels:
            raise fail(where, "empty axis (a variant axis needs at least one label)")
        if vname in axes:
            raise fail(where, f"name clashes with the axis {vname!r}")
        earlier = _variant_paths(variants)  # what the variant axes before this one set
        variants[vname] = {}
        for label, settings in labels.items():
            if not isinstance(settings, Mapping):
                raise fail(f"{where}.{label}", f"expected a table of config fields, got {settings!r}")
            flat = flatten(settings, where=f"{source}: {where}.{label}") if settings else {}
            for path, value in flat.items():
                check_value(value, f"{source}: {where}.{label}.{path}")
                for axis in axes:
                    if overlaps(path, axis):
                        raise fail(f"{where}.{label}.{path}", f"also swept by axes.{axis} ({DROPS}); set it in the "
                                                              f"axis or in the variant, not both")
                hit = next((w for w, p in earlier if overlaps(path, p)), None)
                if hit is not None:
                    raise fail(f"{where}.{label}.{path}", f"overlaps {hit} ({DROPS}); set it in one variant, or "
                                                          f"merge the two into one [variants.NAME] table")
            variants[vname][str(label)] = flat

    swept = [*((f"axes.{p}", p) for p in axes), *_variant_paths(variants)]
    for scene_name, fields in scene_sources.items():  # a scene's data.* win over the base's, never over a sweep
        for key in fields:
            hit = next((w for w, p in swept if overlaps(f"data.{key}", p)), None)
            if hit is not None:
                raise fail(f"scenes.{scene_name}.{key}", f"sets data.{key}, which {hit} sweeps (the scene's value "
                                                         f"would drop the swept one in its runs); leave it out of "
                                                         f"one of them")

    for where, paths in [("base", base), *((f"axes.{p}", [p]) for p in axes),
                         *((f"variants.{v}.{lab}", s) for v, labs in variants.items() for lab, s in labs.items())]:
        for path in paths:
            if path.split(".")[0] in RESERVED_KEYS:
                raise fail(where, f"{path!r} is set by the top-level 'scenes' / 'seeds', not here")

    extra, extra_scenes = _parse_extra(data.get("extra", {}), fail, source, axes, variants, scenes)
    for scene_name, fields in scene_sources.items():  # a scene's data.* would drop an extra cell's too
        for key in fields:
            hit = next((f"extra.{d}.{lab}" for d, labs in extra.items() for lab, flat in labs.items()
                        if any(overlaps(f"data.{key}", p) for p in flat)), None)
            if hit is not None:
                raise fail(f"scenes.{scene_name}.{key}", f"sets data.{key}, which {hit} sets (the scene's value "
                                                         f"would drop the cell's in its runs); leave it out of one of "
                                                         f"them")
    runner = _parse_runner(data.get("runner", {}), fail, source, base_dir)
    min_effect, matched, quick = _parse_report(data.get("report", {}), fail, axes, variants, extra,
                                              extra_scenes, scenes)
    published = _parse_published(data.get("report", {}).get("published", []), fail, scenes, axes, variants, grid)
    check = _parse_check(data["check"], fail, scenes, axes, variants, grid) if "check" in data else None
    return ExperimentSpec(name=name, kind=kind, scenes=tuple(scenes), seeds=tuple(seeds), base=base, axes=axes,
                          variants=variants, grid=grid, description=description, runner=runner, source=source,
                          scene_sources=scene_sources, scene_tables=scene_tables, min_effect=min_effect,
                          check=check, matched=matched, quick=quick, published=published, extra=extra,
                          extra_scenes=extra_scenes, notes=_parse_notes(data.get("report", {}), fail))


def _parse_extra(table: Any, fail, source: str, axes: Mapping[str, tuple[Any, ...]],
                 variants: Mapping[str, Mapping[str, Any]], scenes: Sequence[str]
                 ) -> tuple[dict[str, dict[str, dict[str, Any]]], dict[str, dict[str, tuple[str, ...]]]]:
    """``[extra.DIMENSION]`` tables: ``LABEL = { FIELD = value, ... }``, each one cell outside the
    grid (`ExperimentSpec.extra`): DIMENSION one of the grid's axes or variants (dotted or nested,
    as a ``[check]`` cell names it), LABEL none of its values, the fields flat (dotted keys) and
    never ``scene`` / ``seed``; ``scenes = [...]`` among them, some of the grid's ``scenes``, runs the
    cell at those alone (`ExperimentSpec.extra_scenes`). One `InputError` line otherwise."""
    if not isinstance(table, Mapping):
        raise fail("extra", f"expected [extra.DIMENSION] tables of label = {{ field = value, ... }}, got {table!r}")
    dims = [*axes, *variants]
    out: dict[str, dict[str, dict[str, Any]]] = {}
    only: dict[str, dict[str, tuple[str, ...]]] = {}
    for dim, labels in _cell_values(table, dims, "extra", fail).items():
        where = f"extra.{dim}"
        if not isinstance(labels, Mapping) or not labels:
            raise fail(where, f"expected a table of label = {{ field = value, ... }} (one extra cell each), got "
                              f"{labels!r}")
        known = list(axes[dim]) if dim in axes else list(variants[dim])
        out[dim] = {}
        for label, settings in labels.items():
            if any(str(label) == str(v) or same_value(label, v) for v in known):
                raise fail(f"{where}.{label}", f"a value of the grid's {dim!r} already (its values: "
                                               f"{', '.join(map(str, known))}); give the extra cell its own label")
            if not isinstance(settings, Mapping):
                raise fail(f"{where}.{label}", f"expected a table of config fields, got {settings!r}")
            if "scenes" in settings:
                settings = dict(settings)
                at = settings.pop("scenes")
                if (not isinstance(at, list) or not at or not all(isinstance(x, str) for x in at)
                        or len(set(at)) != len(at)):
                    example = f"[{at!r}]" if isinstance(at, str) else f"[{', '.join(map(repr, scenes[:2]))}]"
                    raise fail(f"{where}.{label}.scenes", f"expected a list of distinct scene names (e.g. scenes = "
                                                          f"{example}), got {at!r}")
                unknown = [x for x in at if x not in scenes]
                if unknown:
                    close = difflib.get_close_matches(unknown[0], list(scenes), n=1)
                    raise fail(f"{where}.{label}.scenes", f"{unknown[0]!r} is not one of the grid's scenes "
                                                          f"({', '.join(scenes)})"
                                                          + (f"; did you mean {close[0]!r}?" if close else ""))
                only.setdefault(dim, {})[str(label)] = tuple(x for x in scenes if x in at)  # the grid's order
            flat = flatten(settings, where=f"{source}: {where}.{label}") if settings else {}
            for path, value in flat.items():
                check_value(value, f"{source}: {where}.{label}.{path}")
                if path.split(".")[0] in RESERVED_KEYS:
                    raise fail(f"{where}.{label}", f"{path!r} is set by the top-level 'scenes' / 'seeds', not here")
            out[dim][str(label)] = flat
    return out, only


def _parse_check(table: Any, fail, scenes: list[str], axes: Mapping[str, tuple[Any, ...]],
                 variants: Mapping[str, Mapping[str, Any]], grid: str) -> CheckSpec:
    """The ``[check]`` table (`CheckSpec`): its structure, its scene among the grid's, and each
    cell a cell of the grid (its values the axes'; whether the kind knows the protocol is
    checked when the check's runs are made, `splatbench.experiments.grid.check_runs`)."""
    if not isinstance(table, Mapping):
        raise fail("check", f"expected a table with {', '.join(CHECK_FIELDS)}, got {table!r}")
    for key in table:
        if key not in CHECK_FIELDS:
            raise fail(f"check.{key}", unknown_key_problem(key, CHECK_FIELDS))
    for key in CHECK_FIELDS:
        if key not in table:
            raise fail(f"check.{key}", "missing (a check names a protocol, one of the grid's scenes and two cells)")
    protocol, scene, cells = table["protocol"], table["scene"], table["cells"]
    if not isinstance(protocol, str) or not protocol:
        raise fail("check.protocol", f"expected a protocol's name (e.g. 'graphdeco-7k'), got {protocol!r}")
    if scene not in scenes:
        raise fail("check.scene", f"expected one of the grid's scenes ({', '.join(scenes)}), got {scene!r}")
    if not isinstance(cells, list) or len(cells) != 2:
        raise fail("check.cells", f"expected two cells, reference first (e.g. [{{ sh_degree = 0 }}, "
                                  f"{{ sh_degree = 3 }}]), got {cells!r}")
    parsed = [_grid_cell(cell, f"check.cells[{i}]", fail, axes, variants, grid) for i, cell in enumerate(cells)]
    if canonical_json(parsed[0]) == canonical_json(parsed[1]):
        raise fail("check.cells", "the two cells are the same cell")
    return CheckSpec(protocol=protocol, scene=scene, cells=(parsed[0], parsed[1]))


def _grid_cell(cell: Any, where: str, fail, axes: Mapping[str, tuple[Any, ...]],
               variants: Mapping[str, Mapping[str, Any]], grid: str) -> dict[str, Any]:
    """A cell of the grid named by a table of ``dimension = value`` (a ``[check]`` cell, a
    ``[report] published`` cell): each value one of its dimension's, every dimension named in a
    product grid, at most one in a one-at-a-time grid (none: its base); one `InputError` line
    ``where...`` otherwise."""
    if not isinstance(cell, Mapping):
        raise fail(where, f"expected a table of axis = value, got {cell!r}")
    dims = [*axes, *variants]
    values = _cell_values(cell, dims, where, fail)
    for dim, value in values.items():
        known = list(axes[dim]) if dim in axes else list(variants[dim])
        if not any(same_value(value, v) for v in known):
            raise fail(f"{where}.{dim}", f"{value!r} is not a value of the grid's "
                                        f"{'axis' if dim in axes else 'variant'} {dim!r} "
                                        f"({', '.join(map(repr, known))})")
    if grid == "product" and set(values) != set(dims):
        missing = [d for d in dims if d not in values]
        raise fail(where, f"names no value of {', '.join(map(repr, missing))} (a cell of a product grid "
                          f"names one value of every axis)")
    if grid == "one-at-a-time" and len(values) > 1:
        raise fail(where, f"names {len(values)} axes; a cell of a one-at-a-time grid is its base ({{}}) or one "
                          f"axis value alone")
    return values


def same_value(a: Any, b: Any) -> bool:
    """Whether a check cell's value names the axis value ``b``: numbers by value (``0`` names an
    axis's ``0.0``, as TOML writes either), anything else as canonical JSON."""
    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    if number(a) and number(b):
        return float(a) == float(b)
    return canonical_json(a) == canonical_json(b)


def _cell_values(cell: Mapping[str, Any], dims: list[str], where: str, fail, prefix: str = "") -> dict[str, Any]:
    """A check cell's ``dimension -> value``: a key (dotted or nested, as TOML writes
    ``strategy.reset_every``) that is a dimension takes its value whole (an axis value
    may be a table); any other key must lead to one."""
    out: dict[str, Any] = {}
    for key, value in cell.items():
        path = f"{prefix}{key}"
        if path in dims:
            out[path] = value
        elif isinstance(value, Mapping) and any(d.startswith(path + ".") for d in dims):
            out.update(_cell_values(value, dims, where, fail, path + "."))
        else:
            raise fail(f"{where}.{path}", f"not an axis of the grid (its axes: {', '.join(dims) or 'none'})")
    return out


#: Keys of the ``[report]`` table.
REPORT_FIELDS = ("min_effect", "matched", "quick", "published", "notes")
#: Keys of one ``[[report.published]]`` entry: a difference (``cells``) or one cell's value (``cell``, ``scene``).
PUBLISHED_FIELDS = ("cells", "cell", "scene", "value", "metric", "source", "protocol")


def _parse_report(table: Any, fail, axes: Mapping[str, tuple[Any, ...]], variants: Mapping[str, Mapping[str, Any]],
                  extra: Mapping[str, Mapping[str, Any]] | None = None,
                  extra_scenes: Mapping[str, Mapping[str, tuple[str, ...]]] | None = None,
                  scenes: Sequence[str] = ()) -> tuple[dict[str, float], dict[str, tuple[Any, ...]], str | None]:
    """The ``[report]`` table: ``min_effect = { metric = number >= 0, ... }`` (the metric names are
    checked against the kind's comparisons when the report is built), ``matched = { dimension =
    value or [values] }`` (each a value of one of the grid's axes or variants, or the label of one
    of its ``[extra.DIMENSION]`` cells: one matched dimension; two extra cells setting one value of a
    plain axis only where their ``scenes`` (``extra_scenes``; every one of ``scenes`` without) are
    disjoint: each scene's matched cell of that value) and ``quick = "path"``: (min_effect, matched, quick)."""
    if not isinstance(table, Mapping):
        raise fail("report", f"expected a table, got {table!r}")
    for key in table:
        if key not in REPORT_FIELDS:
            raise fail(f"report.{key}", unknown_key_problem(key, REPORT_FIELDS))
    given = table.get("min_effect", {})
    if not isinstance(given, Mapping):
        raise fail("report.min_effect", f"expected a table of metric = number, got {given!r}")
    out: dict[str, float] = {}
    for metric, value in given.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < math.inf:
            raise fail(f"report.min_effect.{metric}", f"expected a number >= 0, got {value!r}")
        out[str(metric)] = float(value)
    raw = table.get("matched", {})
    if not isinstance(raw, Mapping):
        raise fail("report.matched", f"expected a table of dimension = value or [values] (e.g. "
                                     f"{{ size = \"matched\" }}), got {raw!r}")
    dims = [*axes, *variants]
    matched: dict[str, tuple[Any, ...]] = {}
    for dim, value in _cell_values(raw, dims, "report.matched", fail).items():
        values = tuple(value) if isinstance(value, list) else (value,)
        known = (*(axes[dim] if dim in axes else variants[dim]), *(extra or {}).get(dim, {}))
        for v in values:
            if not any(same_value(v, k) for k in known):
                alike = next((k for k in known if str(k) == str(v)), None)  # "0" for 0: the type differs
                raise fail(f"report.matched.{dim}", f"{v!r} is not a value of the grid's {dim!r} (its values: "
                                                    f"{', '.join(map(repr, known))})"
                                                    + (f"; write {alike!r}" if alike is not None else ""))
        if isinstance(value, list) and len(values) < 2:
            raise fail(f"report.matched.{dim}", f"a list names cells matched to each other: give two or more, got "
                                                f"{value!r} (one value of another axis names each cell's matched "
                                                f"twin: {dim} = VALUE)")
        if not isinstance(value, list):
            extra_labels = (extra or {}).get(dim, {})
            if any(same_value(value, k) for k in extra_labels):
                raise fail(f"report.matched.{dim}", f"{value!r} is an extra cell, crossed with nothing, so no cell "
                                                    f"has it as a twin; name the matched extra cells as a list: "
                                                    f"{dim} = [{', '.join(map(repr, extra_labels))}]")
            if len(dims) < 2:
                raise fail(f"report.matched.{dim}", f"one value names each cell's matched twin on another axis, and "
                                                    f"the grid has no other (its axes: {dim}); name cells matched "
                                                    f"to each other as a list: {dim} = [A, B]")
        matched[dim] = tuple(next(k for k in known if same_value(v, k)) for v in values)
        if dim in axes:  # the findings pair the axis's cells A and B with the extra cells setting it to A and B
            cells = (extra or {}).get(dim, {})
            setting: dict[str, list[str]] = {}
            for v in matched[dim]:
                if str(v) in cells and dim in cells[str(v)]:
                    setting.setdefault(repr(cells[str(v)][dim]), []).append(str(v))
            for value, labels in setting.items():  # two of one value: only at disjoint scenes (one per scene)
                for i, first in enumerate(labels):
                    for second in labels[i + 1:]:
                        at = [s for s in scenes if all(s in (extra_scenes or {}).get(dim, {}).get(lab, scenes)
                                                       for lab in (first, second))]
                        if at:
                            raise fail(f"report.matched.{dim}", f"the extra cells {first!r} and {second!r} both set "
                                                                f"{dim} = {value}, both at {at[0]}, so neither is "
                                                                f"{at[0]}'s one matched {dim} = {value} twin: name "
                                                                f"one extra cell per value of {dim} at each scene "
                                                                f"(give them disjoint `scenes` lists)")
    if len(matched) > 1:
        raise fail("report.matched", f"expected one dimension, got {', '.join(matched)}")
    quick = table.get("quick")
    if quick is not None and (not isinstance(quick, str) or not quick.strip()):
        raise fail("report.quick", f"expected the path of the quick version's results (a report folder or a "
                                   f"run table), got {quick!r}")
    return out, matched, quick


def _parse_notes(table: Any, fail) -> tuple[str, ...]:
    """``[report] notes = ["...", ...]``: what the experiment's author knows of its data that no number
    in the report shows (a test view whose mask is wrong, ...), each a non-empty line of text."""
    notes = table.get("notes", []) if isinstance(table, Mapping) else []
    if not isinstance(notes, list) or not all(isinstance(n, str) and n.strip() and "\n" not in n for n in notes):
        raise fail("report.notes", f"expected a list of one-line strings (notes = [\"...\"]), got {notes!r}")
    return tuple(n.strip() for n in notes)


def _parse_published(entries: Any, fail, scenes: list[str], axes: Mapping[str, tuple[Any, ...]],
                     variants: Mapping[str, Mapping[str, Any]], grid: str) -> tuple[PublishedSpec, ...]:
    """``[[report.published]]`` (`PublishedSpec`): each entry a published difference
    ``cells = [A, B]``, ``value`` = A − B, or a published value of one cell on one of the grid's
    scenes (``cell``, ``scene``, ``value``); ``source`` and ``protocol`` required, ``metric``
    optional (whether the kind reports it is checked with the kind,
    `splatbench.experiments.grid.published_runs`). Each cell a cell of the grid (`_grid_cell`)."""
    example = ('[[report.published]] tables, e.g. { cells = [{ densify = "absgrad" }, { densify = "default" }], '
               'value = 0.11, source = "...", protocol = "..." }')
    if not isinstance(entries, list):
        raise fail("report.published", f"expected an array of {example}, got {entries!r}")
    out = []
    for i, entry in enumerate(entries):
        where = f"report.published[{i}]"
        if not isinstance(entry, Mapping):
            raise fail(where, f"expected a table (one published number), got {entry!r}")
        for key in entry:
            if key not in PUBLISHED_FIELDS:
                raise fail(f"{where}.{key}", unknown_key_problem(key, PUBLISHED_FIELDS))
        if ("cells" in entry) == ("cell" in entry):
            raise fail(where, "expected either cells = [A, B] (a published difference A − B) or cell = {...} with "
                              "scene = \"...\" (a published value of one cell on one scene)")
        for key in ("value", "source", "protocol"):
            if key not in entry:
                raise fail(f"{where}.{key}", "missing (a published number gives its value, its source and its "
                                             "protocol)")
        if "cells" in entry:
            raw = entry["cells"]
            if not isinstance(raw, list) or len(raw) != 2:
                raise fail(f"{where}.cells", f"expected two cells, A then B, for a published A − B (e.g. [{{ densify "
                                             f"= \"absgrad\" }}, {{ densify = \"default\" }}]), got {raw!r}")
            if "scene" in entry:
                raise fail(f"{where}.scene", "a published difference stands beside every scene of the grid; scene "
                                             "goes with cell = {...} (a published value of one cell)")
            cells = tuple(_grid_cell(c, f"{where}.cells[{k}]", fail, axes, variants, grid) for k, c in enumerate(raw))
            if canonical_json(cells[0]) == canonical_json(cells[1]):
                raise fail(f"{where}.cells", "the two cells are the same cell")
            scene = None
        else:
            cells = (_grid_cell(entry["cell"], f"{where}.cell", fail, axes, variants, grid),)
            scene = entry.get("scene")
            if scene not in scenes:
                raise fail(f"{where}.scene", f"expected the grid's scene the value is of (one of: "
                                             f"{', '.join(scenes)}), got {scene!r}")
        value = entry["value"]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise fail(f"{where}.value", f"expected the published number (a finite number), got {value!r}")
        for key in ("source", "protocol"):
            text = entry[key]
            if not isinstance(text, str) or not text.strip():
                what = ("where it is published (e.g. \"gsplat docs/source/tests/eval.rst\")" if key == "source" else
                        "its protocol (free text or a protocol's name, e.g. \"graphdeco-30k, Mip-NeRF 360\")")
                raise fail(f"{where}.{key}", f"expected {what}, got {text!r}")
        metric = entry.get("metric")
        if metric is not None and (not isinstance(metric, str) or not metric):
            raise fail(f"{where}.metric", f"expected a metric's name (e.g. \"test_psnr\"), got {metric!r}")
        out.append(PublishedSpec(cells=cells, value=float(value), source=" ".join(entry["source"].split()),
                                 protocol=" ".join(entry["protocol"].split()), metric=metric, scene=scene))
    return tuple(out)


#: Keys of a scene table: a dataset folder or a teacher model (besides ``name``).
FOLDER_SCENE_KEYS = ("path", "downscale")
TEACHER_SCENE_KEYS = ("model", "views", "resolution", "up")


def _looks_like_ply(path: Path) -> bool:
    """Whether the file starts as a PLY with a ``vertex`` element (its header alone is read), so
    that a wrong file is named when the experiment is read, not when its run starts."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(1 << 16)
    except OSError:
        return False
    return head.startswith(b"ply") and b"element vertex " in head.split(b"end_header", 1)[0]


def _scene_table(table: Mapping[str, Any], where: str, fail, base_dir: Path | None) -> tuple[str, dict[str, Any]]:
    """``{ name, path, downscale }`` or ``{ name, model, views, resolution, up }`` -> (name, the
    run's ``data`` fields); relative paths resolve against the experiment file's folder."""
    name = table.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        raise fail(f"{where}.name", f"expected a folder-safe scene name, got {name!r}")
    where = f"scenes.{name}"
    kind_keys = FOLDER_SCENE_KEYS if "path" in table else TEACHER_SCENE_KEYS if "model" in table else None
    if kind_keys is None or ("path" in table and "model" in table):
        raise fail(where, "expected exactly one of 'path' (a dataset folder) or 'model' (a 3DGS PLY rendered as a "
                          "teacher scene)")
    for key in table:
        if key != "name" and key not in kind_keys:
            raise fail(f"{where}.{key}", f"unknown key (a {'dataset folder' if 'path' in table else 'teacher'} "
                                         f"scene takes: name, {', '.join(kind_keys)})")
    fields: dict[str, Any] = {}
    for key, value in table.items():
        if key in ("path", "model"):
            if not isinstance(value, str) or not value:
                raise fail(f"{where}.{key}", f"expected a path, got {value!r}")
            p = Path(value).expanduser()
            if base_dir is not None and not p.is_absolute():
                p = base_dir / p
            p = p.resolve()
            shown = repr(value) + (f" ({p})" if str(p) != value else "")  # as written, then where it led
            if key == "path" and not p.is_dir():
                what = "is a file, not a dataset folder" if p.exists() else "does not exist"
                raise fail(f"{where}.path", f"{shown} {what} (paths are relative to the experiment file; give "
                                            f"a capture's folder: COLMAP, transforms.json or LLFF)")
            if key == "model" and not p.is_file():
                raise fail(f"{where}.model", f"{shown} is not a file (give a 3DGS PLY)")
            if key == "model" and not _looks_like_ply(p):
                raise fail(f"{where}.model", f"{shown} is not a PLY with a vertex element (give a 3DGS PLY)")
            fields[key] = str(p)
        elif key == "up":
            if not (isinstance(value, list) and len(value) == 3
                    and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
                raise fail(f"{where}.up", f"expected 3 numbers, got {value!r}")
            if not any(value) or not all(math.isfinite(v) for v in value):
                raise fail(f"{where}.up", f"expected a non-zero direction of 3 finite numbers, got {value!r}")
            fields[key] = [float(v) for v in value]
        elif key != "name":
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise fail(f"{where}.{key}", f"expected an int >= 1, got {value!r}")
            fields[key] = value
    return name, fields


def _variant_paths(variants: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> list[tuple[str, str]]:
    """(where in the file, path) of every path a variant's label sets."""
    return [(f"variants.{name}.{label}.{path}", path)
            for name, labels in variants.items() for label, flat in labels.items() for path in flat]


def _flatten_axes(table: Mapping[str, Any], prefix: str, fail) -> dict[str, list]:
    """``[axes]`` -> ``{dotted.path: [values]}``; a sub-table nests, a list is an axis."""
    out: dict[str, list] = {}
    for key, value in table.items():
        parts = str(key).split(".")
        if not all(FIELD_KEY.match(p) for p in parts):
            raise fail(f"axes.{key}", "bad field name (letters, digits, '_' and '-', dotted for nesting)")
        path = ".".join([prefix, *parts] if prefix else parts)
        if isinstance(value, list):
            items = {path: value}
        elif isinstance(value, Mapping) and value:
            items = _flatten_axes(value, path, fail)
        else:
            raise fail(f"axes.{path}", f"expected a list of values, got {value!r}")
        for sub, values in items.items():
            for other in out:
                if sub == other:  # one axis written twice ("raster.tile_size" and raster.tile_size), as flatten says
                    raise fail(f"axes.{sub}", f"set twice (also as {other!r})")
                if overlaps(sub, other):
                    raise fail(f"axes.{sub}", f"overlaps axes.{other} ({DROPS}); sweep only one of them, or use "
                                              f"a [variants.NAME] table for values that go together")
            out[sub] = values
    return out


def _parse_runner(table: Any, fail, source: str, base_dir: Path | None) -> RunnerDefaults:
    if not isinstance(table, Mapping):
        raise fail("runner", f"expected a table, got {table!r}")
    for key in table:
        if key not in RUNNER_FIELDS:
            raise fail(f"runner.{key}", unknown_key_problem(key, RUNNER_FIELDS))
    workers = table.get("workers")
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
        raise fail("runner.workers", f"expected an int >= 1, got {workers!r}")
    executor = table.get("executor")
    if executor is not None and executor not in EXECUTORS:
        raise fail("runner.executor", f"expected one of {', '.join(map(repr, EXECUTORS))}, got {executor!r}")
    scheduler = table.get("scheduler")
    if scheduler is not None:
        check_scheduler(scheduler, where=f"{source}: runner.scheduler")
    results = table.get("results")
    if results is not None:
        if not isinstance(results, str) or not results:
            raise fail("runner.results", f"expected a folder path, got {results!r}")
        results = Path(results)
        if base_dir is not None and not results.is_absolute():
            results = base_dir / results
    return RunnerDefaults(workers=workers, executor=executor, scheduler=scheduler, results=results)


def check_scheduler(address: Any, *, where: str = "scheduler") -> str:
    """A Dask scheduler address ``tcp://HOST:PORT`` (also tls://, ucx://, inproc://)."""
    if not isinstance(address, str) or not _SCHEDULER.match(address):
        raise InputError(f"{where}: expected an address like tcp://HOST:PORT, got {address!r}")
    return address


def _no_duplicates(values: list, where: str, fail) -> None:
    seen: set[str] = set()
    for v in values:
        key = canonical_json(v)
        if key in seen:
            raise fail(where, f"duplicate value {v!r}")
        seen.add(key)


__all__ = ["ExperimentSpec", "CheckSpec", "PublishedSpec", "RunnerDefaults", "TOP_LEVEL_FIELDS", "RUNNER_FIELDS",
           "CHECK_FIELDS", "REPORT_FIELDS", "PUBLISHED_FIELDS", "GRID_MODES", "EXECUTORS", "RESERVED_KEYS",
           "FOLDER_SCENE_KEYS", "TEACHER_SCENE_KEYS", "parse_experiment", "check_scheduler", "same_value"]
