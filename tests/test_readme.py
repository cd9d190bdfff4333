"""Every ```python block of README.md and docs/experiments.md runs as written from the
repository root, each in a fresh interpreter (so it may use only what it imports and
what the repository holds). Other docs' blocks are signatures to fill in, not programs."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^```python\n(.*?)^```$", re.S | re.M)


DOCS = ("README.md", "docs/experiments.md")


def python_blocks(name: str) -> list[str]:
    return BLOCK.findall((REPO / name).read_text(encoding="utf-8"))


BLOCKS = [(name, i) for name in DOCS for i in range(len(python_blocks(name)))]


def test_each_document_has_python_blocks():
    assert {name for name, _ in BLOCKS} == set(DOCS)


@pytest.mark.parametrize("name, index", BLOCKS, ids=[f"{n}-{i}" for n, i in BLOCKS])
def test_python_block_runs_as_written(name, index):
    code = python_blocks(name)[index]
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{name}: python block {index} failed:\n{code}\n{done.stderr[-3000:]}"
