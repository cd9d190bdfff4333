"""`make help` names every target the Makefile declares phony, and every phony target exists
(issue 42, item 7): a target added without a help line, or a `.PHONY` name left behind after its
rule went, fails here."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

MAKEFILE = Path(__file__).resolve().parents[1] / "Makefile"


def phony_targets(text: str) -> list[str]:
    declared = [line.split(":", 1)[1].split() for line in text.splitlines() if line.startswith(".PHONY:")]
    return [name for names in declared for name in names]


def defined_targets(text: str) -> set[str]:
    # `name:` or `name: prerequisites` at the start of a line; not `NAME := value` or `NAME ?= value`
    return {m.group(1) for m in re.finditer(r"^([A-Za-z0-9_.-]+)\s*:(?!=)", text, re.M)}


def help_lines(text: str) -> list[str]:
    """The lines the help recipe echoes, read from the Makefile (no make needed)."""
    recipe = text.split("\nhelp:", 1)[1].split("\n\n", 1)[0]
    return re.findall(r'^\t@echo "(.*)"$', recipe, re.M)


def named(target: str, lines: list[str]) -> bool:
    return any(re.match(rf"make {re.escape(target)}(\s|$)", line) for line in lines)


def test_every_phony_target_is_defined():
    text = MAKEFILE.read_text(encoding="utf-8")
    phony = phony_targets(text)
    assert phony, "Makefile: no .PHONY line"
    missing = [t for t in phony if t not in defined_targets(text)]
    assert not missing, f"Makefile: .PHONY names targets with no rule: {missing}"


def test_help_names_every_phony_target():
    text = MAKEFILE.read_text(encoding="utf-8")
    lines = help_lines(text)
    missing = [t for t in phony_targets(text) if not named(t, lines)]
    assert not missing, f"Makefile: `make help` does not name {missing}"


def test_the_helpers_notice_a_missing_help_line():
    # The check above could pass vacuously if help_lines read nothing: a target whose help line is
    # removed must be reported.
    text = MAKEFILE.read_text(encoding="utf-8")
    without = "\n".join(line for line in text.splitlines() if not line.startswith('\t@echo "make reports'))
    assert named("reports", help_lines(text)) and not named("reports", help_lines(without))


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_help_prints_what_the_recipe_says():
    done = subprocess.run(["make", "-s", "-f", str(MAKEFILE), "help"], cwd=MAKEFILE.parent,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    printed = done.stdout.splitlines()
    text = MAKEFILE.read_text(encoding="utf-8")
    assert printed == help_lines(text)
    assert all(named(t, printed) for t in phony_targets(text))
