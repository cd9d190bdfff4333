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
