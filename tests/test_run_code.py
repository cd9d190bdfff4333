"""Which code a run ran: `versions.code_version`, the record's ``code`` and the report's "Code:" line.

A grid whose runs span commits (a rerun after a change to the trainer's numerics) has a confound
the run ids cannot see; the report names the commits so that a reader can."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pandas as pd

from splatbench.experiments.store import RunRecord, build_table
from splatbench.reports.report import code_facts
from splatbench.versions import SPLATBENCH_VERSION, code_version

ROOT = Path(__file__).resolve().parents[1]


def test_code_version_names_the_checkouts_commit():
    inside_git = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    code = code_version()
    if inside_git.returncode == 0:
        assert re.fullmatch(r"git:[0-9a-f]{12}(\+dirty)?", code), code
        assert inside_git.stdout.startswith(code[4:16])
    else:  # an installed copy, not a checkout
        assert code == SPLATBENCH_VERSION


def _table(codes: list[str]) -> pd.DataFrame:
    return build_table([RunRecord(run_id=f"{i:016x}", experiment="e", kind="train", scene="s", seed=i,
                                  status="done", config={}, code=c) for i, c in enumerate(codes)])


def test_the_report_names_the_commits_its_runs_ran_at():
    assert code_facts(_table(["git:aaaaaaaaaaaa"] * 3)) == "Code: every run at `git:aaaaaaaaaaaa` (3 runs)."
    mixed = code_facts(_table(["git:aaaaaaaaaaaa", "git:bbbbbbbbbbbb", "git:bbbbbbbbbbbb", ""]))
    assert mixed.startswith("Code: the runs ran at more than one commit: `git:aaaaaaaaaaaa` (1 run), "
                            "`git:bbbbbbbbbbbb` (2 runs); 1 run(s) ran before runs recorded it")
    # a table of runs that recorded nothing, or one without the column (a committed report's), says nothing
    assert code_facts(_table(["", ""])) == ""
    assert code_facts(_table(["git:aaaaaaaaaaaa"]).drop(columns=["code"])) == ""


def test_a_record_written_before_runs_recorded_their_code_still_reads():
    old = {"format": 1, "run_id": "0" * 16, "experiment": "e", "kind": "train", "scene": "s", "seed": 0,
           "status": "done", "config": {}}
    assert RunRecord.from_dict(old).code == ""


def test_the_code_line_covers_the_checks_runs_and_names_them_apart():
    """A check added later (`splatbench run --check-only`, `splatbench report --rebuild --results`) ran at
    another commit than its grid, or its grid recorded none: the line says the runs span commits."""
    a, b = "git:aaaaaaaaaaaa", "git:bbbbbbbbbbbb"
    assert code_facts(_table([a] * 3), _table([a] * 2)) == \
        "Code: every run at `git:aaaaaaaaaaaa` (5 runs: the grid's 3 and the check's 2)."
    assert code_facts(_table([a] * 3), _table([b] * 2)).startswith(
        "Code: the runs ran at more than one commit: the grid's runs at `git:aaaaaaaaaaaa` (3 runs); the check's runs "
        "at `git:bbbbbbbbbbbb` (2 runs); a difference between runs at different commits is also a difference of code")
    # a committed grid from before runs recorded their code (no column), the check's runs at one commit
    assert code_facts(_table([a] * 3).drop(columns=["code"]), _table([b] * 2)).startswith(
        "Code: the runs may span more than one commit (not every run recorded its own; those that did ran at "
        "`git:bbbbbbbbbbbb`): the grid's 3 runs ran before runs recorded it; the check's runs at `git:bbbbbbbbbbbb` "
        "(2 runs);")
    # a check with no done run, or none recorded anywhere: as before
    assert code_facts(_table([a] * 3), _table([])) == "Code: every run at `git:aaaaaaaaaaaa` (3 runs)."
    assert code_facts(_table(["", ""]), _table(["", ""])) == ""
