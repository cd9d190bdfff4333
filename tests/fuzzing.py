"""Mutation fuzzing of valid files: hypothesis strategies and the contract every reader keeps.

A case takes a valid file (or a folder of files) and applies one to three mutations:
truncation, bit flips, overwritten / inserted / deleted / duplicated byte spans, NaN or
Inf written over an aligned 4- or 8-byte float, a count-sized integer (0, -1, 10^11,
2^63 - 1, 2^64 - 1) written over 4 or 8 bytes; and for text files token edits (a number
replaced by ``nan``, ``inf``, ``-1``, ``1e309``, ``100000000000``, a word, nothing), a
line deleted / duplicated / swapped, and a wrong encoding (UTF-16, Latin-1 bytes).

`run_case` then asserts the contract: the read returns data that passes the reader's
own check (finite, validated; readers that answer None for a damaged file, the grid's
result files and claims, count those as "refused (None)"), or raises `InputError`
with a one-line message; any other
exception, a case longer than `CASE_SECONDS`, or a Python/numpy allocation peak above
`memory_bound` fails the test.
"""

from __future__ import annotations

import json
import os
import re
import signal
import struct
import tracemalloc
from collections import Counter
from collections.abc import Callable
from pathlib import Path

from hypothesis import strategies as st

from splatbench.errors import InputError

#: Wall-clock limit of one case (generous: the machine running the suite may be loaded).
CASE_SECONDS = 20
#: Outcomes per reader, for docs/robustness.md (written by tests/test_fuzz.py when asked).
STATS: dict[str, Counter] = {}

_COUNTS = [0, 1, 2**31 - 1, 2**31, 10**11, 2**63 - 1]
_FLOATS = [float("nan"), float("inf"), float("-inf"), 1e300, -0.0, 3.4e38]
_FLOATS32 = [float("nan"), float("inf"), float("-inf"), -0.0, 3.4e38, -3.4e38]
_TOKENS = [b"nan", b"inf", b"-inf", b"-1", b"0", b"1e309", b"100000000000", b"18446744073709551616", b"1.5",
           b"abc", b"", b"\xc3\xa9", b"null", b"[]", b"{}", b'"x"', b"true"]
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


class CaseTimeout(Exception):
    """A case ran longer than `CASE_SECONDS`."""


def _alarm(signum, frame):  # noqa: ARG001
    raise CaseTimeout(f"case ran longer than {CASE_SECONDS} s")


@st.composite
def mutated(draw, data: bytes, text: bool = False) -> bytes:
    """``data`` after 1..3 random mutations (module doc)."""
    for _ in range(draw(st.integers(1, 3))):
        ops = ["truncate", "flip", "overwrite", "insert", "delete", "duplicate", "float", "count"]
        if text:
            ops += ["token", "token", "token", "line", "encoding"]
        op = draw(st.sampled_from(ops))
        n = len(data)
        # anywhere, or in the second half: the payload behind a header, which uniform positions
        # in a small file with a long header (a PLY's 62 property lines) would seldom reach
        pos = draw(st.one_of(st.integers(0, max(n - 1, 0)), st.integers(n // 2, max(n - 1, 0))))
        if op == "truncate":
            data = data[:pos]
        elif op == "flip" and n:
            b = bytearray(data)
            for _ in range(draw(st.integers(1, 8))):
                i = draw(st.integers(0, n - 1))
                b[i] ^= 1 << draw(st.integers(0, 7))
            data = bytes(b)
        elif op == "overwrite":
            data = data[:pos] + draw(st.binary(min_size=1, max_size=16)) + data[pos + 16:]
        elif op == "insert":
            data = data[:pos] + draw(st.binary(min_size=1, max_size=64)) + data[pos:]
        elif op == "delete":
            data = data[:pos] + data[pos + draw(st.integers(1, 64)):]
        elif op == "duplicate":
            span = data[pos:pos + draw(st.integers(1, 256))]
            data = data[:pos] + span + data[pos:]
        elif op == "float":
            width = draw(st.sampled_from([4, 8]))
            at = pos - pos % width
            value = struct.pack("<d", draw(st.sampled_from(_FLOATS))) if width == 8 else \
                struct.pack("<f", draw(st.sampled_from(_FLOATS32)))
            data = data[:at] + value + data[at + width:]
        elif op == "count":
            width = draw(st.sampled_from([4, 8]))
            value = draw(st.sampled_from(_COUNTS)) % (1 << (8 * width))
            data = data[:pos] + value.to_bytes(width, "little") + data[pos + width:]
        elif op == "token":
            numbers = list(_NUMBER.finditer(data))
            if numbers:
                m = numbers[draw(st.integers(0, len(numbers) - 1))]
                data = data[:m.start()] + draw(st.sampled_from(_TOKENS)) + data[m.end():]
        elif op == "line":
            lines = data.split(b"\n")
            i, j = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            how = draw(st.sampled_from(["delete", "duplicate", "swap"]))
            if how == "delete":
                del lines[i]
            elif how == "duplicate":
                lines.insert(i, lines[i])
            else:
                lines[i], lines[j] = lines[j], lines[i]
            data = b"\n".join(lines)
        elif op == "encoding":
            how = draw(st.sampled_from(["utf-16", "latin-1", "bom"]))
            if how == "utf-16":
                data = data.decode("latin-1").encode("utf-16")
            elif how == "latin-1":
                data = data[:pos] + b"\xe9\xff" + data[pos:]
            else:
                data = b"\xef\xbb\xbf" + data
    return data


def memory_bound(input_bytes: int) -> int:
    """Most bytes a case may allocate (tracemalloc peak): 64 MiB of working room plus
    64 times the input (decoded images, float64 copies of float32 columns)."""
    return 64 * 2**20 + 64 * input_bytes


def run_case(reader: str, read: Callable[[], object], check: Callable[[object], None], input_bytes: int) -> str:
    """Call ``read()`` under the contract (module doc); return "ok" or "InputError"."""
    tracemalloc.start()
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_SECONDS)
    try:
        try:
            value = read()
        except InputError as exc:
            message = str(exc)
            assert message and "\n" not in message, f"{reader}: InputError of {message.count(chr(10)) + 1} lines"
            outcome = "InputError"
        else:
            outcome = check(value) or "ok"  # a check may name another outcome, e.g. "refused (None)"
        _, peak = tracemalloc.get_traced_memory()
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        tracemalloc.stop()
    assert peak <= memory_bound(input_bytes), f"{reader}: allocated {peak} bytes for {input_bytes} bytes of input"
    STATS.setdefault(reader, Counter())[outcome] += 1
    return outcome


def write_stats(path: str | os.PathLike) -> None:
    """Merge `STATS` into the JSON file ``path`` (reader -> {outcome: cases})."""
    path = Path(path)
    merged = json.loads(path.read_text()) if path.is_file() else {}
    for reader, counts in STATS.items():
        entry = merged.setdefault(reader, {})
        for outcome, n in counts.items():
            entry[outcome] = entry.get(outcome, 0) + n
    path.write_text(json.dumps(merged, indent=1, sort_keys=True) + "\n")
