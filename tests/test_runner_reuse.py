"""The runner copies a run another experiment of the same results folder finished (the same run
id, kind, scene, seed and resolved config) instead of running it again, for a ``reusable`` kind
(training); never for one whose numbers depend on when it ran, never with ``reuse=False``, never
from a record whose config is not this run's."""

from __future__ import annotations

import json
import tomllib

from click.testing import CliRunner

from splatbench.experiments import expand, parse_experiment, run_experiment
from splatbench.experiments.store import read_records, read_table, result_path

FIRST = """
name = "first"
kind = "{kind}"
scenes = ["alpha"]
seeds = [0, 1]
[axes]
x = [0.0, 1.5]
"""
# shares x = 1.5 with FIRST (the same run ids), adds x = 3.0; its axis is labelled by a variant
SECOND = """
name = "second"
kind = "{kind}"
scenes = ["alpha"]
seeds = [0, 1]
[variants.level]
mid = {{ x = 1.5 }}
high = {{ x = 3.0 }}
"""
REUSABLE = "tests.kinds_for_tests:REUSABLE"
PLAIN = "tests.kinds_for_tests:DUMMY"


def spec_of(text: str, kind: str):
    return parse_experiment(tomllib.loads(text.format(kind=kind)), source="test.toml", default_name="test")


def test_a_run_another_experiment_finished_is_copied_with_this_experiments_labels(tmp_path):
    results = tmp_path / "results"
    first, second = spec_of(FIRST, REUSABLE), spec_of(SECOND, REUSABLE)
    assert run_experiment(first, workers=1, results_dir=results, progress=False).done == 4
    shared = {r.run_id for r in expand(first)} & {r.run_id for r in expand(second)}
    assert len(shared) == 2  # x = 1.5, seeds 0 and 1: the same resolved config, so the same ids

    summary = run_experiment(second, workers=1, results_dir=results, progress=False)
    assert (summary.done, summary.skipped, summary.reused, summary.total) == (2, 2, 2, 4)
    assert "2 of them reused" in summary.line()
    originals = read_records(results / "first")
    copies = read_records(results / "second")
    for run_id in shared:
        copy, original = copies[run_id], originals[run_id]
        assert copy.reused_from == "first" and copy.experiment == "second"
        assert copy.labels == {"level": "mid"} and original.labels == {"x": 1.5}
        # the numbers and the provenance of the run are the original's
        assert (copy.metrics, copy.curves, copy.seconds, copy.started, copy.code) == \
            (original.metrics, original.curves, original.seconds, original.started, original.code)
    assert {r.reused_from for rid, r in copies.items() if rid not in shared} == {""}
    table = read_table(results / "second")
    assert sorted(table.loc[table.reused_from == "first", "run_id"]) == sorted(shared)

    # a copy of a copy names the experiment the run ran for
    third = spec_of(SECOND.replace('name = "second"', 'name = "third"'), REUSABLE)
    run_experiment(third, workers=1, results_dir=results, progress=False)
    assert {read_records(results / "third")[rid].reused_from for rid in shared} == {"first"}


def test_a_run_another_experiments_live_runner_holds_is_left_to_it(tmp_path):
    # Two runners on two experiments that share run ids (tools/run_grids.sh's lanes): a shared run
    # the other experiment's runner is running is not run twice; the next invocation copies it.
    from splatbench.experiments.claims import try_claim

    results = tmp_path / "results"
    first, second = spec_of(FIRST, REUSABLE), spec_of(SECOND, REUSABLE)
    run_experiment(first, workers=1, results_dir=results, progress=False)
    shared = sorted({r.run_id for r in expand(first)} & {r.run_id for r in expand(second)})
    result_path(results, "first", shared[0]).unlink()  # first's runner is running it again, now:
    claim = try_claim(results / "first", shared[0])  # held by a live process (this one)
    assert claim is not None
    summary = run_experiment(second, workers=1, results_dir=results, progress=False)
    assert (summary.done, summary.reused, summary.claimed) == (2, 1, 1), summary.line()
    assert shared[0] not in read_records(results / "second")

    # once it is finished there, the next invocation copies it
    run_experiment(first, workers=1, results_dir=results, progress=False, reuse=False)  # first's own run
    assert shared[0] not in read_records(results / "first")  # still held: its runner has it
    claim.release()
    run_experiment(first, workers=1, results_dir=results, progress=False)
    summary = run_experiment(second, workers=1, results_dir=results, progress=False)
    assert (summary.done, summary.reused, summary.claimed) == (0, 1, 0), summary.line()
    assert read_records(results / "second")[shared[0]].reused_from == "first"


