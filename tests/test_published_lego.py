"""tools/published_lego.py (issue 29 item 7): the paper's settings as a config (graphdeco's
NeRF-synthetic initialisation through the built-in ``init = "random"``, so a bare ``splatbench
train --resume`` continues the run), and the report written from a run's result -- here a
synthetic result (no training), so every number in the report can be checked against it."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from PIL import Image

from splatbench.train import TrainConfig, TrainResult
from splatbench.train.initializers import INITIALIZERS, InitSettings, initialize, random_region
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
        notes=["background [1.0, 1.0, 1.0] (config)"], init={"method": "random", "points": 100_000,
                                                            "region": "nerf_synthetic", "region_shape": "cube",
                                                            "region_center": [0.0, 0.0, 0.0], "region_size": 1.3},
        load={"load_before": 0.1, "load_after": 0.2, "load_other": 0.0, "cores": 2, "loaded": False},
        lpips_net="vgg", lpips_scale_inputs=False, protocol="graphdeco-30k", step_evaluations=cols)


def test_paper_config_is_graphdecos_30k_protocol_on_white(tool, tmp_path):
    cfg = tool.paper_config(tmp_path / "lego", tmp_path / "run")
    assert (cfg.protocol, cfg.iterations, cfg.schedule_length, cfg.evaluation_steps) == \
        ("graphdeco-30k", 30_000, 30_000, [7000, 30_000])
    assert cfg.background == [1.0, 1.0, 1.0] and cfg.init.random_points == 100_000
    assert (cfg.init.method, cfg.init.region, cfg.initial_opacity) == ("random", "nerf_synthetic", 0.1)
    assert (cfg.eval.lpips_net, cfg.eval.lpips_scale_inputs, cfg.data.layout) == ("vgg", False, "blender")
    smoke = tool.paper_config(tmp_path / "lego", tmp_path / "run", tool.SMOKE)
    assert (smoke.iterations, smoke.evaluation_steps, smoke.data.downscale) == (300, [100, 300], 4)


def test_the_tool_adds_no_initializer_so_a_bare_resume_reads_its_config(tool, tmp_path):
    """A checkpoint holds the config as data (`checkpoint_config` is `TrainConfig.from_dict`):
    it names only built-in initializers, and loading the tool registers none."""
    before = dict(INITIALIZERS)
    spec = importlib.util.spec_from_file_location("published_lego_again", ROOT / "tools" / "published_lego.py")
    spec.loader.exec_module(importlib.util.module_from_spec(spec))
    assert INITIALIZERS == before
    cfg = tool.paper_config(tmp_path / "lego", tmp_path / "run")
    assert INITIALIZERS[cfg.init.method].__module__ == "splatbench.train.initializers"  # built in
    assert TrainConfig.from_dict(cfg.to_dict()) == cfg


def _blender_folder(root: Path, centre=(0.0, 0.0, 0.0), radius: float = 4.031, n: int = 12) -> Path:
    """A NeRF-synthetic-style folder (transforms_{train,test}.json, "./train/r_i" paths, 8x8 RGBA
    PNGs, camera_angle_x only): cameras on the upper half of a sphere of ``radius`` (lego's rig:
    4.03) around ``centre``, looking at it. The camera-to-world matrices are written by hand in
    Blender's axes (x right, y up, looking down -z), not through splatbench's `Camera`."""
    rng = np.random.default_rng(5)
    for split, count in (("train", n), ("test", 2)):
        frames = []
        for i in range(count):
            d = rng.normal(size=3)
            d[2] = abs(d[2]) + 0.2  # Blender's z is up: above the ground plane, as lego's rig
            back = d / np.linalg.norm(d)  # the camera looks down -back, at the centre
            right = np.cross([0.0, 0.0, 1.0], back)
            right /= np.linalg.norm(right)
            c2w = np.eye(4)
            c2w[:3, 0], c2w[:3, 1], c2w[:3, 2] = right, np.cross(back, right), back
            c2w[:3, 3] = np.asarray(centre) + radius * back
            frames.append({"file_path": f"./{split}/r_{i}", "rotation": 0.012566, "transform_matrix": c2w.tolist()})
            (root / split).mkdir(parents=True, exist_ok=True)
            Image.fromarray(rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)).save(root / split / f"r_{i}.png")
        (root / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": 0.6911, "frames": frames}))
    return root


def test_region_auto_picks_graphdecos_box_on_a_nerf_synthetic_folder(tool, tmp_path):
    """Loaded from disk as lego is (its axis conventions included): ``auto`` picks the box the
    tool sets explicitly; the same rig moved off the origin gets the convergence ball instead.
    The tool's initializer then fills [-1.3, 1.3]^3 with graphdeco's opacity and 3-NN scales."""
    from splatbench.data import load_dataset
    from splatbench.gaussians_from_points import knn_mean_sq_dist

    ds = load_dataset(_blender_folder(tmp_path / "lego"), background=(1.0, 1.0, 1.0))
    assert ds.layout == "blender" and ds.points is None
    region = random_region(ds, "auto")
    assert (region.chosen, region.shape, region.size) == ("nerf_synthetic", "cube", 1.3) and not region.center.any()
    moved = load_dataset(_blender_folder(tmp_path / "moved", centre=(3.0, 0.0, 0.0)))
    off = random_region(moved, "auto")
    assert off.chosen == "convergence"
    np.testing.assert_allclose(off.center, [3.0, 0.0, 0.0], atol=1e-6)

    cfg = tool.paper_config(tmp_path / "lego", tmp_path / "run", ["init.random_points=3000"])
    made = initialize(cfg.init.method, ds, InitSettings(sh_degree=cfg.sh.max_degree, opacity=cfg.initial_opacity,
                                                 random_points=cfg.init.random_points, seed=cfg.seed,
                                                 region=cfg.init.region))
    g, summary = made.gaussians, made.summary
    assert (summary["method"], summary["region"], summary["points"]) == ("random", "nerf_synthetic", 3000)
    means = g.means.astype(np.float64)
    assert np.abs(means).max() <= 1.3 + 1e-6 and np.abs(means).max() > 1.29  # fills the box
    # uniform: the fraction in the inner half-size cube is 1/8 (binomial sd 0.006 at n = 3000)
    assert abs(np.mean(np.abs(means).max(axis=1) < 0.65) - 0.125) < 0.03
    assert np.allclose(1 / (1 + np.exp(-g.opacity_logits)), 0.1)
    # create_from_pcd's scales: log sqrt of the mean squared 3-NN distance, on all three axes
    # (float32 storage: 1e-5 relative)
    expect = np.log(np.sqrt(np.maximum(knn_mean_sq_dist(means), 1e-7)))
    np.testing.assert_allclose(g.log_scales, np.repeat(expect[:, None], 3, axis=1), atol=1e-5)
    # colours uniform in [0, 1) per channel (graphdeco's are one grey, the tool's doc says so):
    # the DC colour C0 sh0 + 0.5 spans the range, mean 1/2 (sd of the mean 0.29 / sqrt(9000) = 0.003)
    colour = 0.5 + 0.28209479177387814 * g.sh[:, 0].astype(np.float64)
    assert colour.min() >= -1e-6 and colour.max() <= 1 + 1e-6 and colour.min() < 0.01 and colour.max() > 0.99
    assert abs(colour.mean() - 0.5) < 0.015 and math.isclose(np.abs(g.sh[:, 1:]).max(), 0.0)


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
