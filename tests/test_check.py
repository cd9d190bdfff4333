"""The 7K check (issue 29, item 2): a grid's ``[check]`` reruns its headline's two cells at one
scene, every seed, under graphdeco's 7K protocol; `splatbench run` runs those runs too, under
their own run ids, and `splatbench report` sets their paired difference beside the grid's with
a verdict ("holds", "does not hold", "inconclusive", "not run", "incomplete").

Planning is checked on the train kind itself (expansion renders nothing); running on the dummy
kind of `tests.kinds_for_tests` (its protocol "long"); the report on made-up train records
written as the engine writes them (as tests/test_reports.py does), so the file runs in seconds.
"""

from __future__ import annotations

import dataclasses
import tomllib

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from splatbench.errors import InputError
from splatbench.experiments import check_cells, check_runs, expand, parse_experiment, run_experiment
from splatbench.experiments.grid import check_experiment
from splatbench.experiments.store import RunRecord, read_records, write_record
from splatbench.metrics.stats import paired_difference
from splatbench.reports import build_report, write_report
from splatbench.reports.check import CHECK_TABLE_NAME
from splatbench.reports.report import report_from_table

TRAIN_GRID = """
name = "shcheck"
kind = "train"
scenes = ["diffuse", "glossy"]
seeds = [0, 1, 2]
[base]
iterations = 100
eval.every = 50
log_every = 10
data.resolution = 32
data.views = 8
data.spp = 2
[axes]
sh.degree = [0, 1, 3]
loss.ssim_lambda = [0.2, 0.5]
[check]
protocol = "graphdeco-7k"
scene = "glossy"
cells = [{ sh.degree = 0, loss.ssim_lambda = 0.2 }, { sh.degree = 3, loss.ssim_lambda = 0.2 }]
"""


def spec_of(text: str, **changes):
    data = tomllib.loads(text)
    for key, value in changes.items():
        if value is None:
            data.pop(key, None)
        else:
            data[key] = value
    spec = parse_experiment(data, source="x.toml", default_name="x")
    check_experiment(spec)
    return spec


# --------------------------------------------------------------------------- planning
def test_check_runs_are_the_two_cells_at_the_protocol():
    spec = spec_of(TRAIN_GRID)
    a, b = check_cells(spec)
    runs = check_runs(spec)
    assert [r.run_id for r in runs] == [r.run_id for r in (*a, *b)]
    # every seed of the two cells, only the check's scene
    assert [(r.scene, r.seed, r.labels["sh.degree"], r.labels["loss.ssim_lambda"]) for r in runs] == \
        [("glossy", s, d, 0.2) for d in (0, 3) for s in (0, 1, 2)]
    for r in runs:
        c = r.config
        # the protocol overrides the grid's length and curve: graphdeco's 7K column, a point every 700 steps
        assert (c["protocol"], c["iterations"], c["eval"]["every"]) == ("graphdeco-7k", 7000, 700)
        assert c["schedule"] == "scaled" and c["strategy"]["reset_every"] == 3000  # graphdeco's, as written
        # everything else is the grid's cell
        assert (c["log_every"], c["data"]) == (10, {"resolution": 32, "views": 8, "spp": 2, "layout": "auto",
                                                  "test_every": 8, "masks": True})
        assert c["loss"]["ssim_lambda"] == 0.2 and c["sh"]["degree"] == r.labels["sh.degree"]
    # own run ids; the grid's are those of the same file without [check] (existing results are found)
    grid = expand(spec)
    assert not {r.run_id for r in runs} & {r.run_id for r in grid}
    assert [r.run_id for r in grid] == [r.run_id for r in expand(spec_of(TRAIN_GRID, check=None))]
    assert len({r.run_id for r in runs}) == 6
    # the grid's side of the comparison: the grid's own runs of those cells
    by_id = {r.run_id: r for r in grid}
    for cell in check_cells(spec, at_protocol=False):
        for r in cell:
            assert r.run_id in by_id and by_id[r.run_id].config == r.config and r.config["iterations"] == 100