def test_a_run_another_experiment_finished_after_the_start_is_copied_when_its_turn_comes(tmp_path, monkeypatch):
    # The copy is looked for again as each run is submitted: a runner that started while the other
    # experiment's runner was still running a shared run copies it once it is there.
    import splatbench.experiments.runner as runner_module

    results = tmp_path / "results"
    first, second = spec_of(FIRST, REUSABLE), spec_of(SECOND, REUSABLE)
    run_experiment(first, workers=1, results_dir=results, progress=False)
    real, calls = runner_module.reuse_finished, []

    def not_yet_at_the_start(results_dir, spec, runs):
        calls.append(len(runs))
        return [] if len(calls) == 1 else real(results_dir, spec, runs)  # the start's look finds none

    monkeypatch.setattr(runner_module, "reuse_finished", not_yet_at_the_start)
    summary = run_experiment(second, workers=1, results_dir=results, progress=False)
    assert calls == [4]  # the start's look, for the pending runs; each run's turn looks again itself
    assert (summary.done, summary.skipped, summary.reused, summary.total) == (2, 2, 2, 4), summary.line()
    copies = read_records(results / "second")
    assert sorted(rid for rid, r in copies.items() if r.reused_from == "first") == \
        sorted({r.run_id for r in expand(first)} & {r.run_id for r in expand(second)})
    assert len(read_table(results / "second")) == 4 and set(read_table(results / "second").status) == {"done"}


def test_a_copy_never_overwrites_a_runs_own_finished_record(tmp_path):
    # With lanes, experiment second may copy a shared run from first while first's own runner has it
    # queued: when first's runner reaches it, its own done record stays its own (not a copy of a copy).
    from splatbench.experiments.runner import reuse_finished

    results = tmp_path / "results"
    first, second = spec_of(FIRST, REUSABLE), spec_of(SECOND, REUSABLE)
    run_experiment(first, workers=1, results_dir=results, progress=False)
    run_experiment(second, workers=1, results_dir=results, progress=False)  # copies the shared runs
    shared = [r for r in expand(first) if r.run_id in {s.run_id for s in expand(second)}]
    before = {r.run_id: read_records(results / "first")[r.run_id] for r in shared}
    assert reuse_finished(results, first, shared) == []  # second's copies are there, first's own too
    after = read_records(results / "first")
    assert all(after[rid] == rec and rec.reused_from == "" for rid, rec in before.items())


def test_no_reuse_for_a_kind_that_is_not_reusable_or_when_turned_off(tmp_path):
    for kind, reuse in ((PLAIN, True), (REUSABLE, False)):
        results = tmp_path / f"{kind[-5:]}-{reuse}"
        run_experiment(spec_of(FIRST, kind), workers=1, results_dir=results, progress=False)
        summary = run_experiment(spec_of(SECOND, kind), workers=1, results_dir=results, progress=False,
                                 reuse=reuse)
        assert (summary.done, summary.reused) == (4, 0)
        assert {r.reused_from for r in read_records(results / "second").values()} == {""}


def test_a_record_whose_config_is_not_the_runs_is_not_reused(tmp_path):
    results = tmp_path / "results"
    first, second = spec_of(FIRST, REUSABLE), spec_of(SECOND, REUSABLE)
    run_experiment(first, workers=1, results_dir=results, progress=False)
    shared = sorted({r.run_id for r in expand(first)} & {r.run_id for r in expand(second)})
    # a file under the right name whose config says otherwise (edited, or written by other code)
    path = result_path(results, "first", shared[0])
    data = json.loads(path.read_text())
    data["config"]["x"] = 9.0
    path.write_text(json.dumps(data))
    summary = run_experiment(second, workers=1, results_dir=results, progress=False)
    assert (summary.done, summary.reused) == (3, 1)
    assert read_records(results / "second")[shared[0]].reused_from == ""


