"""The one ``key=value`` grammar of the command line (``train --set``, ``render --option``,
``bench raster --option``).

The value is a TOML literal when it parses as one (``1e-3``, ``8``, ``true``,
``[0, 0, 0]``, ``"auto"``), else the bare string (``radius=opacity``). Torch-free, so
the rendering commands can use it without importing the trainer.
"""

from __future__ import annotations

import tomllib
from typing import Any

from splatbench.errors import InputError


def parse_override(text: str, flag: str = "--set") -> tuple[str, Any]:
    """``"key=value"`` -> (key, value); ``flag`` names the option in the one-line error."""
    if "=" not in text:
        raise InputError(f"{flag}: expected key=value, got {text!r}")
    key, raw = (s.strip() for s in text.split("=", 1))
    if not key:
        raise InputError(f"{flag}: empty key in {text!r}")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def parse_overrides(pairs: tuple[str, ...] | list[str], flag: str) -> dict[str, Any]:
    """Several ``key=value`` strings -> {key: value} (a later key wins)."""
    return dict(parse_override(pair, flag) for pair in pairs)
