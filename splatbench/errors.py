"""Errors raised at splatbench's public boundary.

Every user-facing error is one line that names the field and the bad value, so the
CLI can print it without a traceback.
"""


class SplatbenchError(Exception):
    """Base class of splatbench's own errors."""


class InputError(SplatbenchError, ValueError):
    """Bad input: the message names the field and the offending value or shape."""