def test_check_of_a_one_at_a_time_grid_takes_its_base_and_nested_keys():
    text = """
name = "sched"
kind = "train"
scenes = ["textured"]
seeds = [0, 1, 2]
grid = "one-at-a-time"
[base]
iterations = 2000
data.resolution = 32
strategy.reset_every = "10%"
[axes]
strategy.reset_every = ["10%", 0]
strategy.refine_every = [50, 100]
[check]
protocol = "graphdeco-7k"
scene = "textured"
cells = [{}, { strategy.reset_every = 0 }]
"""
    spec = spec_of(text)
    base, never = check_cells(spec)
    assert [r.config["strategy"]["reset_every"] for r in base] == ["10%"] * 3  # 3,000 of graphdeco's 30,000
    assert [r.config["strategy"]["reset_every"] for r in never] == [0] * 3
    assert {r.config["iterations"] for r in (*base, *never)} == {7000}
    grid = {r.run_id for r in expand(spec)}
    assert all(r.run_id in grid for cell in check_cells(spec, at_protocol=False) for r in cell)
    # a number names the axis value it equals (TOML's 50.0 is the axis's 50)
    other = spec_of(text.replace("{ strategy.reset_every = 0 }", "{ strategy.refine_every = 50.0 }"))
    assert [r.config["strategy"]["refine_every"] for r in check_cells(other)[1]] == [50] * 3


@pytest.mark.parametrize("check, message", [
    ({"protocol": "graphdeco-7k", "scene": "glossy", "cells": [{"sh.degree": 0, "loss.ssim_lambda": 0.2}]},
     "check.cells: expected two cells"),
    ({"protocol": "graphdeco-7k", "scene": "textured", "cells": [{}, {}]},
     "check.scene: expected one of the grid's scenes (diffuse, glossy), got 'textured'"),
    ({"protocol": "graphdeco-7k", "scene": "glossy", "cells": [{"sh.degree": 0, "loss.ssim_lambda": 0.2},
                                                              {"sh.degree": 2, "loss.ssim_lambda": 0.2}]},
     "check.cells[1].sh.degree: 2 is not a value of the grid's axis 'sh.degree'"),
    ({"protocol": "graphdeco-7k", "scene": "glossy", "cells": [{"sh.degree": 0}, {"sh.degree": 3}]},
     "check.cells[0]: names no value of 'loss.ssim_lambda'"),
    ({"protocol": "graphdeco-7k", "scene": "glossy", "cells": [{"sh.degree": 0, "loss.ssim_lambda": 0.2, "lr": 1},
                                                              {"sh.degree": 3, "loss.ssim_lambda": 0.2}]},
     "check.cells[0].lr: not an axis of the grid"),
    ({"protocol": "graphdeco-7k", "scene": "glossy", "cells": [{"sh.degree": 3, "loss.ssim_lambda": 0.2}] * 2},
     "check.cells: the two cells are the same cell"),
    ({"protocol": "graphdeco-7k", "scene": "glossy", "cells": [{}, {}], "seeds": [0]},
     "check.seeds: unknown key"),
    ({"protocol": "quick", "scene": "glossy", "cells": [{"sh.degree": 0, "loss.ssim_lambda": 0.2},
                                                       {"sh.degree": 3, "loss.ssim_lambda": 0.2}]},
     "check.protocol: 'quick' is laid over the grid's own iterations"),
    ({"protocol": "graphdeco-9k", "scene": "glossy", "cells": [{"sh.degree": 0, "loss.ssim_lambda": 0.2},
                                                              {"sh.degree": 3, "loss.ssim_lambda": 0.2}]},
     "check.protocol: expected one of 'quick', 'graphdeco-30k', 'graphdeco-7k', got 'graphdeco-9k'"),
])
def test_a_bad_check_is_one_line_before_anything_runs(check, message):
    with pytest.raises(InputError) as err:
        spec_of(TRAIN_GRID, check=check)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert str(err.value).startswith("x.toml: check")


def test_a_check_at_the_grids_own_protocol_or_of_a_kind_without_protocols_is_refused():
    with pytest.raises(InputError, match=r"check.protocol: the grid already runs 'graphdeco-7k'"):
        spec_of(TRAIN_GRID.replace("iterations = 100\neval.every = 50", 'protocol = "graphdeco-7k"\neval.every = 700'))
    raster = """
name = "r"
kind = "raster"
scenes = ["synthetic-100-32"]
seeds = [0, 1, 2]
[axes]
tile_size = [8, 16]
[check]
protocol = "graphdeco-7k"
scene = "synthetic-100-32"
cells = [{ tile_size = 8 }, { tile_size = 16 }]
"""
    with pytest.raises(InputError, match=r"check: run kind 'raster' has no protocols"):
        spec_of(raster)


# --------------------------------------------------------------------------- running
DUMMY_GRID = """
name = "dcheck"
kind = "tests.kinds_for_tests:DUMMY"
scenes = ["alpha", "beta"]
seeds = [0, 1]
[axes]
x = [0.0, 1.5, 3.0]
[check]
protocol = "long"
scene = "beta"
cells = [{ x = 0.0 }, { x = 3.0 }]
"""


