"""Input guards at the boundary, each reporting a bad value in one line (`InputError`):
arrays (shape, dtype, finiteness), SH degrees, image sizes, and mappings turned into frozen
dataclasses (known keys with "did you mean", annotated value types)."""

from __future__ import annotations

import dataclasses
import functools
import math
import operator
import types
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from splatbench.errors import InputError

T = TypeVar("T")

# A dimension spec: an int (exact), None (any), or a letter naming a size that must
# agree across fields (e.g. "N" for the number of Gaussians).
Dim = int | str | None


def check_shape(name: str, shape: Sequence[int], spec: Sequence[Dim], sizes: dict[str, int]) -> None:
    """Raise `InputError` unless ``shape`` matches ``spec``; binds letters in ``sizes``."""
    shape = tuple(int(s) for s in shape)
    want = "[" + ", ".join("?" if d is None else str(d) for d in spec) + "]"
    if len(shape) != len(spec):
        raise InputError(f"{name}: expected shape {want}, got {list(shape)}")
    for got, dim in zip(shape, spec):
        if dim is None:
            continue
        if isinstance(dim, str):
            bound = sizes.setdefault(dim, got)
            if bound != got:
                raise InputError(f"{name}: expected shape {want} with {dim}={bound}, got {list(shape)}")
        elif got != dim:
            raise InputError(f"{name}: expected shape {want}, got {list(shape)}")


def first_nonfinite(array: np.ndarray) -> tuple[int, ...] | None:
    """Index of the first NaN/Inf entry, or None when all entries are finite."""
    bad = ~np.isfinite(array)
    if not bad.any():
        return None
    return tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), array.shape))


def check_finite(name: str, array: np.ndarray) -> None:
    """Raise `InputError` naming the first non-finite entry of ``array``."""
    where = first_nonfinite(array)
    if where is not None:
        raise InputError(f"{name}: non-finite value {float(array[where])!r} at index {list(where)}")


def as_float_array(name: str, value, spec: Sequence[Dim], sizes: dict[str, int],
                   dtype=np.float32, finite: bool = True) -> np.ndarray:
    """Convert ``value`` to a contiguous float array and check its shape and values."""
    try:
        array = np.asarray(value)
    except Exception as exc:  # noqa: BLE001 - report any conversion failure in one line
        raise InputError(f"{name}: cannot convert {type(value).__name__} to an array ({exc})") from None
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise InputError(f"{name}: expected a float array, got dtype {array.dtype}")
    check_shape(name, array.shape, spec, sizes)
    array = np.ascontiguousarray(array, dtype=dtype)
    if finite:
        check_finite(name, array)
    return array


#: Numbers of SH bases per colour channel, indexed by SH degree 0..3 (K = (d+1)²).
SH_BASES_OF_DEGREE = (1, 4, 9, 16)


def check_sh_degree(name: str, value, *, allow_auto: bool = False) -> int | str:
    """An SH degree: an integer in 0..3 (bools rejected), or ``"auto"`` when ``allow_auto``;
    else one-line `InputError`. The one SH-degree check outside ``raster/``."""
    expected = "an int in 0..3 or 'auto'" if allow_auto else "an int in 0..3"
    if allow_auto and value == "auto":
        return "auto"
    if isinstance(value, bool):
        raise InputError(f"{name}: expected {expected}, got {value!r}")
    try:
        degree = operator.index(value)
    except TypeError:
        raise InputError(f"{name}: expected {expected}, got {value!r}") from None
    if not 0 <= degree <= 3:
        raise InputError(f"{name}: expected {expected}, got {degree}")
    return degree


# --------------------------------------------------------------------------- image size
#: Dr.Jit arrays hold at most 2**32 - 1 entries (32-bit sizes and indices).
DRJIT_MAX_ENTRIES = 2**32 - 1
#: Entries per pixel of the largest per-pixel array of the pipeline: the RGB image, [H*W*3].
LARGEST_BUFFER_CHANNELS = 3
#: Bytes per pixel the rasterizer's pipeline keeps alive at once (an upper estimate):
#: forward state (3 colour accumulators, depth, transmittance, last contributor,
#: contributor count, pixel index and tile id: 10 x 4 B), its outputs (rgb, alpha,
#: depth: 5 x 4 B), their numpy float32 copies (20 B) and PNG bytes (3 B) come to
#: 83 B; the backward pass keeps the forward state and its cotangents again (x 2),
#: rounded up to 256 B for temporaries.
PIXEL_BYTES = 256


