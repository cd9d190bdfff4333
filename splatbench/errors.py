"""Errors raised at splatbench's public boundary.

Every user-facing error is one line that names the field and the bad value, so the
CLI can print it without a traceback.
"""


class SplatbenchError(Exception):
    """Base class of splatbench's own errors."""


class InputError(SplatbenchError, ValueError):
    """Bad input: the message names the field and the offending value or shape."""


#: Longest `one_line` summary (a table cell, a result record's ``error``).
ONE_LINE_MAX = 300


def one_line(exc: BaseException) -> str:
    """``"ExcType: first line of the message"`` (``"ExcType"`` for an empty message), cut at
    `ONE_LINE_MAX` characters: how a failure is recorded where a traceback does not fit."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")[:ONE_LINE_MAX]