def test_run_runs_the_check_after_the_grid_and_resumes(tmp_path):
    spec = spec_of(DUMMY_GRID)
    grid, checks = expand(spec), check_runs(spec)
    summary = run_experiment(spec, workers=2, results_dir=tmp_path, progress=False, check=False)
    assert (summary.done, summary.total) == (len(grid), 12)
    assert set(read_records(tmp_path / "dcheck")) == {r.run_id for r in grid}
    summary = run_experiment(spec, workers=2, results_dir=tmp_path, progress=False)
    assert (summary.done, summary.skipped, summary.total) == (4, 12, 16)  # only the check's 4 runs ran
    records = read_records(tmp_path / "dcheck")
    for r in checks:  # each under its own id, with the protocol's config (curves 7 points long)
        rec = records[r.run_id]
        assert rec.status == "done" and rec.scene == "beta" and len(rec.curves["value"]) == 7
        assert rec.labels == {"x": r.config["x"]} and r.config["x"] in (0.0, 3.0)
    summary = run_experiment(spec, workers=2, results_dir=tmp_path, progress=False)
    assert (summary.done, summary.skipped) == (0, 16)

    from splatbench.experiments.cli import run as run_command

    path = tmp_path / "dcheck.toml"
    path.write_text(DUMMY_GRID)
    out = CliRunner().invoke(run_command, [str(path), "--results", str(tmp_path), "--dry-run"])
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()
    assert sum("check: protocol=long" in line for line in lines) == 4 and "16 runs in" in lines[-1]
    assert all(line.split()[1] == "done" for line in lines[:-1])
    out = CliRunner().invoke(run_command, [str(path), "--results", str(tmp_path), "--dry-run", "--no-check"])
    assert "check:" not in out.output and "12 runs in" in out.output


def test_check_only_runs_the_checks_runs_alone_and_resumes(tmp_path):
    """`splatbench run --check-only`: exactly the check's runs, under the run ids a full run gives them
    (so a later full run skips them), none of the grid's; resumable; --dry-run lists the same runs."""
    from splatbench.cli import main
    from splatbench.experiments.store import read_table

    spec = spec_of(DUMMY_GRID)
    grid, checks = expand(spec), check_runs(spec)
    summary = run_experiment(spec, workers=2, results_dir=tmp_path, progress=False, check_only=True)
    assert (summary.done, summary.skipped, summary.failed, summary.total) == (4, 0, 0, 4)
    assert set(read_records(tmp_path / "dcheck")) == {r.run_id for r in checks}  # none of the grid's ran
    assert list(read_table(tmp_path / "dcheck").run_id) == [r.run_id for r in checks]
    summary = run_experiment(spec, workers=2, results_dir=tmp_path, progress=False, check_only=True)
    assert (summary.done, summary.skipped, summary.total) == (0, 4, 4)
    # a full run afterwards runs the grid's 12 alone: the check's runs are the ones it would have run
    summary = run_experiment(spec, workers=2, results_dir=tmp_path, progress=False)
    assert (summary.done, summary.skipped, summary.total) == (12, 4, 16)
    # the command line: --dry-run --check-only lists the check's runs, in check order, and nothing else
    path = tmp_path / "dcheck.toml"
    path.write_text(DUMMY_GRID)
    fresh = tmp_path / "fresh"
    out = CliRunner().invoke(main, ["run", str(path), "--results", str(fresh), "--dry-run", "--check-only"])
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()
    assert [line.split()[0] for line in lines[:-1]] == [r.run_id for r in checks]
    assert all(line.split()[1] == "pending" and line.endswith("check: protocol=long") for line in lines[:-1])
    assert lines[-1] == f"4 runs in {fresh / 'dcheck'} (the check's only; the grid's left out)"
    out = CliRunner().invoke(main, ["run", str(path), "--results", str(fresh), "--check-only", "--workers", "1",
                                    "--no-progress"])
    assert out.exit_code == 0, out.output
    assert "done 4, skipped 0 (finished), 0 claimed by another runner, failed 0 of 4" in out.output
    assert set(read_records(fresh / "dcheck")) == {r.run_id for r in checks}
    assert not {r.run_id for r in grid} & set(read_records(fresh / "dcheck"))


def test_check_only_without_a_check_or_with_no_check_is_one_line(tmp_path):
    from splatbench.cli import main

    path = tmp_path / "plain.toml"
    path.write_text(DUMMY_GRID.split("[check]")[0])
    for args in (["--check-only"], ["--check-only", "--dry-run"]):
        out = CliRunner().invoke(main, ["run", str(path), "--results", str(tmp_path), *args])
        assert out.exit_code == 2 and out.output.count("\n") == 1, out.output
        assert out.output.startswith(f"splatbench: error: {path}: --check-only: the file has no [check] table")
    with pytest.raises(InputError, match=r"--check-only: the file has no \[check\] table"):
        run_experiment(spec_of(DUMMY_GRID, check=None), workers=1, results_dir=tmp_path, progress=False,
                       check_only=True)
    path.write_text(DUMMY_GRID)
    out = CliRunner().invoke(main, ["run", str(path), "--results", str(tmp_path), "--check-only", "--no-check"])
    assert out.exit_code == 2 and out.output.count("\n") == 1, out.output
    assert "--check-only: runs only the file's [check], --no-check leaves it out" in out.output
    assert not (tmp_path / "dcheck").exists() and not (tmp_path / "plain").exists()  # nothing ran