def image_size_problem(width: int, height: int, *, memory: bool = True) -> str | None:
    """Why a ``width`` x ``height`` image cannot be rendered here, or None when it can.

    Two bounds, checked before anything is allocated:
    - Dr.Jit's: an array holds at most 2**32 - 1 entries, and the largest per-pixel
      array is the RGB image with 3 entries per pixel, so W * H <= (2**32 - 1) // 3
      (about 1.43e9 pixels, e.g. 37837 x 37837);
    - memory's (``memory=True``): W * H * `PIXEL_BYTES` must fit in the memory
      available now (psutil's ``available``).
    """
    pixels = int(width) * int(height)
    max_pixels = DRJIT_MAX_ENTRIES // LARGEST_BUFFER_CHANNELS
    if pixels > max_pixels:
        return (f"{width}x{height} is {pixels:.3g} pixels, above Dr.Jit's limit of {max_pixels:.3g} "
                f"(2^32 - 1 array entries / {LARGEST_BUFFER_CHANNELS} colour channels)")
    if memory:
        import psutil

        need, free = pixels * PIXEL_BYTES, psutil.virtual_memory().available
        if need > free:
            return (f"{width}x{height} needs about {need / 2**30:.1f} GiB ({PIXEL_BYTES} B per pixel), "
                    f"more than the {free / 2**30:.1f} GiB of memory available")
    return None


def parse_size(text: str, flag: str) -> tuple[int, int]:
    """``"WxH"`` -> (W, H), both >= 1; a one-line `InputError` naming ``flag`` otherwise."""
    parts = text.lower().split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise InputError(f"{flag}: expected WxH, got {text!r}") from None
    if width < 1 or height < 1:
        raise InputError(f"{flag}: expected WxH with W, H >= 1, got {text!r}")
    return width, height


def check_image_size(width: int, height: int, *, field: str = "size", memory: bool = True) -> None:
    """Raise a one-line `InputError` naming ``field`` when `image_size_problem` finds one."""
    problem = image_size_problem(width, height, memory=memory)
    if problem is not None:
        raise InputError(f"{field}: {problem}; choose a smaller image")


# --------------------------------------------------------------------------- mappings
def unknown_key_problem(key: str, known: Iterable[str]) -> str:
    """The one wording of a key that names no field: ``unknown key (did you mean 'x'?)``
    when one known name is close (difflib), else ``unknown key (known: a, b, ...)``."""
    import difflib

    names = sorted(known)
    close = difflib.get_close_matches(key, names, n=1)
    if close:
        return f"unknown key (did you mean {close[0]!r}?)"
    return f"unknown key (known: {', '.join(names) if names else 'none'})"


