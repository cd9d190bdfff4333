"""`splatbench bench ab-train`: the alternating old/new training harness. Timings are
never checked; only the protocol (same setup on both sides, alternation, the
quiet-machine rule of `bench ab`, clean-up) and the one-line errors."""

from __future__ import annotations

import subprocess
from contextlib import contextmanager
from pathlib import Path

import pytest
from click.testing import CliRunner

from splatbench.bench import ab, ab_train
from splatbench.metrics import load as load_rule
from splatbench.bench.ab_train import AbTrainSettings, format_train_result, run_ab_train
from splatbench.cli import main
from splatbench.errors import InputError

REPO = Path(__file__).resolve().parents[1]


def test_both_sides_train_the_same_run_in_alternation_and_clean_up(monkeypatch):
    monkeypatch.setattr(load_rule, "QUIET_SHARE", -1.0)  # never quiet enough: the shared rule must withhold the ratio
    trees_made = []

    @contextmanager
    def recording_old_tree(repo, commit):
        with ab.old_tree(repo, commit) as tree:
            trees_made.append(tree)
            yield tree

    # record this run's temporary worktree (other runs may hold theirs in the same repository meanwhile)
    monkeypatch.setattr(ab_train, "old_tree", recording_old_tree)
    settings = AbTrainSettings(sizes=(24,), gaussians=60, views=2, block=2, pairs=5, warmup=1)
    (r,) = run_ab_train(REPO, "HEAD", settings)
    t = r.timing
    assert len(t.old_seconds) == len(t.new_seconds) == 5 and min(t.old_seconds + t.new_seconds) > 0
    assert len(t.loads) == 7 and t.ratio is None  # at the start, before each of the 5 pairs, at the end and "withheld" in t.note
    assert r.old_it_per_s == pytest.approx(2 / t.old_median, rel=1e-3)
    # HEAD and this tree train the same scene with the same seed in two processes: the losses
    # after every block agree bit for bit (training is deterministic by seed), and they change
    # from block to block (the steps really ran). Fails in a tree whose training code is edited
    # but not committed -- the two sides then differ, which is what this checks.
    assert r.old_losses == r.new_losses and len(set(r.new_losses)) == 5
    assert len(r.old_cpu_seconds) == len(r.new_cpu_seconds) == 5 and min(r.old_cpu_seconds + r.new_cpu_seconds) > 0
    assert r.cpu_ratio > 0
    assert "24x24" in format_train_result(r) and "withheld" in format_train_result(r)
    (tree,) = trees_made
    trees = subprocess.run(["git", "-C", str(REPO), "worktree", "list"], capture_output=True, text=True).stdout
    assert str(tree) not in trees and not tree.exists()  # the temporary worktree is gone


def test_fewer_than_five_pairs_is_refused():
    with pytest.raises(InputError, match="--pairs: expected >= 5"):
        AbTrainSettings(pairs=4)


def test_bad_commit_is_one_line(tmp_path):
    result = CliRunner().invoke(main, ["bench", "ab-train", "--against", "no-such-commit", "--size", "24",
                                       "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert "--against: 'no-such-commit' is not a commit of" in result.output and "Traceback" not in result.output
