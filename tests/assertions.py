"""Assertions shared by the tests."""

from __future__ import annotations

import pytest

from splatbench.errors import InputError


def one_line_error(fn, *parts: str) -> str:
    """Call ``fn``, assert it raises `InputError` with a one-line message containing
    every string in ``parts`` (field names, values), and return the message."""
    with pytest.raises(InputError) as info:
        fn()
    msg = str(info.value)
    assert "\n" not in msg, msg
    for part in parts:
        assert part in msg, (part, msg)
    return msg
