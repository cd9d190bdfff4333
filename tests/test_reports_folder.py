"""The top-level reports/ holds reports only (issue 42 item 6): what made a report (a script, a
device session's commands) lives in tools/, so that reports/ is read, never run. A report folder
keeps its results, tables, figures and logs."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: What a program is: a source file by its suffix, or any file with an execute bit.
PROGRAM_SUFFIXES = {".py", ".sh", ".bash", ".ipynb", ".pl", ".rb", ".js"}


def programs_under(folder: Path) -> list[str]:
    found = []
    for path in sorted(folder.rglob("*")):
        if path.is_file() and (path.suffix in PROGRAM_SUFFIXES or os.access(path, os.X_OK)):
            found.append(path.relative_to(folder).as_posix())
    return found


def test_reports_holds_no_program():
    assert programs_under(ROOT / "reports") == [], "move these to tools/ (and point the report at them there)"


def test_the_rule_finds_a_script_and_an_executable(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "report.md").write_text("# a report\n")
    (tmp_path / "a" / "verify.py").write_text("print(1)\n")
    (tmp_path / "run").write_text("#!/bin/sh\n")
    (tmp_path / "run").chmod(0o755)
    assert programs_under(tmp_path) == ["a/verify.py", "run"]