# --------------------------------------------------------------------------- the report
SH_GRID = """
name = "shfake"
kind = "train"
scenes = ["diffuse", "glossy"]
seeds = [0, 1, 2]
[base]
iterations = 100
eval.every = 50
data.resolution = 32
data.views = 8
data.spp = 2
[axes]
sh.degree = [0, 3]
[check]
protocol = "graphdeco-7k"
scene = "glossy"
cells = [{ sh.degree = 0 }, { sh.degree = 3 }]
"""


def record(spec, run, psnr: float, slope: float = 0.0) -> RunRecord:
    """A finished train run ending at ``psnr`` whose test curve rises ``slope`` dB per 1,000 steps."""
    end = run.config["iterations"]
    every = run.config["eval"]["every"]
    steps = list(range(every, end + 1, every))
    curve = [psnr - slope * (end - s) / 1000 for s in steps]
    metrics = {"test_psnr": psnr, "test_ssim": 0.9, "test_lpips": 0.1, "num_gaussians": 1000,
               "train_seconds": 10.0, "render_ms_per_view": 5.0, "time_loaded": 0, "lpips_net": "alex",
               "lpips_scale_inputs": 1}
    curves = {"step": steps, "psnr": curve, "loss": [0.1] * len(steps), "num_gaussians": [1000] * len(steps),
              "eval_step": steps, "eval_psnr": curve, "eval_ssim": [0.9] * len(steps)}
    return RunRecord(run_id=run.run_id, experiment=spec.name, kind="train", scene=run.scene, seed=run.seed,
                     status="done", config=dict(run.config), labels=dict(run.labels), metrics=metrics, curves=curves,
                     seconds=1.0, started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:01+00:00",
                     worker="h:1")


def grid_results(root, spec, gain: float = 0.5, noise: float = 0.05, code: str = ""):
    """The grid done: SH 3 over SH 0 by ``gain`` dB on glossy, seed noise of ``noise`` dB, flat curves;
    ``code``: the commit the runs record."""
    rng = np.random.default_rng(0)
    for run in expand(spec):
        d = run.labels["sh.degree"]
        write_record(root, dataclasses.replace(record(spec, run, 26.0 + (gain if d == 3 and run.scene == "glossy"
                                                                         else 0.0) + rng.normal(0, noise)), code=code))


def check_results(root, spec, gain: float, slope: float = 0.0, skip: int = 0, noise: float = 0.05, code: str = ""):
    """The check's runs done (but the last ``skip``): SH 3 over SH 0 by ``gain`` dB."""
    rng = np.random.default_rng(1)
    runs = check_runs(spec)
    for run in runs[:len(runs) - skip]:
        d = run.labels["sh.degree"]
        write_record(root, dataclasses.replace(record(spec, run, 28.0 + (gain if d == 3 else 0.0)
                                                      + rng.normal(0, noise), slope if d == 3 else 0.0), code=code))


def test_report_says_not_run_without_the_checks_results(tmp_path):
    spec = spec_of(SH_GRID)
    grid_results(tmp_path / "results", spec)
    report = build_report(spec, tmp_path / "results")
    out = tmp_path / "report"
    text = write_report(report, out).read_text()
    assert report.check.verdict == "not run" and report.check.headline == "7K check: not run"
    assert report.check.rerun.claim is None and report.check.grid.claim.practical
    assert "## Headline at the 7K protocol" in text
    assert ("**7K check: not run** (`sh.degree=3` against `sh.degree=0` on glossy alone, 3 seeds, rerun at "
            "protocol `graphdeco-7k`; no other comparison of the grid is rerun") in text  # the header
    assert ("**7K check: not run**: none of its 6 runs has a finished result. Run `splatbench run x.toml` "
            "(finished runs are skipped) and report again.") in text
    assert "| `graphdeco-7k` | 0 of 6 | – | – | – | – |" in text
    assert "the 3DGS paper's 7K column" in text and not (out / CHECK_TABLE_NAME).exists()
    # each cell's other metrics beside the primary: the grid's side only (the check has no runs yet)
    assert "Each cell's SSIM, LPIPS, Gaussians beside its test PSNR" in text
    assert "| `quick` | `sh.degree=3` |" in text and "| `graphdeco-7k` | `sh.degree=3` |" not in text
    # a grid without [check] names none
    plain = write_report(build_report(spec_of(SH_GRID, check=None), tmp_path / "results"), tmp_path / "plain")
    assert "**7K check: none declared**" in plain.read_text() and "## Headline at" not in plain.read_text()


