"""tools/backfill_view_psnr.py: a run finished before runs recorded each test view's PSNR gets
them from its saved final model, evaluated again as the run's final evaluation did
(`splatbench.train.reevaluate`), checked against its recorded test PSNR; a record that
disagrees is refused and left as it is; a run a runner holds is never touched. And
tools/lpips_scale.py measures that run's own renders.

The run: a few steps on the `diffuse` scene at 32² rendered by Mitsuba (as tests/test_train.py),
recorded as the experiment runner records it, then stripped of its per-view fields.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from splatbench.experiments.kinds import metric_values
from splatbench.experiments.store import RunRecord, read_record, read_table, write_record, write_table
from splatbench.experiments.train_kind import TrainRun
from splatbench.train import TrainConfig, train
from splatbench.train.config import SHConfig, StrategyConfig

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("backfill_view_psnr", ROOT / "tools" / "backfill_view_psnr.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """(results folder, the run's record as the runner wrote it): a 40-step run ending at SH degree 1 of
    its 3 (one band every 20 steps), recorded with its per-view PSNRs."""
    from splatbench.scenes.render import render_dataset

    root = tmp_path_factory.mktemp("backfill")
    data = root / "diffuse-32"
    render_dataset("diffuse", data, resolution=32, views=16, spp=4, progress=False)  # 2 test views
    work = root / "res" / "exp" / "work" / "0123456789abcdef"
    cfg = TrainConfig(dataset=str(data), out=str(work), iterations=40, log_every=10, schedule="absolute",
                      sh=SHConfig(degree=3, interval=20), strategy=StrategyConfig(name="none"),
                      init=dataclasses.replace(TrainConfig().init, method="random", random_points=300))
    result = train(cfg)
    # the model ends below the config's degree (its SH truncated in the PLY): the evaluation must render at 1
    assert result.sh_degree == 1 and len(result.test_view_psnr) == 2
    run = TrainRun.of(result, None)
    rec = RunRecord(run_id="0123456789abcdef", experiment="exp", kind="train", scene="diffuse", seed=0, status="done",
                    config={}, labels={"sh.degree": 3}, metrics=metric_values(run), curves=run.curves)
    write_record(root / "res", rec)
    write_table(root / "res" / "exp", [rec])
    return root / "res", rec


def stripped(rec: RunRecord) -> RunRecord:
    """The record as a run finished before e5194ed wrote it."""
    return dataclasses.replace(rec, curves={k: v for k, v in rec.curves.items() if k != "test_view_psnr"},
                               metrics={k: v for k, v in rec.metrics.items() if k != "worst_view_psnr"})


def test_backfill_restores_the_runs_own_per_view_psnrs(finished, capsys):
    results, original = finished
    tool = _tool()
    write_record(results, stripped(original))
    assert tool.main([str(results), "exp", "--dry-run"]) == 0
    assert read_record(results / "exp" / "0123456789abcdef.json") == stripped(original)  # a dry run writes nothing
    assert tool.main([str(results), "exp"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert any(line.startswith("0123456789abcdef diffuse {'sh.degree': 3} seed 0: ") for line in out), out
    back = read_record(results / "exp" / "0123456789abcdef.json")
    # the same numbers the run recorded (re-evaluated bit for bit on the machine that trained it), and where they
    # came from
    assert back.curves["test_view_psnr"] == original.curves["test_view_psnr"]
    assert back.metrics["worst_view_psnr"] == original.metrics["worst_view_psnr"]
    assert back.curves["test_view_psnr_from"] == tool.FROM
    assert {k: v for k, v in back.curves.items() if k != "test_view_psnr_from"} == original.curves
    # the table rewritten from the record
    table = read_table(results / "exp")
    assert json.loads(table.curves[0])["test_view_psnr"] == original.curves["test_view_psnr"]
    assert table["metric.worst_view_psnr"][0] == original.metrics["worst_view_psnr"]
    # a second pass finds nothing to do
    assert tool.main([str(results), "exp"]) == 0
    assert "1 records, 0 done without per-view PSNRs" in capsys.readouterr().out


def test_a_record_the_model_disagrees_with_is_refused_and_a_held_run_left_alone(finished, capsys):
    results, original = finished
    tool = _tool()
    # a record whose test PSNR is 0.01 dB off what its model gives: far beyond float32 noise (1e-4 dB at 30 dB)
    wrong = stripped(original)
    wrong = dataclasses.replace(wrong, metrics={**wrong.metrics, "test_psnr": wrong.metrics["test_psnr"] + 0.01})
    from splatbench.train.reevaluate import tolerance_db

    assert tolerance_db(original.curves["test_view_psnr"]) < 1e-3
    write_record(results, wrong)
    assert tool.main([str(results), "exp"]) == 1
    lines = capsys.readouterr().out.splitlines()
    error = next(line for line in lines if line.startswith("error: "))
    assert error.startswith("error: 0123456789abcdef: the saved model evaluates to ") and error.endswith("; refused")
    assert read_record(results / "exp" / "0123456789abcdef.json") == wrong
    # a run a runner holds: never touched
    claims = results / "exp" / "claims"
    claims.mkdir(exist_ok=True)
    (claims / "0123456789abcdef.claim").write_text("held")
    write_record(results, stripped(original))
    try:
        assert tool.main([str(results), "exp"]) == 0
        assert "0123456789abcdef: held by a runner (claims/0123456789abcdef.claim); left alone" in capsys.readouterr().out
        assert read_record(results / "exp" / "0123456789abcdef.json") == stripped(original)
    finally:
        (claims / "0123456789abcdef.claim").unlink()


def test_the_lpips_scale_tool_measures_the_runs_own_renders(finished):
    """tools/lpips_scale.py's measurement of the same saved run (`evaluate_saved_run` with both LPIPS
    conventions): each test view's AlexNet LPIPS averages to the run's recorded test_lpips bit for bit (the
    same renders, on the machine that trained it), and VGG's is there for each view."""
    results, original = finished
    spec = importlib.util.spec_from_file_location("lpips_scale", ROOT / "tools" / "lpips_scale.py")
    tool = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = tool
    spec.loader.exec_module(tool)
    write_record(results, original)
    runs, skipped = tool.measure(results, "exp")
    assert skipped == [] and len(runs) == 1
    run = runs[0]
    assert original.metrics["lpips_net"] == "alex" and original.metrics["lpips_scale_inputs"] == 1
    assert float(np.mean(run.alex)) == original.metrics["test_lpips"]
    assert run.psnr == original.metrics["test_psnr"]
    assert len(run.vgg) == len(run.alex) == 2 and all(v > 0 for v in run.vgg)
