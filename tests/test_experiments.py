"""Experiment runner: grid expansion and run ids, validation before anything runs,
resume, failure recording, the results table, SIGKILL-and-resume, and Dask on loopback.

Everything runs the dummy kind of `tests.kinds_for_tests` (deterministic numbers from the config,
a configurable sleep, told to fail or crash on demand), so no rendering is involved.
Network: the Dask test binds to 127.0.0.1 only.
"""

from __future__ import annotations

import dataclasses
import json
import os
import random
import re
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from splatbench.errors import InputError
from splatbench.experiments import check_runs, expand, load_experiment, parse_experiment, run_experiment
from splatbench.experiments.grid import make_run_id
from splatbench.versions import code_version
from splatbench.experiments.store import (CORE_COLUMNS, TABLE_NAME, RunRecord, build_table, read_records, read_table,
                                          remove_stale_temps, result_path, write_record)

REPO = Path(__file__).resolve().parents[1]

SWEEP = """
name = "sweep"
kind = "tests.kinds_for_tests:DUMMY"
scenes = ["alpha", "beta"]
seeds = [0, 1, 2]
[base]
sleep = {sleep}
opts.b = "q"
[axes]
x = [0.0, 1.5]
"""


def spec_of(text: str, source: str = "test.toml"):
    return parse_experiment(tomllib.loads(text), source=source, default_name="test")