def test_the_cli_says_what_it_reused_and_no_reuse_turns_it_off(tmp_path):
    from splatbench.cli import main

    results = tmp_path / "results"
    for name, text in (("first", FIRST), ("second", SECOND)):
        (tmp_path / f"{name}.toml").write_text(text.format(kind=REUSABLE))
    runner = CliRunner()
    args = ["--results", str(results), "--workers", "1", "--no-progress"]
    assert runner.invoke(main, ["run", str(tmp_path / "first.toml"), *args]).exit_code == 0
    out = runner.invoke(main, ["run", str(tmp_path / "second.toml"), *args])
    assert out.exit_code == 0, out.output
    assert "skipped 2 (finished, 2 of them reused from another experiment)" in out.stdout
    (tmp_path / "third.toml").write_text(SECOND.replace('"second"', '"third"').format(kind=REUSABLE))
    out = runner.invoke(main, ["run", str(tmp_path / "third.toml"), *args, "--no-reuse"])
    assert out.exit_code == 0 and out.stdout.startswith("done 4, skipped 0 (finished)"), out.output


def test_the_report_counts_the_reused_runs(tmp_path):
    from splatbench.reports.report import reuse_facts

    results = tmp_path / "results"
    first, second = spec_of(FIRST, REUSABLE), spec_of(SECOND, REUSABLE)
    run_experiment(first, workers=1, results_dir=results, progress=False)
    run_experiment(second, workers=1, results_dir=results, progress=False)
    assert reuse_facts(read_table(results / "first")) == ""
    assert reuse_facts(read_table(results / "second")).startswith(
        "Reused: 2 of the 4 runs ran for another experiment") and "(2 from `first`)" in \
        reuse_facts(read_table(results / "second"))
    # a table from before records named it has no column: nothing to say
    assert reuse_facts(read_table(results / "second").drop(columns=["reused_from"])) == ""


def test_dry_run_marks_what_a_run_would_reuse_and_what_it_reused(tmp_path, capsys):
    from splatbench.cli import main

    results = tmp_path / "results"
    for name, text in (("first", FIRST), ("second", SECOND)):
        (tmp_path / f"{name}.toml").write_text(text.format(kind=REUSABLE))
    runner = CliRunner()
    args = ["--results", str(results)]
    assert runner.invoke(main, ["run", str(tmp_path / "first.toml"), *args, "--workers", "1",
                                "--no-progress"]).exit_code == 0
    before = runner.invoke(main, ["run", str(tmp_path / "second.toml"), *args, "--dry-run"]).output.splitlines()
    assert sum("reusable" in line and line.endswith("(from first)") for line in before) == 2
    assert sum(" pending " in line for line in before) == 2
    off = runner.invoke(main, ["run", str(tmp_path / "second.toml"), *args, "--dry-run", "--no-reuse"]).output
    assert "reusable" not in off
    # the runner says what it reused, even without a progress bar (on stderr)
    out = runner.invoke(main, ["run", str(tmp_path / "second.toml"), *args, "--workers", "1", "--no-progress"])
    assert "2 of them reused: the same run id and config finished for first" in out.stderr
    after = runner.invoke(main, ["run", str(tmp_path / "second.toml"), *args, "--dry-run"]).output.splitlines()
    assert sum(line.endswith("(reused from first)") and " done " in line for line in after) == 2


def test_the_reports_run_time_counts_only_the_runs_made_for_it(tmp_path):
    from splatbench.reports.report import run_time

    results = tmp_path / "results"
    run_experiment(spec_of(FIRST, REUSABLE), workers=1, results_dir=results, progress=False)
    run_experiment(spec_of(SECOND, REUSABLE), workers=1, results_dir=results, progress=False)
    table = read_table(results / "second")
    assert "over 2 runs" in run_time(table)  # 4 done, 2 of them copies of first's runs
    assert "over 4 runs" in run_time(table.assign(reused_from=""))