def check_keys(keys: Iterable[str], known: Iterable[str], *, prefix: str = "", source: str = "") -> None:
    """Raise a one-line `InputError` ``[SOURCE: ]PREFIXKEY: unknown key (...)`` for the first
    of ``keys`` not in ``known`` (`unknown_key_problem`). ``prefix`` is the table's dotted
    path (``"strategy."``); ``source`` names the file or flag (``"--set"``)."""
    known = set(known)
    for key in keys:
        if key not in known:
            where = f"{source}: " if source else ""
            raise InputError(f"{where}{prefix}{key}: {unknown_key_problem(str(key), known)}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


#: Field type -> (test, wording) of `check_type`; a TOML value's types only.
_TYPES: dict[Any, tuple[Callable[[Any], bool], str]] = {
    bool: (lambda v: isinstance(v, bool), "true or false"),
    int: (_is_int, "an int"),
    float: (_is_number, "a finite number"),
    str: (lambda v: isinstance(v, str), "a string"),
    int | str: (lambda v: isinstance(v, str) or _is_int(v), "an int or 'auto'"),
    float | str: (lambda v: isinstance(v, str) or _is_number(v), "a number or 'auto'"),
    list[float]: (lambda v: isinstance(v, list) and all(map(_is_number, v)), "a list of numbers"),
    list[int]: (lambda v: isinstance(v, list) and all(map(_is_int, v)), "a list of ints"),
    list[float] | str: (lambda v: isinstance(v, str) or (isinstance(v, list) and all(map(_is_number, v))),
                        "a list of numbers or 'auto'"),
    dict[str, Any]: (lambda v: isinstance(v, dict), "a table"),
}


def check_type(name: str, value: Any, tp: Any) -> None:
    """Raise a one-line `InputError` ``NAME: expected <type>, got <value>`` unless ``value``
    is of the field type ``tp`` (bools are not numbers; numbers are finite; ``X | None``
    also takes None)."""
    optional = _optional_of(tp)
    if optional is not None:
        if value is None:
            return
        tp = optional
    if tp not in _TYPES:  # pragma: no cover - a new field type must be added to _TYPES
        raise TypeError(f"{name}: unsupported field type {tp}")
    test, wording = _TYPES[tp]
    if not test(value):
        raise InputError(f"{name}: expected {wording}, got {value!r}")


def coerce(value: Any, tp: Any) -> Any:
    """``value`` widened to the field type ``tp`` where TOML cannot say it: an int where a
    float is expected (alone or in a list) becomes a float; anything else is returned as is."""
    floats = tp in (float, float | str, float | None)
    if floats and _is_int(value):
        return float(value)
    if tp in (list[float], list[float] | str) and isinstance(value, list):
        return [float(v) if _is_int(v) else v for v in value]
    return value


def dataclass_from_mapping(cls: type[T], data: Mapping[str, Any], *, base: Mapping[str, Any] | None = None,
                           prefix: str = "", source: str = "") -> T:
    """``cls(**base, **data)`` for a dataclass ``cls``, after the boundary checks: every key
    names a field (`check_keys`, with "did you mean"), every value has its field's
    annotated type (`check_type`, after `coerce`). Ranges are the class's own business
    (its ``__post_init__``). Messages name ``PREFIXKEY`` (and ``source`` first), the class's
    own too: its ``ClassName.field: ...`` or ``field: ...`` becomes ``source: PREFIXfield: ...``,
    so that one option has one name in every message (the one the user wrote)."""
    hints = _field_types(cls)
    check_keys(data, hints, prefix=prefix, source=source)
    values = {}
    for key, value in data.items():
        value = coerce(value, hints[key])
        if hints[key] in _TYPES or _optional_of(hints[key]) in _TYPES:  # other types: the class checks them
            check_type(f"{source}: {prefix}{key}" if source else f"{prefix}{key}", value, hints[key])
        values[key] = value
    try:
        return cls(**{**(base or {}), **values})
    except InputError as exc:
        message = str(exc)
        owner = next((c.__name__ for c in cls.__mro__ if message.startswith(f"{c.__name__}.")), None)
        if owner is not None and prefix:
            named = prefix + message[len(owner) + 1:]
        elif prefix and message.split(":", 1)[0] in hints:  # a bare ``field: ...``
            named = prefix + message
        else:
            raise
        raise InputError(f"{source}: {named}" if source else named) from None


def _optional_of(tp: Any) -> Any:
    """``X`` of ``X | None``, else None."""
    if isinstance(tp, types.UnionType) and type(None) in tp.__args__:
        return functools.reduce(operator.or_, [a for a in tp.__args__ if a is not type(None)])
    return None


def _field_types(cls: type) -> dict[str, Any]:
    """Field name -> its evaluated annotation; None for every field where the annotations
    cannot be evaluated (a class defined in a function that names local imports): its
    values are then left to the class's own checks."""
    try:
        hints = typing.get_type_hints(cls)
    except NameError:
        hints = {}
    return {f.name: hints.get(f.name) for f in dataclasses.fields(cls)}