@pytest.mark.parametrize("grid_gain, gain, slope, noise, verdict, grid_noise", [
    (0.5, 0.6, 0.0, 0.05, "holds", 0.05),            # same sign, significant, above 0.1 dB
    (0.5, 0.6, 0.5, 0.05, "holds", 0.05),            # holds, but SH 3's 7K curve still rises 0.5 dB / 1,000 steps
    (0.5, -0.4, 0.0, 0.05, "does not hold", 0.05),   # the sign flips
    (0.5, 0.03, 0.0, 0.005, "does not hold", 0.005),  # the 7K interval within ±0.1 dB: no practical difference there
    (0.5, 0.03, 0.0, 0.05, "inconclusive", 0.05),    # the 7K interval spans 0 and reaches past 0.1 dB: cannot tell
    (0.5, 0.6, 0.0, 1.0, "inconclusive", 0.05),      # seeds too noisy at 7K: an interval that cannot tell either way
    (0.0, 0.0, 0.0, 0.005, "holds", 0.005),          # no difference at either; both intervals within ±0.1 dB
    (0.0, 0.0, 0.0, 0.2, "inconclusive", 0.05),      # no significant difference, but the interval reaches past 0.1 dB
    (0.0, 0.6, 0.0, 0.05, "does not hold", 0.005),   # no practical difference in the grid, a practical one at 7K
    # the grid's interval reaches past 0.1 dB (no headline of "no difference"): nothing to break, nor to hold
    (0.0, 0.6, 0.0, 0.05, "inconclusive", 0.05),
    (0.0, 0.0, 0.0, 0.005, "inconclusive", 0.05),
])
def test_report_gives_a_verdict_with_the_checks_results(tmp_path, grid_gain, gain, slope, noise, verdict,
                                                        grid_noise):
    spec = spec_of(SH_GRID)
    root = tmp_path / "results"
    grid_results(root, spec, grid_gain, grid_noise)
    check_results(root, spec, gain, slope, noise=noise)
    report = build_report(spec, root)
    out = tmp_path / "report"
    text = write_report(report, out).read_text()
    check = report.check
    assert check.verdict == verdict and f"**7K check: {verdict}**: " in text
    # the numbers are those of the check's own runs, written beside the report, paired over seeds
    table = pd.read_parquet(out / CHECK_TABLE_NAME)
    assert list(table.run_id) == [r.run_id for r in check_runs(spec)]
    per = {d: dict(zip(g.seed, g["metric.test_psnr"])) for d, g in table.groupby("axis.sh.degree")}
    iv = paired_difference(per[0], per[3])
    claim = check.rerun.claim
    assert claim.n == 3 and claim.value == pytest.approx(iv.estimate) and claim.low == pytest.approx(iv.low)
    assert abs(claim.value - gain) < 3 * noise and claim.text in text
    # beside each cell's PSNR, its SSIM, LPIPS and Gaussians at each protocol (record(): 0.9, 0.1 and 1,000 in
    # every run: seeds that did not vary them)
    row = next(line for line in text.splitlines() if line.startswith("| `graphdeco-7k` | `sh.degree=3` |"))
    assert row.endswith("| 0.9000 (no spread) | 0.1000 (no spread) | 1000 (no spread) |"), row
    assert [m.name for m, _, _ in check.rerun.others] == ["test_ssim", "test_lpips", "num_gaussians"]
    # each seed's value of both cells, so that a seed that went its own way shows (the means hide it)
    for seed in (0, 1, 2):
        a, b = per[0][seed], per[3][seed]
        assert f"| `graphdeco-7k` | {seed} | {a:.2f} | {b:.2f} | {b - a:+.2f} |" in text
    assert check.rerun.settled is (slope == 0.0)
    assert ("**not settled** at `graphdeco-7k` (`sh.degree=3` +0.50 dB / 1,000 steps" in text) is (slope > 0)
    # the grid's side is the grid's runs of the same two cells (iterations 100), not the check's
    assert check.grid.protocol == "quick" and check.grid.claim.value == pytest.approx(grid_gain, abs=0.15)
    if grid_gain == 0.5:  # the verdict re-derived from the check's interval (docs/reports.md, "The protocol check")
        expected = ("holds" if claim.low > 0 and claim.value >= 0.1 else
                    "does not hold" if claim.high < 0 or (-0.1 < claim.low and claim.high < 0.1) else "inconclusive")
        assert expected == verdict, (claim.low, claim.value, claim.high)
    if grid_gain == 0.0:  # a no-difference headline: holds only where both intervals rule a difference out
        g = check.grid.claim
        ruled_out = [-0.1 < c.low and c.high < 0.1 for c in (g, claim)]
        assert all(ruled_out) is (verdict == "holds") and (claim.high - claim.low < 0.2) is (noise < 0.05)
        assert ruled_out[0] is (grid_noise < 0.05)  # the grid's seeds at 0.05 dB: its interval reaches past 0.1 dB
        if not ruled_out[0]:
            assert "which neither shows a practical difference nor rules one out" in check.reason
    # rebuilt from the report folder alone, the section is the same
    rebuilt = report_from_table(spec, pd.read_parquet(out / "results.parquet"), len(expand(spec)), table)
    assert rebuilt.check == dataclasses.replace(check, table=rebuilt.check.table)


