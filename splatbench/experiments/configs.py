"""Run configs as values: dotted keys (`flatten`, `unflatten`, `override`), `canonical_json`,
and a run table's cells read back (`cell_value`, `decode`, `run_config`).

A config is held *flat*, as ``dotted.path -> value`` (docs/experiments.md, "Dotted
keys"); a run kind receives the nested form. `canonical_json` is the one text of a
config value: the run id (`splatbench.experiments.grid.make_run_id`), duplicate
detection in `splatbench.experiments.spec` and the grid's labels all hash or compare it.
A run table (`splatbench.experiments.store.build_table`) holds a config as ``config.*``
columns, a column of mixed types as JSON text; `run_config` turns a row back into the
nested config its kind's hooks read, for the reports and the kinds' report hooks alike.
Shared by `spec`, `grid`, `kinds` and `store`; imports nothing of theirs.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from datetime import date, datetime, time
from typing import Any

import pandas as pd

from splatbench.errors import InputError

#: One part of a dotted field name.
FIELD_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]*$")


def flatten(table: Mapping[str, Any], prefix: str = "", *, where: str = "config") -> dict[str, Any]:
    """A nested table -> ``{dotted.path: leaf}``. Keys holding dots are split; an empty
    table is a leaf (``{}``); a path set twice is an `InputError` naming ``where``."""
    flat: dict[str, Any] = {}
    for key, value in table.items():
        parts = str(key).split(".")
        if not all(FIELD_KEY.match(p) for p in parts):
            raise InputError(f"{where}: bad field name {key!r} (letters, digits, '_' and '-', dotted for nesting)")
        path = ".".join([prefix, *parts] if prefix else parts)
        items = flatten(value, path, where=where).items() if isinstance(value, Mapping) and value else [(path, value)]
        for sub, leaf in items:
            _set_path(flat, sub, leaf, where=where)
    return flat


def unflatten(flat: Mapping[str, Any]) -> dict[str, Any]:
    """``{dotted.path: leaf}`` -> a nested dict (the form a run kind receives)."""
    nested: dict[str, Any] = {}
    for path, value in flat.items():
        node = nested
        *parents, last = path.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = plain(value)
    return nested


def overlaps(a: str, b: str) -> bool:
    """Whether dotted paths ``a`` and ``b`` name the same field, or one a field inside the other."""
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


def override(flat: Mapping[str, Any], settings: Mapping[str, Any]) -> dict[str, Any]:
    """``flat`` with ``settings`` applied: each set path replaces the base value at that
    path, everything under it and any leaf above it. (An experiment's axes and variants
    never overlap one another, so in a grid cell only the base's values are replaced:
    `splatbench.experiments.spec`.)"""
    out = dict(flat)
    for path in settings:
        for key in list(out):
            if overlaps(key, path):
                del out[key]
    out.update(settings)
    return out


def _set_path(flat: dict[str, Any], path: str, value: Any, *, where: str) -> None:
    for key in flat:
        if overlaps(key, path):
            raise InputError(f"{where}.{path}: set twice (also as {key!r})")
    flat[path] = value


def plain(value: Any) -> Any:
    """A deep copy of a config value as plain JSON types: mappings as dicts, tuples and lists
    as lists (what a run kind, a record and `canonical_json` receive)."""
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def check_value(value: Any, where: str) -> None:
    """Config values must survive canonical JSON: no dates, no NaN or infinity."""
    if isinstance(value, (datetime, date, time)):
        raise InputError(f"{where}: dates and times are not config values, got {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise InputError(f"{where}: non-finite value {value!r}")
    if isinstance(value, Mapping):
        for k, v in value.items():
            check_value(v, f"{where}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            check_value(v, f"{where}[{i}]")


def canonical_json(value: Any) -> str:
    """Sorted keys, no spaces, ASCII, no NaN: the same value always gives the same text."""
    try:
        return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise InputError(f"config: not a canonical JSON value ({exc})") from None


def cell_value(value: Any) -> Any:
    """A run table cell as a plain hashable value: NaN / NA as None, a NumPy scalar as its Python
    value; JSON text (a column of mixed types) left as text (`decode` reads it)."""
    if value is None or value is pd.NA or (isinstance(value, float) and math.isnan(value)):
        return None
    return value.item() if hasattr(value, "item") else value


def decode(value: Any) -> Any:
    """A run table cell back to a value (`cell_value`): JSON text of a mixed column is decoded (a
    number only where the text is its canonical JSON: ``"1.50"`` stays text), NaN is None."""
    value = cell_value(value)
    if isinstance(value, str):
        try:
            decoded = json.loads(value)
        except ValueError:
            return value
        return decoded if not isinstance(decoded, (int, float)) or value.strip() == json.dumps(decoded) else value
    return value


def run_config(run: pd.Series) -> dict[str, Any]:
    """A run table row's recorded config, nested (its ``config.*`` columns decoded, None left out),
    with its ``scene`` and ``seed``: what a kind's hooks (`RunKind.planned`,
    `SettlingCurves.resets`) read."""
    flat = {c[len("config."):]: decode(run[c]) for c in run.index if str(c).startswith("config.")}
    return {**unflatten({k: v for k, v in flat.items() if v is not None}), "scene": run.scene, "seed": int(run.seed)}
