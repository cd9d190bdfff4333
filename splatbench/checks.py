"""Boundary checks for arrays: shape, dtype and finiteness, reported in one line."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from splatbench.errors import InputError

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


def check_sh_degree(name: str, value) -> int:
    """An SH degree: an integer in 0..3 (bools rejected), else one-line `InputError`."""
    import operator

    if isinstance(value, bool):
        raise InputError(f"{name}: expected an int in 0..3, got {value!r}")
    try:
        degree = operator.index(value)
    except TypeError:
        raise InputError(f"{name}: expected an int in 0..3, got {value!r}") from None
    if not 0 <= degree <= 3:
        raise InputError(f"{name}: expected an int in 0..3, got {degree}")
    return degree
