"""`splatbench bench raster`: the harness runs end to end and rejects bad input in one line.

Timings are not checked (the machine is shared); only that the harness measures
something sane and writes the documented columns.
"""

from __future__ import annotations

import csv
import json
from dataclasses import fields, replace

import pytest
from click.testing import CliRunner

from splatbench.metrics.machine import MachineInfo
from splatbench.bench.raster import (CSV_COLUMNS, STANDARD_SYNTHETIC, RasterBenchResult, format_table, leak_warnings,
                                     standard_suite, target_of)
from splatbench.metrics.timing import StageSplit
from splatbench.cli import main
from splatbench.errors import InputError
from splatbench.workloads import GARDEN_SFM, parse_synthetic, parse_workload, workload_spec

TINY = ["bench", "raster", "--synthetic", "200", "64x64", "--repeats", "1", "--device", "cpu"]


def test_bench_raster_tiny_workload_writes_documented_csv_and_json(tmp_path):
    result = CliRunner().invoke(main, [*TINY, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "synthetic-200-64x64-s0" in result.stdout  # the table

    with open(tmp_path / "raster.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames) == CSV_COLUMNS
        rows = list(reader)
    assert len(rows) == 1
    row = rows[0]
    assert (int(row["n"]), int(row["width"]), int(row["height"])) == (200, 64, 64)
    assert row["device"] == "cpu" and int(row["tile_size"]) == 16 and int(row["repeats"]) == 1
    for key in ("fwd_ms", "fwd_bwd_ms", "preprocess_ms", "binning_ms", "compositing_ms",
                "backward_compositing_ms", "backward_preprocess_ms", "total_ms", "mevals_per_s",
                "base_rss_mb", "setup_rss_mb", "peak_rss_mb", "first_run_peak_rss_mb"):
        assert float(row[key]) > 0, key
    pairs, visible = int(row["pairs"]), int(row["visible"])
    assert pairs > 0 and 0 < visible <= 200
    assert 0 < int(row["evaluations"]) <= pairs * 16 ** 2  # lanes walk lists no longer than their tile's
    # the work counts (splatbench.raster.work_stats) are ordered, and the peak was measured
    useful, inside = int(row["useful_evaluations"]), int(row["inside_cutoff_evaluations"])
    assert 0 < useful <= inside <= int(row["block_evaluations"]) <= int(row["evaluations"])
    assert int(row["cutoff_box_pairs"]) >= int(row["box_pairs"]) >= pairs  # culled in two steps
    assert int(row["cutoff_evaluations"]) == int(row["cutoff_box_pairs"]) * 16 ** 2 >= int(row["evaluations"])
    assert float(row["binning_ms"]) == pytest.approx(float(row["binning_cull_ms"]) + float(row["binning_sort_ms"]),
                                                     abs=2e-3)  # medians of sums vs sums of medians: 1 run here
    assert float(row["first_run_peak_rss_mb"]) >= float(row["setup_rss_mb"])  # the whole process so far
    assert float(row["useful_share"]) == pytest.approx(useful / int(row["evaluations"]), abs=1e-4)  # 4 places
    assert float(row["peak_gflops"]) > 0 and 0 < float(row["share_of_peak"])
    assert row["target_fwd_bwd_ms"] == row["meets_target"] == ""  # not a standard workload

    report = json.loads((tmp_path / "raster.json").read_text())
    assert set(report["machine"]) == {f.name for f in fields(MachineInfo)}
    assert report["machine"]["cpu_count"] >= 1 and report["machine"]["device"] == "cpu"
    assert report["settings"] == {"repeats": 1, "device": "cpu", "options": {}}
    (typed,) = [RasterBenchResult.from_dict(r) for r in report["results"]]
    assert typed.pairs == pairs and len(typed.fwd_runs_ms) == len(typed.fwd_bwd_runs_ms) == 1
    assert isinstance(typed.stages, StageSplit) and typed.stages.total_ms > 0


@pytest.mark.parametrize("args, message", [
    (["--synthetic", "10", "12"], "--synthetic: expected WxH, got '12'"),
    (["--synthetic", "ten", "8x8"], "--synthetic: expected a Gaussian count, got 'ten'"),
    (["--synthetic", "0", "8x8"], "--synthetic: expected a Gaussian count >= 1, got '0'"),
    (["--workload", "no/such/scene.npz"], "--workload: no such file 'no/such/scene.npz'"),
    (["--synthetic", "10", "8x8", "--repeats", "0"], "--repeats: expected a count >= 1, got 0"),
    (["--synthetic", "10", "8x8", "--option", "tile_size=3"], "tile_size: expected a power of two"),
    (["--synthetic", "10", "8x8", "--option", "device=cpu"], "--option device: use --device instead"),
    (["--synthetic", "10", "8x8", "--device", "tpu"], "device: expected 'auto', 'cpu' or 'cuda', got 'tpu'"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["bench", "raster", *args, "--out", str(out)])
    assert result.exit_code == 2
    (line,) = result.output.strip().splitlines()
    assert line.startswith("splatbench: error: ") and message in line, result.output
    assert not out.exists()


def test_bad_npz_reported_from_the_subprocess_in_one_line(tmp_path):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"not an npz")
    result = CliRunner().invoke(main, ["bench", "raster", "--workload", str(bad), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    errors = [line for line in result.output.splitlines() if line.startswith("splatbench: error:")]
    assert len(errors) == 1 and "broken.npz: not a readable npz" in errors[0], result.output
    assert "Traceback" not in result.output


def test_targets_attach_to_the_standard_synthetic_workloads_only():
    suite = standard_suite(seed=3)
    assert [(s.n, s.width, s.height) for s in suite[:-1]] == list(STANDARD_SYNTHETIC)
    assert [target_of(s).fwd_bwd_ms for s in suite[:-1]] == [35.0, 450.0, 2000.0]
    assert target_of(suite[-2]).peak_rss_mb == 1500.0 and target_of(suite[0]).peak_rss_mb is None
    assert suite[-1].label == "garden-view0" and target_of(suite[-1]) is None
    assert target_of(parse_synthetic("10000", "256X256", seed=9)).fwd_bwd_ms == 35.0
    assert target_of(parse_synthetic("10001", "256x256")) is None


def test_the_command_line_and_experiment_scene_names_give_one_typed_spec():
    assert workload_spec("synthetic-20000-256", 4) == parse_synthetic("20000", "256x256", seed=4)
    assert workload_spec("synthetic-20000-320x200", 4) == parse_synthetic("20000", "320x200", seed=4)
    garden, flag = workload_spec("garden", 4), parse_workload("garden")
    assert (garden.kind, garden.path, garden.view) == (flag.kind, flag.path, flag.view) == ("npz", str(GARDEN_SFM), 0)
    assert workload_spec("garden-v2", 0).view == 2
    with pytest.raises(InputError, match="scene: unknown workload 'gardn'"):
        workload_spec("gardn", 0)


def test_table_marks_met_and_missed_targets():
    stages = StageSplit(1.0, 2.0, 3.0, 4.0, 5.0, 0.5, 15.5, binning_cull_ms=1.5, binning_sort_ms=0.5)
    base = RasterBenchResult(
        name="synthetic-10000-256x256-s0", n=10_000, width=256, height=256, sh_degree=3, device="cpu",
        tile_size=16, pixel_block=4, repeats=5, fwd_ms=10.0, fwd_bwd_ms=30.0, stages=stages, pairs=1000, visible=900,
        evaluations=256_000, mevals_per_s=85.3, box_pairs=1200, block_evaluations=120_000,
        inside_cutoff_evaluations=70_000, useful_evaluations=64_000, useful_share=0.25, cutoff_box_pairs=2000,
        cutoff_evaluations=512_000, cutoff_useful_share=0.125, peak_gflops=80.0,
        share_of_peak=0.048, base_rss_mb=350.0, setup_rss_mb=360.0, peak_rss_mb=400.0,
        first_run_peak_rss_mb=380.0,
        rss_reset=True, retained_mb_per_run=0.0, target_fwd_bwd_ms=35.0, target_peak_rss_mb=None, meets_target=True)
    lines = format_table([base, replace(base, name="slow", fwd_bwd_ms=50.0, meets_target=False),
                          replace(base, name="other", target_fwd_bwd_ms=None, meets_target=None)]).splitlines()
    assert len(lines) == 5  # header, rule, three rows
    assert lines[2].endswith("35 ms  yes") and lines[3].endswith("35 ms   NO") and lines[4].endswith("-    -")
    assert "1.0/2.0(1.5+0.5)/3.0/4.0/5.0/0.5" in lines[2]  # binning as cull + sort
    assert "2,000/1,200/1,000" in lines[2]  # pairs of the cutoff boxes, the support boxes, kept
    # Mevals without culling/performed/useful (useful share), % of peak
    assert "0.5/0.3/0.1 (25.0 %)" in lines[2] and "4.8 % of 80.0 GFLOP/s" in lines[2]
    assert leak_warnings([base]) == []
    (warning,) = leak_warnings([base, replace(base, name="leaky", retained_mb_per_run=40.0)])
    assert warning.startswith("warning: leaky: RSS grew 40.0 MB per run")


def test_option_and_set_share_one_key_value_grammar():
    """`render --option`, `bench raster --option` and `train --set` parse values the same way."""
    from splatbench.overrides import parse_override, parse_overrides

    pairs = ("tile_size=8", "alpha_min=1e-3", "antialiased=true", "radius=opacity", "background=[0, 0, 1]")
    assert parse_overrides(pairs, "--option") == dict(parse_override(p) for p in pairs) == {
        "tile_size": 8, "alpha_min": 1e-3, "antialiased": True, "radius": "opacity", "background": [0, 0, 1]}
    with pytest.raises(InputError, match=r"^--option: expected key=value, got 'tile_size'$"):
        parse_overrides(("tile_size",), "--option")