def test_report_of_part_of_the_check_gives_no_verdict(tmp_path):
    spec = spec_of(SH_GRID)
    grid_results(tmp_path, spec)
    check_results(tmp_path, spec, 0.6, skip=2)
    report = build_report(spec, tmp_path)
    assert report.check.verdict == "incomplete" and report.check.rerun.done == 4
    text = write_report(report, tmp_path / "report").read_text()
    assert "**7K check: incomplete**: 4 of its 6 runs are done; no verdict from part of the seeds." in text
    # its settled column says it was judged on the runs done so far (not the check's word on settling)
    row = next(line for line in text.splitlines() if line.startswith("| `graphdeco-7k` | 4 of 6"))
    assert row.endswith(" (on the 4 of 6 runs done) |"), row


def test_report_command_keeps_the_check_beside_the_report_and_rebuilds_it(tmp_path):
    """`splatbench report` writes check.parquet, refuses to replace it from a results folder that
    lacks the check's runs (a report never shrinks), and --rebuild rewrites the same report from
    the folder's two tables."""
    from splatbench.experiments import load_experiment
    from splatbench.reports.cli import report as report_command

    path = tmp_path / "shfake.toml"
    path.write_text(SH_GRID)
    spec = load_experiment(path)
    full, partial, out = tmp_path / "full", tmp_path / "partial", tmp_path / "out"
    grid_results(full, spec)
    check_results(full, spec, 0.6)
    grid_results(partial, spec)
    run = CliRunner().invoke(report_command, [str(path), "--results", str(full), "--out", str(out)])
    assert run.exit_code == 0, run.output
    assert "shfake: 12 done, 0 failed, 0 not run of 12; 7K check: holds (6 of its 6 runs done)" in run.output
    text = (out / "report.md").read_text()
    run = CliRunner().invoke(report_command, [str(path), "--results", str(partial), "--out", str(out)])
    assert isinstance(run.exception, InputError)  # the command line prints it in one line, exit status 2
    assert f"{out / CHECK_TABLE_NAME}: holds 6 finished runs, the report from {partial / 'shfake'} would hold 0" \
        in str(run.exception)
    assert (out / "report.md").read_text() == text
    run = CliRunner().invoke(report_command, [str(path), "--out", str(out), "--rebuild"])
    assert run.exit_code == 0, run.output
    rebuilt = (out / "report.md").read_text()
    # the rebuilt report names the --out it was rebuilt with (no --results: it read the report folder)
    assert f"shfake.toml --out {out}`: " in rebuilt
    assert rebuilt.replace(f" --out {out}", "") \
        == text.replace(f" --results {full} --out {out}", "").replace(f" --results {full}", "")
    assert "**7K check: holds**: " in rebuilt


