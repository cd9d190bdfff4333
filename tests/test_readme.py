"""Every ```python block of README.md runs as written from the repository root, each
in a fresh interpreter (so it may use only what it imports and what the repository
holds)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^```python\n(.*?)^```$", re.S | re.M)


def python_blocks(text: str) -> list[str]:
    return BLOCK.findall(text)


def test_the_readme_has_python_blocks():
    assert python_blocks((REPO / "README.md").read_text(encoding="utf-8"))


@pytest.mark.parametrize("index", range(len(python_blocks((REPO / "README.md").read_text(encoding="utf-8")))))
def test_readme_python_block_runs_as_written(index):
    code = python_blocks((REPO / "README.md").read_text(encoding="utf-8"))[index]
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"README python block {index} failed:\n{code}\n{done.stderr[-3000:]}"
