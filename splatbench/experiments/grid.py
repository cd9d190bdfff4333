"""Grid expansion: an `ExperimentSpec` -> a deterministic list of `RunSpec`.

Order: scenes (file order), then the grid's cells (axes in file order, then
variants; the last one varies fastest), then seeds. ``grid = "product"`` takes every
combination; ``grid = "one-at-a-time"`` takes the base alone, then each axis value
(or variant) alone on top of the base. Cells whose resolved configs are equal
(for example an axis value equal to the base) are one run, listed once, first
occurrence first.

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
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from splatbench.errors import InputError
from splatbench.experiments.configs import canonical_json, flatten, override, unflatten
from splatbench.experiments.kinds import get_kind
from splatbench.experiments.spec import ExperimentSpec, parse_experiment
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
    try:
        kind = get_kind(spec.kind)
    except InputError as exc:
        raise InputError(f"{spec.source}: {exc}") from None
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
    variant_names = set(spec.variants)
    checked: dict[str, str | None] = {}

    def check(flat: dict[str, Any]) -> str | None:
        key = canonical_json(flat)
        if key not in checked:
            try:
                kind.validate(unflatten(flat))
                checked[key] = None
            except InputError as exc:
                checked[key] = str(exc)
        return checked[key]

    runs: list[RunSpec] = []
    seen: set[str] = set()
    for scene in spec.scenes:
        for cell in _cells(spec, dims):
            flat_cell = dict(spec.base)
            for _, _, settings, _ in cell:
                flat_cell = override(flat_cell, settings)
            for seed in spec.seeds:
                flat = {**flat_cell, **_source(spec, scene), "scene": scene, "seed": seed}
                problem = check(flat)
                if problem is not None:
                    raise InputError(f"{spec.source}: {_culprit(spec, cell, scene, seed, check, problem)}: {problem}")
                config = unflatten(flat)
                if kind.resolve is not None:
                    try:
                        config = kind.resolve(config)
                    except InputError as exc:
                        raise InputError(f"{spec.source}: {_culprit(spec, cell, scene, seed, check)}: {exc}") \
                            from None
                rid = make_run_id(spec.kind, kind.identity(config) if kind.identity is not None else config)
                if rid in seen:
                    continue
                seen.add(rid)
                resolved = flatten(config) if config else {}
                chosen = {name: label for name, label, _, _ in cell}
                labels = {name: (chosen.get(name) if name in variant_names else _label(resolved, name))
                          for name in spec.dimensions}
                runs.append(RunSpec(experiment=spec.name, kind=spec.kind, scene=scene, seed=seed, config=config,
                                    run_id=rid, labels=labels))
    return runs


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
    ``validate``, by expanding the grid. Raises one `InputError` line; runs nothing."""
    expand(spec, known_scenes=known_scenes)


__all__ = ["RunSpec", "expand", "make_run_id", "load_experiment", "check_experiment"]