def test_rebuild_with_results_adds_the_check_to_a_committed_report(tmp_path):
    """A committed report whose grid's results folder is gone gets its check with `splatbench run
    --check-only` and `splatbench report --rebuild --results DIR`: the grid's table is the report
    folder's own, unchanged (whatever DIR holds of the grid), the check's runs are DIR's; a mixed-commit
    report says so; a check.parquet never shrinks (but with --force); a folder without a finished
    check run, or a file without a [check], is one line."""
    from splatbench.experiments import load_experiment
    from splatbench.reports.cli import report as report_command

    path = tmp_path / "shfake.toml"
    path.write_text(SH_GRID)
    spec = load_experiment(path)
    gone, new, out = tmp_path / "gone", tmp_path / "new", tmp_path / "out"
    grid_results(gone, spec, code="git:aaaaaaaaaaaa")
    run = CliRunner().invoke(report_command, [str(path), "--results", str(gone), "--out", str(out)])
    assert run.exit_code == 0, run.output
    committed = pd.read_parquet(out / "results.parquet")
    before = (out / "report.md").read_text()
    assert "**7K check: not run**" in before and "Code: every run at `git:aaaaaaaaaaaa` (12 runs)." in before
    # the new folder: the check's runs at another commit, and grid runs that differ from the committed ones
    check_results(new, spec, 0.6, code="git:bbbbbbbbbbbb")
    grid_results(new, spec, gain=-1.0, code="git:cccccccccccc")
    run = CliRunner().invoke(report_command, [str(path), "--out", str(out), "--rebuild", "--results", str(new)])
    assert run.exit_code == 0, run.output
    assert (f"shfake: rebuilt from {out / 'results.parquet'}, the check's runs from {new / 'shfake'}: "
            f"7K check: holds (6 of its 6 runs done)") in run.output
    pd.testing.assert_frame_equal(pd.read_parquet(out / "results.parquet"), committed)
    assert list(pd.read_parquet(out / CHECK_TABLE_NAME).run_id) == [r.run_id for r in check_runs(spec)]
    text = (out / "report.md").read_text()
    report = report_from_table(spec, committed, len(expand(spec)))
    for axis in report.axes:  # the grid's tables and findings: the committed runs', not the new folder's
        assert axis.markdown() in text and report.findings[axis.axis].markdown() in text
    assert "**7K check: holds**" in text
    assert ("Code: the runs ran at more than one commit: the grid's runs at `git:aaaaaaaaaaaa` (12 runs); the "
            "check's runs at `git:bbbbbbbbbbbb` (6 runs); a difference between runs at different commits is also a "
            "difference of code") in text
    assert "git:cccccccccccc" not in text
    # the command that made it: the grid's runs from the report folder, the check's from --results
    assert f"Generated by `splatbench report {path} --rebuild --results {new} --out {out}`: 12 runs" in text
    # the check's section names the run command as a report made from one results folder does
    assert f"`splatbench run {path}` runs it after the grid's runs" in text
    after = text

    # never fewer finished check runs than check.parquet holds; --force replaces it anyway
    partial, empty = tmp_path / "partial", tmp_path / "empty"
    check_results(partial, spec, 0.6, skip=2)
    run = CliRunner().invoke(report_command, [str(path), "--out", str(out), "--rebuild", "--results", str(partial)])
    assert isinstance(run.exception, InputError)
    message = str(run.exception)
    assert message == (f"{out / CHECK_TABLE_NAME}: holds 6 finished runs, the check's runs in {partial / 'shfake'} "
                       f"would give 4; run the rest with `splatbench run {path} --check-only --results {partial}`, "
                       f"or pass --force to replace it")
    assert (out / "report.md").read_text() == after and len(pd.read_parquet(out / CHECK_TABLE_NAME)) == 6
    run = CliRunner().invoke(report_command, [str(path), "--out", str(out), "--rebuild", "--results", str(empty)])
    assert isinstance(run.exception, InputError) and "\n" not in str(run.exception)
    assert str(run.exception) == (f"--rebuild --results: no finished run of the check's 6 in {empty / 'shfake'}; "
                                  f"run `splatbench run {path} --check-only --results {empty}` first")
    run = CliRunner().invoke(report_command, [str(path), "--out", str(out), "--rebuild", "--results", str(partial),
                                              "--force"])
    assert run.exit_code == 0, run.output
    assert "7K check: incomplete (4 of its 6 runs done)" in run.output
    assert len(pd.read_parquet(out / CHECK_TABLE_NAME)) == 4
    pd.testing.assert_frame_equal(pd.read_parquet(out / "results.parquet"), committed)
    # a plain --rebuild afterwards reads the check back from check.parquet: the same report
    again = (out / "report.md").read_text()
    run = CliRunner().invoke(report_command, [str(path), "--out", str(out), "--rebuild"])
    assert run.exit_code == 0, run.output
    assert (out / "report.md").read_text().replace(f" --out {out}", "") == \
        again.replace(f" --rebuild --results {partial}", "").replace(f" --out {out}", "")

    # a file without a [check]: --results has nothing to be read for with --rebuild
    plain = tmp_path / "plain.toml"
    plain.write_text(SH_GRID.split("[check]")[0])
    run = CliRunner().invoke(report_command, [str(plain), "--out", str(out), "--rebuild", "--results", str(new)])
    assert isinstance(run.exception, InputError) and "\n" not in str(run.exception)
    assert str(run.exception).startswith(f"--rebuild --results: {plain} has no [check]")


