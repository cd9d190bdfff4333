"""`splatbench bench ab`: the alternating old/new harness. Timings are never checked;
only the protocol (alternation, medians, the quiet-machine rule, clean-up)."""

from __future__ import annotations

import subprocess
from pathlib import Path

from click.testing import CliRunner

from splatbench.bench import ab
from splatbench.cli import main

REPO = Path(__file__).resolve().parents[1]


def test_ratio_only_on_a_quiet_machine():
    quiet = ab.summarize("10 8x8", "c11f838", [3.0, 1.0, 2.0, 9.0, 2.0], [1.0, 1.5, 0.5, 1.0, 4.0],
                         [0.2, 0.9, 1.0, 0.5, 0.3, 0.1])
    assert (quiet.old_median, quiet.new_median, quiet.ratio, quiet.note) == (2.0, 1.0, 2.0, "")
    busy = ab.summarize("10 8x8", "c11f838", [2.0] * 5, [1.0] * 5, [0.2, 1.01, 0.3])
    assert busy.ratio is None and busy.note.startswith("ratio withheld: 1-minute load average reached 1.01 > 1.0")


def test_bad_commit_is_one_line(tmp_path):
    result = CliRunner().invoke(main, ["bench", "ab", "--against", "no-such-commit", "--synthetic", "10", "8x8",
                                       "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert "--against: 'no-such-commit' is not a commit of" in result.output and "Traceback" not in result.output


def test_alternating_runs_against_head_and_clean_up(monkeypatch):
    monkeypatch.setattr(ab, "QUIET_LOAD", -1.0)  # this machine is never quiet enough: the ratio is withheld
    (r,) = ab.run_ab(REPO, "HEAD", [(50, 16, 16)], repeats=5, warmup=1)
    assert len(r.old_seconds) == len(r.new_seconds) == 5 and min(r.old_seconds + r.new_seconds) > 0
    assert len(r.loads) == 6 and r.ratio is None and "withheld" in r.note
    trees = subprocess.run(["git", "-C", str(REPO), "worktree", "list"], capture_output=True, text=True).stdout
    assert "splatbench-ab-" not in trees  # the temporary worktree is gone
