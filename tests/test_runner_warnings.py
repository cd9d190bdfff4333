"""The runner's console shows every distinct warning of its runs once, in full, and counts
repeats (the trial's issue 2: it showed a run's first warning and "(and N more)")."""

from __future__ import annotations

import tomllib

from splatbench.experiments import parse_experiment, run_experiment
from splatbench.experiments.runner import WarningTally
from splatbench.experiments.store import read_records

GRID = """
name = "noisy"
kind = "tests.kinds_for_tests:DUMMY"
scenes = ["alpha"]
seeds = [0, 1, 2]
[variants.mode]
quiet = {}
loud = { mode = "warn-many" }
"""
SHARED = "warning: dummy runs share this one"


def test_every_distinct_warning_is_shown_once_and_repeats_are_counted(tmp_path, capsys):
    spec = parse_experiment(tomllib.loads(GRID), source="noisy.toml", default_name="noisy")
    summary = run_experiment(spec, workers=1, results_dir=tmp_path, progress=False)
    assert (summary.done, summary.warned) == (6, 3)
    # each loud run warned of its own warning and of the shared one (twice): 3 + 1 distinct warnings
    records = [r for r in read_records(tmp_path / "noisy").values() if r.warnings]
    assert sorted(r.warnings[0] for r in records) == [f"warning: dummy run told to warn (seed {s})" for s in range(3)]
    assert all(r.warnings[1:] == [SHARED, SHARED] for r in records)
    err = capsys.readouterr().err.splitlines()
    shown = [line.split(" warned: ", 1)[1] for line in err if " runs warned: " not in line and " warned: " in line]
    assert sorted(shown) == sorted([SHARED, *(f"warning: dummy run told to warn (seed {s})" for s in range(3))])
    assert not [line for line in err if "more)" in line]  # nothing left out behind a count
    assert [line for line in err if " runs warned: " in line or "distinct warnings" in line] == [
        "noisy: 4 distinct warnings from this invocation's runs, each shown above with the first run that gave it; "
        "given by several runs:",
        f"noisy: x 3 runs warned: {SHARED}"]


def test_warning_tally_counts_runs_in_the_order_first_seen():
    tally = WarningTally()
    assert tally.first_seen(["b", "a", "b"]) == ["b", "a"]
    assert tally.first_seen(["a", "c"]) == ["c"]
    assert tally.first_seen(["a"]) == []
    assert tally.runs == {"b": 1, "a": 3, "c": 1}  # a run counts once however often it says it
    assert tally.summary("g") == ["g: 3 distinct warnings from this invocation's runs, each shown above with the "
                                  "first run that gave it; given by several runs:", "g: x 3 runs warned: a"]
    lone = WarningTally()
    lone.first_seen(["only"])
    assert lone.summary("g") == []  # shown once with its run: nothing to count