def _sh_check_report(tmp_path, more):
    """SH_GRID's grid and check results, the check's SH 3 runs 0.6 dB above SH 0's (seeded noise), each
    check record's metrics updated with ``more(run, three)``; (the report, its text)."""
    spec = spec_of(SH_GRID)
    root = tmp_path / "results"
    grid_results(root, spec)
    rng = np.random.default_rng(1)
    for run in check_runs(spec):
        three = run.labels["sh.degree"] == 3
        rec = record(spec, run, 28.0 + (0.6 if three else 0.0) + rng.normal(0, 0.05))
        write_record(root, dataclasses.replace(rec, metrics={**rec.metrics, **more(run, three)}))
    report = build_report(spec, root)
    return report, write_report(report, tmp_path / "report").read_text()


def test_a_check_whose_ssim_goes_the_other_way_says_so_in_its_headline(tmp_path):
    """Issue 39: sh_degree's 7K check held in PSNR while its SSIM reversed; the verdict's sentence and
    the header's line say so."""
    report, text = _sh_check_report(tmp_path, lambda run, three: {
        "test_ssim": 0.9 - (0.01 + 0.001 * run.seed if three else 0.0)})
    assert report.check.verdict == "holds" and report.check.rerun.opposed[0][0] == "SSIM"
    assert "**7K check: holds**, **but SSIM goes the other way, significantly there** (SSIM -0.0110 [95 % CI" in text
    assert "; **but SSIM goes the other way, significantly** at `graphdeco-7k`: SSIM -0.0110" in text


@pytest.mark.parametrize("sh_recorded", [False, True])
def test_a_check_whose_cells_differ_in_model_size_says_so_in_its_verdict(tmp_path, sh_recorded):
    """The findings' model-size rule (`findings.size_shift`) inside the check's verdict: SH 3 ending with
    1.5 x the Gaussians of SH 0 at 7K; where the runs record their SH degree, bytes per Gaussian differ
    (14 floats at degree 0, 59 at 3) and the size is judged in bytes, naming the Gaussians' ratio beside."""
    report, text = _sh_check_report(tmp_path, lambda run, three: {
        "num_gaussians": 1500 if three else 1000, **({"sh_degree": 3 if three else 0} if sh_recorded else {})})
    assert report.check.verdict == "holds"
    size = (f"×{1.5 * 59 / 14:.3f} the bytes (×1.500 the Gaussians) (≥ 10 % larger" if sh_recorded else
            "×1.500 the Gaussians (≥ 10 % more")
    assert report.check.rerun.size == size and report.check.grid.size == ""  # the grid's cells: 1,000 each
    assert (f"; **against model size**: `sh.degree=3` ends at {size}) at `graphdeco-7k` against `sh.degree=0`; "
            f"the check has no matched-size cell: quality and size are not separated") in text


def test_a_check_run_with_a_test_view_far_below_its_other_seeds_is_named_under_the_per_seed_table(tmp_path):
    # guitar seed 1 at graphdeco-7k (docs/history/2026-12-07-divergent-seed.md): one view 18 dB below the same view
    # in the other seeds; the check's runs are compared among themselves, cell by cell
    spec = spec_of(SH_GRID)
    root = tmp_path / "results"
    grid_results(root, spec)
    check_results(root, spec, 0.6)
    records = read_records(root / spec.name)
    for run in check_runs(spec):
        views = [40.0 + v + 0.1 * run.seed for v in range(4)]
        if run.seed == 1 and run.labels["sh.degree"] == 3:
            views[2] -= 18.0
        rec = records[run.run_id]
        write_record(root, dataclasses.replace(rec, curves={**rec.curves, "test_view_psnr": views}))
    text = write_report(build_report(spec, root), tmp_path / "report").read_text()
    section = text[text.index("## Headline at the 7K protocol"):]
    lines = section.splitlines()
    flagged = [i for i, line in enumerate(lines) if line.startswith("- **Outlier test view**")]
    assert len(flagged) == 1 and lines[flagged[0]].startswith(
        "- **Outlier test view**: glossy, `sh.degree=3`, seed 1 (`"), lines
    assert "test view 2 at 24.10 dB, 18.0 dB below the same view in the cell's other seeds (their median 42.10 dB)" \
        in lines[flagged[0]]
    assert lines[flagged[0] + 1].endswith("6 runs checked, 1 flagged.")
    # under the per-seed table, in the appendix after the verdict; the section's body says one run was flagged
    verdict = next(i for i, line in enumerate(lines) if line.startswith("**7K check: "))
    assert verdict < lines.index("## Appendix: The check in full") < lines.index(
        "Each seed's test PSNR (dB), both cells (a seed that went its own way shows here, not in the means above):") \
        < flagged[0]
    assert ("Each cell's other metrics, each seed's test PSNR and the check's runs' outlier test views (**a run flagged "
            "with an outlier test view**): \"Appendix: The check in full\".") in lines[:verdict]
