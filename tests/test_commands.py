"""The `demo`, `render`, `report` and `bench train` commands end to end (small and fast)."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from PIL import Image

from splatbench.cli import main
from splatbench.gaussians import SH_C0, Gaussians


def invoke(*args) -> tuple[int, str]:
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.output


def test_render_a_ply_frames_its_gaussian(tmp_path):
    """One red Gaussian: the framing camera puts it in the middle of a WxH PNG on black;
    a PLY that records no up is framed y-down (COLMAP's world) and the command says so."""
    red = np.array([[[0.9, 0.05, 0.05]]])
    g = Gaussians(means=np.array([[1.0, 2.0, 3.0]]), log_scales=np.full((1, 3), -1.0),
                  quats=np.array([[1.0, 0, 0, 0]]), opacity_logits=np.array([4.0]), sh=(red - 0.5) / SH_C0)
    g.to_ply(tmp_path / "one.ply")
    code, out = invoke("render", tmp_path / "one.ply", "--size", "40x30", "--out", tmp_path / "one.png")
    assert code == 0, out
    assert out.strip().splitlines() == [
        "note: up -y (COLMAP's y-down world; the PLY records none: pass --up +y if the picture is upside down)",
        f"rendered 1 Gaussians at 40x30: {(tmp_path / 'one.png').resolve()}"]
    img = np.asarray(Image.open(tmp_path / "one.png").convert("RGB"))
    assert img.shape == (30, 40, 3)
    centre, corner = img[15, 20].astype(int), img[0, 0].astype(int)
    assert centre[0] > 100 and centre[0] > 4 * max(centre[1], centre[2], 1)  # red where the Gaussian is
    assert corner.max() == 0                                                 # black background far from it
    code, out = invoke("render", tmp_path / "one.ply", "--sh-degree", "4")
    assert code == 2 and out.strip() == "splatbench: error: --sh-degree: expected an int in 0..3, got 4"


def test_report_of_a_finished_dummy_grid(tmp_path):
    exp = tmp_path / "sweep.toml"
    exp.write_text('name = "sweep"\nkind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha"]\nseeds = [0, 1]\n[axes]\nx = [0.0, 2.0]\n')
    code, out = invoke("run", exp, "--results", tmp_path / "results", "--workers", "1", "--no-progress")
    assert code == 0, out
    code, out = invoke("report", exp, "--results", tmp_path / "results", "--out", tmp_path / "report")
    assert code == 0, out
    lines = out.strip().splitlines()
    assert lines == ["sweep: 4 done, 0 failed, 0 not run of 4", str(tmp_path / "report" / "report.md")]
    text = (tmp_path / "report" / "report.md").read_text()
    assert "sweep" in text and (tmp_path / "report" / "results.parquet").is_file()


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_report_never_replaces_a_report_with_fewer_finished_runs(tmp_path):
    """No finished run: one line, exit 2, nothing written. A results folder with fewer finished
    runs than the report folder's results.parquet: refused the same way, naming --force, the
    folder byte-identical; --force replaces it."""
    exp = tmp_path / "sweep.toml"
    exp.write_text('name = "sweep"\nkind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha"]\nseeds = [0, 1]\n[axes]\nx = [0.0, 2.0]\n')
    results, report = tmp_path / "results", tmp_path / "report"
    code, out = invoke("report", exp, "--results", results, "--out", report)
    assert code == 2 and out.strip() == (f"splatbench: error: sweep: no finished run of the 4 in {results / 'sweep'}; "
                                         f"run `splatbench run {exp} --results {results}` first")
    assert not report.exists()

    assert invoke("run", exp, "--results", results, "--workers", "1", "--no-progress")[0] == 0
    assert invoke("report", exp, "--results", results, "--out", report)[0] == 0
    before = _snapshot(report)
    assert {"report.md", "results.parquet"} <= set(before)

    runs = sorted((results / "sweep").glob("*.json"))
    assert len(runs) == 4
    for path in runs[1:]:
        path.unlink()
    code, out = invoke("report", exp, "--results", results, "--out", report)
    assert code == 2 and out.strip() == (
        f"splatbench: error: {report / 'results.parquet'}: holds 4 finished runs, the report from "
        f"{results / 'sweep'} would hold 1; run the rest with `splatbench run {exp} --results {results}`, or pass --force to replace it")
    assert _snapshot(report) == before
    runs[0].unlink()
    code, out = invoke("report", exp, "--results", results, "--out", report, "--force")
    assert code == 2 and "no finished run of the 4" in out  # --force never writes an empty report
    assert _snapshot(report) == before

    assert invoke("run", exp, "--results", results, "--workers", "1", "--no-progress")[0] == 0
    runs[-1].unlink()
    code, out = invoke("report", exp, "--results", results, "--out", report, "--force")
    assert code == 0, out
    assert out.strip().splitlines()[0] == "sweep: 3 done, 0 failed, 1 not run of 4"
    assert _snapshot(report)["results.parquet"] != before["results.parquet"]
    assert len(pd.read_parquet(report / "results.parquet")) == 3


def test_bench_train_writes_one_row_per_size(tmp_path):
    code, out = invoke("bench", "train", "--size", "16", "--gaussians", "64", "--iterations", "2", "--warmup", "1",
                       "--device", "cpu", "--out", tmp_path)
    assert code == 0, out
    rows = list(csv.DictReader((tmp_path / "train.csv").open()))
    assert [(r["width"], r["height"], r["n"], r["iterations"], r["device"]) for r in rows] == [
        ("16", "16", "64", "2", "cpu")]
    row = rows[0]
    assert float(row["it_per_s"]) > 0
    # the step's parts are shares of the timed steps: they add up to 100 % up to per-part rounding (0.05 each)
    parts = ("raster_forward", "raster_backward", "loss", "optimizer", "other")
    assert sum(float(row[f"{p}_pct"]) for p in parts) == pytest.approx(100.0, abs=0.05 * len(parts))
    data = json.loads((tmp_path / "train.json").read_text())
    assert isinstance(data, dict) and out.rstrip().endswith(f"wrote {Path(tmp_path) / 'train.csv'} and "
                                                            f"{Path(tmp_path) / 'train.json'}")


def test_demo_checks_garden_runs_the_grid_and_writes_its_report(tmp_path):
    """`splatbench demo` pointed at a tiny grid (the dummy kind) and a 1/20-scale reference check:
    every step prints its line, writes its files, and a second invocation resumes (runs nothing)."""
    exp = tmp_path / "tiny.toml"
    exp.write_text('name = "tinydemo"\nkind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha"]\nseeds = [0]\n[axes]\nx = [0.0, 2.0]\n')
    common = ["--experiment", exp, "--results", tmp_path / "results", "--report-dir", tmp_path / "report",
              "--workers", "1"]
    code, out = invoke("demo", *common, "--out", tmp_path / "out", "--scale", "0.05")
    assert code == 0, out
    lines = out.strip().splitlines()
    # 1. the garden check: the full capture at full size, the reference at 1/20 (32x21)
    assert lines[0].startswith("Dr.Jit rasterizer: 138766 Gaussians at 648x420 in ")
    assert lines[1].startswith("reference check at 32x21: max |fast - reference| = ")
    assert np.isfinite(float(lines[1].split("= ")[1].split()[0]))
    # the max covers the boundary band too; the line says how many pixels exceed the per-pixel
    # tolerance and how many of them lie outside the band the oracle derives (none may), and
    # the check itself holds: garden at 1/20 is within parity (tests/test_raster_parity.py's rule)
    m = re.search(r"over all pixels; (\d+) of 672 above the 2e-05 parity tolerance, (\d+) of them outside the "
                  r"boundary band of (\d+) pixels where float32 may take a discrete decision differently "
                  r"\(allowed: 0\) \(image: ", lines[1])
    assert m and int(m.group(2)) == 0 and int(m.group(1)) <= int(m.group(3)), lines[1]
    assert Image.open(tmp_path / "out" / "garden.png").size == (648, 420)
    assert f"the difference, on a colour scale: {tmp_path / 'out' / 'garden_difference.png'})" in lines[1]
    width, height = Image.open(tmp_path / "out" / "garden_difference.png").size  # a figure with its colour bar
    assert width > height > 21
    # 2. the grid ran, 3. its report was written and its path is the last line
    assert "tinydemo: done 2, skipped 0 (finished), 0 claimed by another runner, failed 0 of 2 in " in out
    report = tmp_path / "report" / "report.md"
    assert lines[-1] == f"report: {report.resolve()}"
    assert "| alpha | `2` |" in report.read_text() and (tmp_path / "report" / "results.parquet").is_file()
    # resumable: nothing left to run
    code, out = invoke("demo", *common, "--no-garden")
    assert code == 0, out
    assert "tinydemo: done 0, skipped 2 (finished)" in out and "Dr.Jit rasterizer" not in out


def test_demo_report_goes_under_out_by_default(tmp_path, monkeypatch):
    """Without --report-dir the report lands in out/<name>/report, never in the committed reports/
    (a fresh clone stays clean after `make demo`)."""
    exp = tmp_path / "tiny.toml"
    exp.write_text('name = "tinydemo"\nkind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha"]\nseeds = [0]\n[axes]\nx = [0.0]\n')
    monkeypatch.chdir(tmp_path)
    code, out = invoke("demo", "--experiment", exp, "--results", "results", "--workers", "1", "--no-garden")
    assert code == 0, out
    report = tmp_path / "out" / "tinydemo" / "report" / "report.md"
    assert out.strip().splitlines()[-1] == f"report: {report.resolve()}" and report.is_file()
    assert not (tmp_path / "reports").exists()
