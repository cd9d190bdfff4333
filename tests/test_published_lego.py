"""tools/published_lego.py (issue 29 item 7): the paper's settings as a config, graphdeco's
NeRF-synthetic initialisation, and the report written from a run's result -- here a
synthetic result (no training), so every number in the report can be checked against it."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from splatbench.train import TrainResult
from splatbench.train.initializers import InitSettings
from splatbench.train.result import EvalPoint, StepEvaluation

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("published_lego", ROOT / "tools" / "published_lego.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["published_lego"] = mod
    spec.loader.exec_module(mod)
    return mod


def fake_result(psnr_30k: float, *, iterations: int = 30_000) -> TrainResult:
    steps = [s for s in (7000, 30_000) if s <= iterations] or [iterations]
    early = {s: 1e-3 * (s == 7000) for s in steps}  # the 7K column's LPIPS is 0.001 higher
    cols = [StepEvaluation(s, psnr_30k - (2.5 if s == 7000 else 0.0), 0.95 + s * 1e-7, "vgg", 0.061 + early[s],
                           0.052 + early[s], 150_000 + s * 5, 3.6 * s, 200) for s in steps]
    last = cols[-1]
    return TrainResult(
        test_psnr=last.psnr, test_ssim=last.ssim, test_lpips=last.lpips_unscaled, num_gaussians=last.num_gaussians,
        train_seconds=cols[-1].train_seconds, iterations=iterations, sh_degree=3, sh_degree_reason="fixed",
        ply_path="/somewhere/run/point_cloud.ply", render_ms_per_view=812.0, peak_rss_mb=2400.0, strategy="default",
        scene_extent=4.4, test_views=200,
        evaluations=[EvalPoint(2500, 30.1, 0.9, 0.08), EvalPoint(7000, cols[0].psnr, cols[0].ssim, 0.05)],
        notes=["background [1.0, 1.0, 1.0] (config)"], init={"method": "paper-cube", "points": 100_000,
                                                            "region": [-1.3, 1.3]},
        load={"load_before": 0.1, "load_after": 0.2, "load_other": 0.0, "cores": 2, "loaded": False},
        lpips_net="vgg", lpips_scale_inputs=False, protocol="graphdeco-30k", step_evaluations=cols)


def test_paper_config_is_graphdecos_30k_protocol_on_white(tool, tmp_path):
    cfg = tool.paper_config(tmp_path / "lego", tmp_path / "run")
    assert (cfg.protocol, cfg.iterations, cfg.schedule_length, cfg.evaluation_steps) == \
        ("graphdeco-30k", 30_000, 30_000, [7000, 30_000])
    assert cfg.background == [1.0, 1.0, 1.0] and cfg.init == "paper-cube" and cfg.init_random_points == 100_000
    assert (cfg.lpips_net, cfg.lpips_scale_inputs, cfg.layout) == ("vgg", False, "blender")
    smoke = tool.paper_config(tmp_path / "lego", tmp_path / "run", tool.SMOKE)
    assert (smoke.iterations, smoke.evaluation_steps, smoke.downscale) == (300, [100, 300], 4)


def test_paper_cube_is_graphdecos_nerf_synthetic_initialisation(tool):
    from splatbench.train.initializers import INITIALIZERS

    made = INITIALIZERS["paper-cube"](None, InitSettings(sh_degree=3, opacity=0.1, random_points=5000, seed=3))
    g = made.gaussians
    assert len(g) == 5000 and made.summary["region"] == [-1.3, 1.3]
    assert np.abs(g.means).max() <= 1.3 and np.abs(g.means).max() > 1.29  # fills the cube
    colour = 0.5 + 0.28209479177387814 * g.sh[:, 0]
    assert colour.min() >= 0.5 and colour.max() <= 0.5 + 0.2821 / 255  # SH2RGB(U[0, 1) / 255): grey
    assert np.allclose(1 / (1 + np.exp(-g.opacity_logits)), 0.1)


def test_report_puts_the_paper_beside_the_run_and_says_whether_it_is_within_half_a_db(tool, tmp_path):
    (tmp_path / "lego").mkdir()
    (tmp_path / "lego" / "transforms_train.json").write_text(json.dumps({"frames": [{}] * 100}))
    cfg = tool.paper_config(tmp_path / "lego", tmp_path / "run")
    path = tool.write_report(fake_result(35.41), cfg, tmp_path / "report",
                             command="python tools/published_lego.py LEGO")
    text = path.read_text()
    assert "Not the paper's protocol" not in text
    assert "`graphdeco-30k`" in text and "100 views" in text and "200 views" in text
    assert "evaluated after 7,000 and 30,000 steps of one run" in text
    assert "| test PSNR (dB) | 35.78 (30K) | 32.91 | 35.41 |" in text
    assert "| difference to the paper (dB) |  |  | -0.37 |" in text
    assert "| LPIPS, [0, 1] unscaled (graphdeco) | not per scene | 0.0530 | 0.0520 |" in text
    assert "| LPIPS, [-1, 1] (lpips package) |  | 0.0620 | 0.0610 |" in text
    assert "| Gaussians |  | 185,000 | 300,000 |" in text
    assert "35.41 dB against 35.78 dB, -0.37 dB: within 0.5 dB" in text
    assert "100,000 points uniform in [-1.3, 1.3]^3" in text
    assert "| 2,500 | 30.10 | 0.9000 | 0.0800 |" in text  # the test curve
    far = tool.write_report(fake_result(35.0), cfg, tmp_path / "far", command="x").read_text()
    assert "-0.78 dB: NOT within 0.5 dB" in far
    saved = json.loads((tmp_path / "report" / "result.json").read_text())
    assert saved["result"]["ply_path"] == "point_cloud.ply" and "dataset" not in saved["config"]
    assert TrainResult.from_dict(saved["result"]).step_evaluations == fake_result(35.41).step_evaluations
    assert (tmp_path / "report" / "curve.csv").read_text().splitlines()[0] == "step,psnr,ssim,lpips_alex"
    assert (tmp_path / "report" / "curve.png").stat().st_size > 0


def test_a_smoke_run_is_marked_and_compared_with_nothing(tool, tmp_path):
    cfg = tool.paper_config(tmp_path / "lego", tmp_path / "run", tool.SMOKE)
    text = tool.report_markdown(fake_result(20.0, iterations=300), cfg, command="x")
    assert text.startswith("> **Not the paper's protocol**: 300 steps of protocol `graphdeco-30k`, "
                           "images downscaled 4x")
    assert "**Against the paper:** no comparison" in text and "within 0.5 dB" not in text


def test_resume_finds_the_last_checkpoint(tool, tmp_path):
    ck = tmp_path / "checkpoints"
    ck.mkdir()
    for step in (100, 2500, 900):
        (ck / f"iteration_{step}.pt").write_bytes(b"")
    (ck / "iteration_x.pt").write_bytes(b"")
    assert tool.last_checkpoint(tmp_path) == ck / "iteration_2500.pt"
    assert tool.last_checkpoint(tmp_path / "none") is None