def write(tmp_path: Path, text: str, name: str = "exp.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def deterministic(frame: pd.DataFrame) -> pd.DataFrame:
    """The columns that do not depend on when or where a run ran, sorted by run id."""
    keep = [c for c in frame.columns if c in CORE_COLUMNS or c.split(".")[0] in ("axis", "config", "metric")
            or c == "curves"]
    return frame[keep].sort_values("run_id").reset_index(drop=True)


def assert_table_matches_files(folder: Path, expected_ids: set[str]) -> None:
    """The parquet table holds exactly the per-run files, field by field."""
    table = read_table(folder)
    records = read_records(folder)
    assert set(table["run_id"]) == set(records) == expected_ids
    assert len(table) == len(records)
    for row in table.to_dict("records"):
        row = {k: None if _missing(v) else v for k, v in row.items()}
        rec = records[row["run_id"]]
        assert (row["status"], row["scene"], row["seed"], row["error"]) == (rec.status, rec.scene, rec.seed,
                                                                              rec.error)
        assert row["config.x"] == rec.config["x"] and row["config.opts.b"] == rec.config["opts"]["b"]
        assert row["code"] == rec.code == code_version()  # the code each run ran (tests/test_run_code.py)
        for name, value in rec.metrics.items():
            assert row[f"metric.{name}"] == value, name
        for name, label in rec.labels.items():
            assert row[f"axis.{name}"] == label, name
        assert (row["curves"] is None) == (rec.curves is None)
        if rec.curves is not None:
            assert json.loads(row["curves"]) == rec.curves


def _missing(value) -> bool:
    """A missing cell as parquet gives it back (None, NaN or pd.NA)."""
    return value is None or (not isinstance(value, (list, dict, str)) and bool(pd.isna(value)))


# --------------------------------------------------------------------------- grid and run ids
GRID = """
name = "grid"
kind = "tests.kinds_for_tests:DUMMY"
scenes = ["alpha", "beta"]
seeds = [0, 1]
[base]
n = 2
opts.b = "q"
[axes]
x = [0.0, 1.5]
"opts.a" = [1, 2]
[variants.mode]
good = {}
bad = { mode = "fail", sleep = 0.5 }
"""


def test_grid_expands_in_documented_order_with_labels():
    runs = expand(spec_of(GRID))
    assert len(runs) == 2 * 2 * 2 * 2 * 2
    assert [r.scene for r in runs[:16]] == ["alpha"] * 16  # scenes outermost
    assert [r.seed for r in runs[:4]] == [0, 1, 0, 1]  # seeds innermost
    first, last = runs[0], runs[-1]
    assert first.labels == {"x": 0.0, "opts.a": 1, "mode": "good"}
    assert last.labels == {"x": 1.5, "opts.a": 2, "mode": "bad"}
    assert last.config == {"x": 1.5, "n": 2, "mode": "fail", "sleep": 0.5, "gate": "", "opts": {"a": 2, "b": "q"},
                           "scene": "beta", "seed": 1}
    assert first.config["mode"] == "ok" and first.config["sleep"] == 0.0  # the kind's defaults, resolved
    assert len({r.run_id for r in runs}) == len(runs)
    assert all(re.fullmatch(r"[0-9a-f]{16}", r.run_id) for r in runs)
    assert [r.run_id for r in expand(spec_of(GRID))] == [r.run_id for r in runs]  # deterministic


def test_run_id_is_the_hash_of_the_full_resolved_config():
    run = expand(spec_of(GRID))[0]
    assert run.run_id == make_run_id("tests.kinds_for_tests:DUMMY", run.config)
    # Defaults written out, dotted keys in any of their forms, key order: the same run.
    same = spec_of("""
        name = "other-name"
        kind = "tests.kinds_for_tests:DUMMY"
        scenes = ["alpha"]
        seeds = [0]
        [base.opts]
        b = "q"
        a = 1
        [base]
        mode = "ok"
        x = 0
        n = 2
        sleep = 0.0
        """)
    assert expand(same)[0].run_id == run.run_id
    # Changing any single field (or scene, seed, kind) changes it.
    changes = {"x": 0.25, "n": 3, "sleep": 0.1, "gate": "g", "mode": "fail", "opts": {"a": 5, "b": "q"},
               "opts.b": None, "scene": "beta", "seed": 7}
    ids = {run.run_id}
    for key, value in changes.items():
        config = json.loads(json.dumps(run.config))
        if key == "opts.b":
            config["opts"]["b"] = "z"
        else:
            config[key] = value
        ids.add(make_run_id("tests.kinds_for_tests:DUMMY", config))
    ids.add(make_run_id("other-kind", run.config))
    assert len(ids) == len(changes) + 2


def test_adding_an_axis_value_adds_only_new_run_ids():
    before = {r.run_id for r in expand(spec_of(GRID))}
    after = {r.run_id for r in expand(spec_of(GRID.replace("x = [0.0, 1.5]", "x = [0.0, 1.5, 3.0]")))}
    assert before < after and len(after - before) == 2 * 2 * 2 * 2
    more_seeds = {r.run_id for r in expand(spec_of(GRID.replace("seeds = [0, 1]", "seeds = [0, 1, 2]")))}
    assert before < more_seeds


def test_one_at_a_time_grid_and_table_valued_axis():
    spec = spec_of("""
        kind = "tests.kinds_for_tests:DUMMY"
        scenes = ["alpha"]
        grid = "one-at-a-time"
        [base]
        x = 1.0
        opts = { a = 3, b = "base" }
        [axes]
        x = [1.0, 2.0]                       # 1.0 equals the base: the same run, listed once
        opts = [{ a = 4 }]                   # a table replaces the whole sub-table
        """)
    runs = expand(spec)
    assert [r.labels["x"] for r in runs] == [1.0, 2.0, 1.0]
    assert runs[2].config["opts"] == {"a": 4, "b": "p"}  # b back to the kind's default, not the base's
    assert runs[0].labels["opts"] == '{"a":3,"b":"base"}'


# --------------------------------------------------------------------------- malformed files
#: The lines every dummy-kind case starts with.
HEAD = 'kind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha"]\n'
MALFORMED = {
    "unknown top-level field": (HEAD + 'sceens = ["beta"]\n', r"sceens: unknown key \(did you mean 'scenes'\?\)"),
    "empty axis": (HEAD + '[axes]\nx = []\n', r"axes\.x: empty axis"),
    "empty variant": (HEAD + '[variants.v]\n', r"variants\.v: empty axis"),
    "unknown scene": ('kind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha", "delta"]\n', r"scenes: unknown scene 'delta'"),
    "unknown config key in base": (HEAD + '[base]\nopts.c = 1\n',
                                   r"base: opts\.c: unknown key"),
    "unknown config key in an axis": (HEAD + '[axes]\nxx = [1, 2]\n',
                                      r"axes\.xx = 1: xx: unknown key"),
    "bad value in a variant": (HEAD + '[variants.v]\nok = {}\nno = { mode = "x" }\n',
                               r"variants\.v\.no: mode: expected 'ok', 'warn', 'fail' or 'crash'"),
    "unknown kind": ('kind = "nope"\nscenes = ["alpha"]\n', r"kind: unknown run kind 'nope'"),
    "axis not a list": (HEAD + '[axes]\nx = 3\n', r"axes\.x: expected a list"),
    "reserved key": (HEAD + '[axes]\nseed = [1, 2]\n', r"axes\.seed: 'seed' is set by"),
    "duplicate seed": (HEAD + 'seeds = [1, 1]\n', r"seeds: duplicate value 1"),
    "unknown runner field": (HEAD + '[runner]\nthreads = 2\n',
                             r"runner\.threads: unknown key"),
    "bad scheduler": (HEAD + '[runner]\nscheduler = "127.0.0.1"\n',
                      r"runner\.scheduler: expected an address like tcp://HOST:PORT"),
    "a base value one variant cannot take": ('kind = "train"\nscenes = ["textured"]\n[base]\noptim.lr_means = 0.0\n'
                                             'optim.lr_means_final = 0.0\n[variants.densify]\nnone = { strategy.name = "none" }\n'
                                             'budget = { strategy.name = "budget" }\n',
                                             r"variants\.densify\.budget: optim\.lr_means: 0 freezes the means, but strategy "
                                             r"'budget'"),
    "invalid TOML": ('kind = "tests.kinds_for_tests:DUMMY"\nscenes = [\n', r"invalid TOML"),
    # overlapping dimensions: in a product cell with both, the later used to drop the other's value silently
    "two variants setting one field": (HEAD + '[variants.v]\nok = {}\nloud = { mode = "warn" }\n'
                                       '[variants.w]\nquick = {}\nslow = { sleep = 0.1, mode = "ok" }\n',
                                       r"variants\.w\.slow\.mode: overlaps variants\.v\.loud\.mode \(in a cell with "
                                       r"both, the later would drop the other's value\); set it in one variant, or "
                                       r"merge the two into one \[variants\.NAME\] table$"),
    "a variant setting a field inside another's": (HEAD + '[variants.v]\nwhole = { opts = {} }\n'
                                                   '[variants.w]\none = { opts.a = 2 }\n',
                                                   r"variants\.w\.one\.opts\.a: overlaps variants\.v\.whole\.opts "
                                                   r"\(in a cell with both"),
    "an axis inside another axis": (HEAD + '[axes]\nopts = [{ a = 1 }]\n"opts.a" = [2]\n',
                                    r"axes\.opts\.a: overlaps axes\.opts \(in a cell with both, the later would drop "
                                    r"the other's value\); sweep only one of them, or use a \[variants\.NAME\] table "
                                    r"for values that go together$"),
    # one field written quoted and dotted: the same path twice, said as the base says it (not "overlaps" itself)
    "one axis written quoted and dotted": (HEAD + '[axes]\n"opts.a" = [1]\nopts.a = [2]\n',
                                           r"axes\.opts\.a: set twice \(also as 'opts\.a'\)$"),
    "one base field written quoted and dotted": (HEAD + '[base]\n"opts.a" = 1\nopts.a = 2\n',
                                                 r"base\.opts\.a: set twice \(also as 'opts\.a'\)$"),
    "one variant field written quoted and dotted": (HEAD + '[variants.v]\nl = { "opts.a" = 1, opts.a = 2 }\n',
                                                    r"variants\.v\.l\.opts\.a: set twice \(also as 'opts\.a'\)$"),
    "a variant inside an axis": (HEAD + '[axes]\nopts = [{ a = 1 }]\n[variants.v]\nl = { opts.b = "q" }\n',
                                 r"variants\.v\.l\.opts\.b: also swept by axes\.opts \(in a cell with both, the later "
                                 r"would drop the other's value\); set it in the axis or in the variant, not both$"),
    "a scene table setting a swept data field": ('kind = "tests.kinds_for_tests:DUMMY"\n'
                                                 'scenes = [{ name = "here", path = ".", downscale = 8 }]\n'
                                                 '[axes]\ndata.downscale = [4, 8]\n',
                                                 r"scenes\.here\.downscale: sets data\.downscale, which "
                                                 r"axes\.data\.downscale sweeps \(the scene's value would drop the "
                                                 r"swept one in its runs\); leave it out of one of them$"),
}


def test_two_variant_tables_on_different_fields_combine_in_a_product_grid(tmp_path):
    """The overlap refusals above leave disjoint variant tables alone: every cell keeps both
    tables' values."""
    path = write(tmp_path, HEAD + '[variants.v]\nok = {}\nloud = { mode = "warn" }\n'
                                  '[variants.w]\nquick = {}\nslow = { sleep = 0.1 }\n')
    runs = expand(load_experiment(path))
    assert [(r.labels["v"], r.labels["w"], r.config["mode"], r.config["sleep"]) for r in runs] == [
        ("ok", "quick", "ok", 0.0), ("ok", "slow", "ok", 0.1),
        ("loud", "quick", "warn", 0.0), ("loud", "slow", "warn", 0.1)]


@pytest.mark.parametrize("case", MALFORMED, ids=list(MALFORMED))
def test_malformed_experiment_is_one_line_error_before_anything_runs(tmp_path, case):
    text, pattern = MALFORMED[case]
    path = write(tmp_path, text)
    with pytest.raises(InputError) as err:
        load_experiment(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(str(path)), message
    assert re.search(pattern, message), message

    results = tmp_path / "results"
    out = CliRunner().invoke(_main(), ["run", str(path), "--results", str(results), "--no-progress"])
    assert out.exit_code == 2, out.output
    assert out.stderr.strip().count("\n") == 0 and "splatbench: error: " in out.stderr and "Traceback" not in out.stderr
    assert not results.exists()  # nothing ran, nothing was written


def test_known_scenes_callback_overrides_the_kinds(tmp_path):
    path = write(tmp_path, 'kind = "tests.kinds_for_tests:DUMMY"\nscenes = ["mine"]\n')
    assert load_experiment(path, known_scenes=lambda: {"mine"}).scenes == ("mine",)
    with pytest.raises(InputError, match="scenes: unknown scene 'mine'"):
        load_experiment(path)


def _main():
    from splatbench.cli import main

    return main


# --------------------------------------------------------------------------- store
def test_store_reads_only_whole_result_files(tmp_path):
    folder = tmp_path / "exp"
    rec = RunRecord(run_id="0123456789abcdef", experiment="exp", kind="tests.kinds_for_tests:DUMMY", scene="alpha", seed=0, status="done",
                    config={"x": 1.0, "scene": "alpha", "seed": 0}, metrics={"value": 2.5})
    write_record(tmp_path, rec)
    # A valid-looking record under a temporary name, a foreign file, a torn file: none is a result.
    fake = {**rec.to_dict(), "run_id": "fedcba9876543210"}
    (folder / ".fedcba9876543210.json.99999999.abcd.tmp").write_text(json.dumps(fake))
    (folder / "notes.json").write_text("{}")
    (folder / "aaaaaaaaaaaaaaaa.json").write_text('{"run_id": "aaaaaaaaaaaaaaaa", "status": "do')
    assert list(read_records(folder)) == [rec.run_id]
    assert read_records(folder)[rec.run_id] == rec
    assert remove_stale_temps(folder) == 1  # pid 99999999 cannot exist
    assert not list(folder.glob("*.tmp")) and not list(folder.glob(".*.tmp"))


def test_table_columns_hold_mixed_types():
    recs = [RunRecord(run_id=f"{i:016x}", experiment="e", kind="k", scene="s", seed=i, status="done",
                      config={"sh_degree": deg, "bg": [0, 0, 0]}, labels={"sh_degree": deg},
                      metrics={"psnr": 20.0 + i, "n": 10 * i, "ok": True}, curves={"step": [1, 2]})
               for i, deg in enumerate([0, 3, "auto"])]
    frame = build_table(recs)
    assert list(frame["config.sh_degree"]) == ["0", "3", '"auto"']  # mixed: JSON text
    assert list(frame["config.bg"]) == ["[0, 0, 0]"] * 3
    assert frame["metric.psnr"].dtype == "float64" and str(frame["metric.n"].dtype) == "Int64"
    assert list(frame.columns[:len(CORE_COLUMNS)]) == list(CORE_COLUMNS)


# --------------------------------------------------------------------------- runner
def mode_grid(name: str, plain: str, other: str, mode: str) -> str:
    """A dummy-kind grid over seeds 0 and 1 with two cells: ``plain`` and ``other`` (``mode``)."""
    return f"""
        name = "{name}"
        kind = "tests.kinds_for_tests:DUMMY"
        scenes = ["alpha"]
        seeds = [0, 1]
        [variants.mode]
        {plain} = {{}}
        {other} = {{ mode = "{mode}" }}
        """


def test_failed_runs_are_recorded_the_rest_complete_and_resume_skips_done(tmp_path):
    text = mode_grid("mixed", "good", "bad", "fail")
    results = tmp_path / "results"
    spec = spec_of(text)
    first = run_experiment(spec, workers=2, results_dir=results, progress=False)
    assert (first.done, first.skipped, first.failed, first.total) == (2, 0, 2, 4)
    folder = results / "mixed"
    records = read_records(folder)
    failed = [r for r in records.values() if r.status == "failed"]
    assert len(failed) == 2 and all(r.labels["mode"] == "bad" for r in failed)
    for r in failed:
        assert r.error.startswith("RuntimeError: dummy run told to fail") and "\n" not in r.error
        assert "Traceback" in r.traceback
    assert_table_matches_files(folder, {r.run_id for r in expand(spec)})
    done_files = {rid: result_path(results, "mixed", rid).stat().st_mtime_ns for rid, r in records.items()
                  if r.status == "done"}

    # Again with one more seed: done runs are skipped, failed ones retried, new cells run.
    spec2 = spec_of(text.replace("seeds = [0, 1]", "seeds = [0, 1, 2]"))
    second = run_experiment(spec2, workers=2, results_dir=results, progress=False)
    assert (second.done, second.skipped, second.failed, second.total) == (1, 2, 3, 6)
    assert {rid: result_path(results, "mixed", rid).stat().st_mtime_ns for rid in done_files} == done_files
    assert_table_matches_files(folder, {r.run_id for r in expand(spec2)})


def test_a_runs_warnings_reach_its_file_the_table_and_the_report(tmp_path, capsys):
    """What a run warned of (`RunResult.warnings`) is never dropped by the grid: the run's
    file, the table's ``warnings`` column and a "Warnings" section (with a pointer in the
    header) carry it; a grid whose runs warned of nothing has neither."""
    from splatbench.reports.report import build_report, write_report

    text = mode_grid("warned", "quiet", "loud", "warn")
    results = tmp_path / "results"
    spec = spec_of(text)
    summary = run_experiment(spec, workers=1, results_dir=results, progress=False)
    assert (summary.done, summary.warned) == (4, 2)
    assert summary.line().startswith('done 4 (2 warned: see their report\'s "Warnings"), skipped 0')
    said = [line for line in capsys.readouterr().err.splitlines() if " warned: " in line]  # without a bar too
    assert len(said) == 2 and all("warning: dummy run told to warn" in line for line in said)
    records = read_records(results / "warned")
    for r in records.values():
        expected = [f"warning: dummy run told to warn (seed {r.seed})"] if r.labels["mode"] == "loud" else []
        assert r.warnings == expected
    table = read_table(results / "warned")
    assert table.columns[-2:].tolist() == ["warnings", "curves"]
    assert sorted(json.loads(w) for w in table.warnings.dropna()) == [["warning: dummy run told to warn (seed 0)"],
                                                                      ["warning: dummy run told to warn (seed 1)"]]
    report = write_report(build_report(spec, results), tmp_path / "out").read_text()
    assert "**Warnings:** 2 run(s) warned" in report and "## Warnings" in report
    # the Summary says so too, quoting the distinct warnings (a warning can change what the numbers mean)
    summary = report[report.index("## Summary"):report.index("## Protocol and runs")]
    assert ('**Warnings**: 2 of 4 runs warned (2 distinct: "warning: dummy run told to warn (seed 0)"; "warning: '
            'dummy run told to warn (seed 1)"); each in full in "Warnings".') in summary
    rows = [line for line in report.splitlines() if "dummy run told to warn" in line and line.startswith("|")]
    assert len(rows) == 2 and all("| alpha | `mode=loud` |" in row for row in rows)
    quiet = spec_of(text.replace('loud = { mode = "warn" }', "").replace('name = "warned"', 'name = "quiet"'))
    run_experiment(quiet, workers=1, results_dir=results, progress=False)
    assert "Warnings" not in write_report(build_report(quiet, results), tmp_path / "out2").read_text()
    # a stored record whose warnings are not strings is damaged (its run is redone), not trusted
    path = result_path(results, "warned", next(iter(records)))
    data = json.loads(path.read_text())
    path.write_text(json.dumps({**data, "warnings": [3]}))
    damaged: list = []
    assert next(iter(records)) not in read_records(results / "warned", damaged)
    assert "warnings: expected a list of strings" in damaged[0][1]


def test_a_run_that_kills_its_worker_is_recorded_and_the_rest_complete(tmp_path):
    spec = spec_of("""
        name = "crashy"
        kind = "tests.kinds_for_tests:DUMMY"
        scenes = ["alpha"]
        [variants.mode]
        good = {}
        other = { x = 1.0 }
        crash = { mode = "crash" }
        """)
    # One worker, the crash last: two pools (the one it breaks, the one it breaks alone).
    summary = run_experiment(spec, workers=1, results_dir=tmp_path, progress=False)
    assert (summary.done, summary.failed) == (2, 1)
    records = read_records(tmp_path / "crashy")
    for r in records.values():
        assert r.status == ("failed" if r.labels["mode"] == "crash" else "done")
        if r.status == "failed":
            assert r.error == "worker process died while running it (a crash, or killed)"


# --------------------------------------------------------------------------- execution order
TRACED = """
name = "traced"
kind = "tests.kinds_for_tests:TRACE"
scenes = ["alpha", "beta"]
seeds = [0, 1, 2]
[base]
log = "{log}"
[axes]
cell = ["a", "b"]
[check]
protocol = "long"
scene = "beta"
cells = [{{ cell = "a" }}, {{ cell = "b" }}]
"""

#: The runs of TRACED in the order they execute: seed by seed, scene by scene, each cell in turn;
#: then the check's runs, seed by seed, each cell in turn.
INTERLEAVED = [f"{scene} {cell} {seed} -" for seed in (0, 1, 2) for scene in ("alpha", "beta") for cell in "ab"] + \
              [f"beta {cell} {seed} long" for seed in (0, 1, 2) for cell in "ab"]


def _line(run) -> str:
    return f"{run.scene} {run.config['cell']} {run.seed} {run.config.get('protocol') or '-'}"


def test_runs_execute_interleaved_across_cells_and_the_table_keeps_expand_order(tmp_path):
    """One worker runs the grid seed-major (consecutive runs are different cells, so a machine
    drifting over the grid's time spreads over every cell), the check's runs after the grid's;
    the results table is in `expand`'s order (scene, cell, seed), then the check's. A resumed
    grid runs what is left in the same interleaved order."""
    log = tmp_path / "ran.log"
    spec = spec_of(TRACED.format(log=log))
    grid, checks = expand(spec), check_runs(spec)
    assert [_line(r) for r in grid] == [f"{scene} {cell} {seed} -" for scene in ("alpha", "beta") for cell in "ab"
                                        for seed in (0, 1, 2)]  # expand's own order: unchanged
    results = tmp_path / "results"
    summary = run_experiment(spec, workers=1, results_dir=results, progress=False)
    assert (summary.done, summary.failed, summary.total) == (18, 0, 18)
    assert log.read_text().splitlines() == INTERLEAVED
    table = read_table(results / "traced")
    assert list(table.run_id) == [r.run_id for r in [*grid, *checks]]
    assert list(table["metric.line"]) == [_line(r) for r in [*grid, *checks]]

    # resumed: the runs left (here every cell "b" of seeds 1 and 2, and one check run) run interleaved too
    gone = [r for r in [*grid, *checks] if (r.config["cell"] == "b" and r.seed > 0) or _line(r) == "beta a 2 long"]
    for r in gone:
        result_path(results, "traced", r.run_id).unlink()
    log.unlink()
    again = run_experiment(spec, workers=1, results_dir=results, progress=False)
    assert (again.done, again.skipped) == (len(gone), 18 - len(gone))
    assert log.read_text().splitlines() == [line for line in INTERLEAVED if line in {_line(r) for r in gone}]
    assert list(read_table(results / "traced").run_id) == [r.run_id for r in [*grid, *checks]]


def test_an_executor_with_many_slots_gets_the_runs_submitted_interleaved(tmp_path, monkeypatch):
    """With several workers it is the order of submission that spreads drift: the Dask executor
    (every run submitted at once; the scheduler runs them first submitted, first run) gets them
    interleaved. A stand-in executor records the submissions and runs each in this process."""
    from concurrent.futures import Future

    from splatbench.experiments import runner
    from splatbench.experiments.one_run import RunContext, execute_run

    submitted: list[str] = []

    class Recording:
        capacity = sys.maxsize  # as DaskExecutor's

        def __init__(self, workers, threads, scheduler, prepared):
            assert workers == 4

        def submit(self, run, results_dir):
            submitted.append(_line(run))
            fut: Future = Future()
            fut.set_result(execute_run(run, results_dir, RunContext()))
            return fut

        def wait(self, futures, timeout=None):
            return set(futures)

        @staticmethod
        def broken(exc):
            return False

        def close(self, cancel=False):
            pass

    monkeypatch.setattr(runner, "DaskExecutor", Recording)
    spec = spec_of(TRACED.format(log=tmp_path / "ran.log"))
    summary = run_experiment(spec, workers=4, executor="dask", results_dir=tmp_path / "results", progress=False)
    assert (summary.done, summary.total) == (18, 18)
    assert submitted == INTERLEAVED
    assert list(read_table(tmp_path / "results" / "traced").run_id) == [r.run_id for r in [*expand(spec),
                                                                                            *check_runs(spec)]]


def test_a_dask_worker_runs_them_in_the_order_submitted(tmp_path):
    """Dask's scheduler hands out runs submitted at once first submitted, first (a one-worker
    `LocalCluster` on 127.0.0.1 runs them interleaved), so the order of submission holds there too."""
    log = tmp_path / "ran.log"
    spec = spec_of(TRACED.format(log=log))
    summary = run_experiment(spec, workers=1, executor="dask", results_dir=tmp_path / "results", progress=False)
    assert (summary.done, summary.total) == (18, 18)
    assert log.read_text().splitlines() == INTERLEAVED


# --------------------------------------------------------------------------- kill and resume
@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The 12-run sweep run once, without interruption, on the local executor."""
    results = tmp_path_factory.mktemp("uninterrupted")
    spec = spec_of(SWEEP.format(sleep=0.2))
    summary = run_experiment(spec, workers=2, results_dir=results, progress=False)
    assert (summary.done, summary.failed, summary.total) == (12, 0, 12)
    return spec, read_table(results / "sweep")


def _result_files(folder: Path) -> list[Path]:
    return [p for p in folder.glob("*.json") if re.fullmatch(r"[0-9a-f]{16}\.json", p.name)] if folder.is_dir() else []


def _start_cli(path: Path, results: Path, log: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "splatbench.experiments.cli", str(path), "--workers", "2",
           "--results", str(results), "--no-progress"]
    return subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=open(log, "ab"), start_new_session=True)


def test_sigkill_at_random_points_then_resume_loses_and_duplicates_nothing(tmp_path, uninterrupted):
    spec, expected = uninterrupted
    path = write(tmp_path, SWEEP.format(sleep=0.2))
    results, log = tmp_path / "results", tmp_path / "runner.log"
    folder = results / "sweep"
    rng = random.Random(6)
    for _ in range(3):
        target = min(len(_result_files(folder)) + rng.randint(1, 4), 11)
        proc = _start_cli(path, results, log)
        deadline = time.monotonic() + 90
        while len(_result_files(folder)) < target and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, 0.25))  # anywhere: mid-run, mid-write, between runs
        os.killpg(proc.pid, signal.SIGKILL)  # the runner and its pool workers
        proc.wait(timeout=30)
        for p in _result_files(folder):  # a result file is always whole
            assert json.loads(p.read_text())["status"] == "done", p
    finished_before = {p.name for p in _result_files(folder)}
    assert 0 < len(finished_before) < 12, "the kills should land mid-sweep"

    proc = _start_cli(path, results, log)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0, log.read_text()[-3000:]
    assert out.decode().strip().splitlines()[-1] == f"done {12 - len(finished_before)}, " \
        f"skipped {len(finished_before)} (finished), 0 claimed by another runner, failed 0 of 12"

    files = _result_files(folder)
    ids = {r.run_id for r in expand(spec)}
    assert sorted(p.stem for p in files) == sorted(ids)  # each run exactly once
    assert all(json.loads(p.read_text())["status"] == "done" for p in files)
    assert not [p for p in folder.iterdir() if p.name.endswith(".tmp")]  # stale temporaries cleaned
    assert_table_matches_files(folder, ids)
    pd.testing.assert_frame_equal(deterministic(read_table(folder)), deterministic(expected))


# --------------------------------------------------------------------------- dask
def test_dask_local_cluster_on_loopback_gives_the_local_results(tmp_path, uninterrupted, monkeypatch):
    pytest.importorskip("distributed")
    import distributed

    spec, expected = uninterrupted
    addresses = []

    class Recording(distributed.LocalCluster):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            addresses.append(self.scheduler_address)
            addresses.extend(self.scheduler_info.get("workers", {}))  # worker addresses

    monkeypatch.setattr(distributed, "LocalCluster", Recording)
    summary = run_experiment(spec, workers=2, executor="dask", results_dir=tmp_path, progress=False)
    assert (summary.done, summary.failed, summary.total) == (12, 0, 12)
    assert addresses and all(a.startswith("tcp://127.0.0.1:") for a in addresses), addresses
    folder = tmp_path / "sweep"
    assert_table_matches_files(folder, {r.run_id for r in expand(spec)})
    pd.testing.assert_frame_equal(deterministic(read_table(folder)), deterministic(expected))
    assert (folder / TABLE_NAME).is_file()


def test_dask_existing_scheduler_on_loopback_via_the_cli(tmp_path, uninterrupted):
    """`splatbench run --executor dask --scheduler tcp://...` hands the runs to a scheduler
    that was already running (here a loopback cluster started by the test) and gets the
    local executor's results."""
    distributed = pytest.importorskip("distributed")
    from click.testing import CliRunner

    from splatbench.cli import main

    spec, expected = uninterrupted
    path = write(tmp_path, SWEEP.format(sleep=0.2), "sweep.toml")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        result = CliRunner().invoke(main, ["run", str(path), "--executor", "dask", "--scheduler", address,
                                           "--results", str(tmp_path / "results")])
        assert result.exit_code == 0, result.output
        # the runs went through this scheduler: it counted one finished task per run
        done = {name: sum(p.state_counts.values()) for name, p in cluster.scheduler.task_prefixes.items()}
        assert sum(done.values()) >= 12, done
    folder = tmp_path / "results" / "sweep"
    assert_table_matches_files(folder, {r.run_id for r in expand(spec)})
    pd.testing.assert_frame_equal(deterministic(read_table(folder)), deterministic(expected))


@pytest.mark.parametrize("executor", ["local", "dask"])
def test_workers_get_their_budget_and_what_prepare_returned_with_each_run(tmp_path, executor):
    """The runner hands each worker its Dr.Jit thread budget (CPUs // workers) and what
    the kind's ``prepare`` returned in the runner, with the run: it adds no environment
    variable (the workers' ``SPLATBENCH_*`` are the runner's own)."""
    if executor == "dask":
        pytest.importorskip("distributed")
    spec = parse_experiment({"name": "probe", "kind": "tests.kinds_for_tests:PROBE", "scenes": ["s"],
                             "seeds": [0, 1, 2]}, source="probe.toml")
    summary = run_experiment(spec, workers=2, executor=executor, results_dir=tmp_path, progress=False)
    assert (summary.done, summary.failed) == (3, 0)
    table = read_table(tmp_path / "probe")
    # the runner splits the cores this process may run on (its affinity) among the workers
    assert (table["metric.drjit_threads"] == max(1, len(os.sched_getaffinity(0)) // 2)).all()
    assert (table["metric.prepared_runs"] == 3).all() and (table["metric.prepared_parent"] == os.getpid()).all()
    assert not (table["metric.pid"] == os.getpid()).any()  # the runs ran in workers
    own = ",".join(sorted(k for k in os.environ if k.startswith("SPLATBENCH_")))
    assert (table["metric.env"].fillna("") == own).all(), table["metric.env"].tolist()


def test_a_kind_written_before_prepared_existed_still_runs(tmp_path):
    """`run(config, workdir)` (two parameters, the contract before `prepare`'s result was
    passed on) is still called, without it; a three-parameter run gets it."""
    from splatbench.experiments.one_run import call_run

    seen = []
    call_run(lambda config, workdir: seen.append((config, workdir)), {"a": 1}, tmp_path, "prepared")
    call_run(lambda config, workdir, prepared: seen.append(prepared), {"a": 1}, tmp_path, "prepared")
    assert seen == [({"a": 1}, tmp_path), "prepared"]


def test_a_runs_config_is_read_onto_its_kinds_config_dataclass():
    """The engine maps a run's dotted keys onto the kind's Config (`check_config`, `read_config`):
    a field, a field of a dataclass-typed field (``opts.a``, ``raster.tile_size``), an INLINE
    field's own at the top level (the raster kind's ``alpha_min``; the field's own name is no
    key), ``scene`` and ``seed`` always; types are read (an int where a float is declared is that
    float) and the Config's ranges checked, each mistake one line naming the key."""
    from splatbench.experiments.kinds import RUN_KEYS, check_config, read_config
    from splatbench.experiments.raster_kind import RasterConfig
    from splatbench.raster.options import RasterOptions
    from splatbench.train.config import TrainConfig
    from tests.kinds_for_tests import DummyConfig, DummyOpts, ProbeConfig

    def error(call) -> str:
        with pytest.raises(InputError) as err:
            call()
        assert "\n" not in str(err.value)
        return str(err.value)

    cfg = read_config(DummyConfig, {"scene": "alpha", "seed": 2, "x": 1, "opts": {"a": 4}})
    assert cfg == DummyConfig(scene="alpha", seed=2, x=1.0, opts=DummyOpts(a=4)) and isinstance(cfg.x, float)
    assert error(lambda: read_config(DummyConfig, {"opts": {"c": 1}})) == "opts.c: unknown key (known: a, b)"
    assert error(lambda: read_config(DummyConfig, {"n": 0})) == "n: expected an int >= 1, got 0"
    assert error(lambda: read_config(DummyConfig, {"n": "3"})).startswith("n: expected an int")
    assert read_config(ProbeConfig, {"scene": "s", "seed": 1}) == ProbeConfig() and RUN_KEYS == ("scene", "seed")
    raster = read_config(RasterConfig, {"scene": "synthetic-10-8x8", "seed": 0, "eps2d": 1, "tile_size": 8})
    assert raster.options == RasterOptions(eps2d=1.0, tile_size=8) and isinstance(raster.options.eps2d, float)
    assert error(lambda: read_config(RasterConfig, {"scene": "garden", "options": {}})).startswith(
        "options: unknown key")
    assert error(lambda: read_config(RasterConfig, {"scene": "garden", "near": 0.5})) == \
        "near: set by the workload's camera, not by a raster run"
    assert error(lambda: read_config(RasterConfig, {"scene": "garden", "alpha_min": 2.0})).startswith("alpha_min: ")
    assert error(lambda: check_config(TrainConfig, {"raster": {"tile_sise": 8}})) == \
        "raster.tile_sise: unknown key (did you mean 'tile_size'?)"
    check_config(TrainConfig, {"scene": "glossy", "strategy": {"anything": 1}})  # a group that reads its own table


def test_the_engine_refuses_a_key_the_kinds_config_lacks_before_the_kind_sees_it(tmp_path):
    """A kind whose validate accepts anything still never gets a key its Config has no field for:
    the grid checks every run's config against the Config first, naming where the key comes from."""
    from dataclasses import dataclass

    from splatbench.experiments.kinds import RunKind, register_kind
    from tests.kinds_for_tests import DummyRun

    @dataclass(frozen=True)
    class LaxConfig:
        rate: float = 0.1

    register_kind(RunKind(name="lax-kind", validate=lambda config: None, config=LaxConfig, result=DummyRun,
                          run=lambda config, workdir, prepared: None))
    spec = parse_experiment({"name": "lax", "kind": "lax-kind", "scenes": ["s"], "base": {"rate": 0.2, "rat": 1}},
                            source="lax.toml")
    with pytest.raises(InputError, match=r"^lax\.toml: base: rat: unknown key \(did you mean 'rate'\?\)$"):
        expand(spec)
    assert [r.config for r in expand(dataclasses.replace(spec, base={"rate": 0.2}))] == [
        {"rate": 0.2, "scene": "s", "seed": 0}]


def test_a_missing_scene_folder_is_named_as_written_and_where_it_led(tmp_path):
    """A relative path is resolved against the experiment file (often through a link such as
    ../shared): the error gives the path as the user wrote it, then the folder it led to."""
    (tmp_path / "exp").mkdir()
    toml = tmp_path / "exp" / "e.toml"
    toml.write_text('name = "e"\nkind = "train"\nscenes = [{ name = "cap", path = "../data/missing" }]\n'
                    'seeds = [0]\n[base]\niterations = 10\n')
    with pytest.raises(InputError) as err:
        load_experiment(toml)
    message = str(err.value)
    assert f"scenes.cap.path: '../data/missing' ({(tmp_path / 'data' / 'missing').resolve()}) does not exist" \
        in message, message
