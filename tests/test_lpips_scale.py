"""tools/lpips_scale.py: the slope of AlexNet-LPIPS differences on LPIPS-VGG differences between models on
the same views (the AlexNet minimum effect, `splatbench.experiments.train_kind.LPIPS_MIN_EFFECT`), recovered
from synthetic values of known slope; and the tool leaves alone what it must not measure, writing nothing.
No rendering: the measurement itself runs on a grid's results (docs/reports.md, "Minimum effects").
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import sys
from pathlib import Path

import numpy as np

from splatbench.experiments.store import RunRecord, write_record

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("lpips_scale", ROOT / "tools" / "lpips_scale.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # its dataclasses resolve their annotations through it
    spec.loader.exec_module(mod)
    return mod


def _scene(rng, slope: float, runs: int = 12, views: int = 9, spread: float = 0.01, noise: float = 0.0):
    """([R, V] AlexNet, [R, V] VGG): each view its own difficulty in each net (unrelated offsets, far larger
    than the models' differences), each run a model quality ``q`` that moves VGG by ``q`` times a per-view
    gain and AlexNet by ``slope`` times that; plus independent noise per net of SD ``noise`` (VGG) and
    ``slope * noise`` (AlexNet): the disagreement between nets, in each net's own units."""
    view_vgg, view_alex = rng.uniform(0.05, 0.3, views), rng.uniform(0.01, 0.2, views)
    q = rng.normal(0, spread, runs)[:, None] * rng.uniform(0.5, 1.5, views)[None, :]
    vgg = view_vgg + q + rng.normal(0, noise, (runs, views))
    alex = view_alex + slope * q + rng.normal(0, slope * noise, (runs, views))
    return alex, vgg


def test_a_known_slope_is_recovered_exactly_without_noise():
    tool = _tool()
    rng = np.random.default_rng(1)
    scenes = {"a": _scene(rng, 0.45), "b": _scene(rng, 0.45, runs=6, spread=0.001)}
    out = tool.estimate(scenes, boot=200)
    for entry in (*out["scenes"].values(), out["pooled"]):
        for key in ("per_view", "run_means"):
            s = entry[key]
            # exact up to float64 rounding of sums of ~100 products (1e-12 relative is ~1e4 ulps of slack)
            for value in (s["rma"], s["ols"], s["ols_inverse"], *s["rma_ci"]):
                assert math.isclose(value, 0.45, rel_tol=1e-12), (key, s)
            assert math.isclose(s["r"], 1.0, rel_tol=1e-12)
    assert out["scenes"]["b"]["runs"] == 6 and out["scenes"]["b"]["views"] == 9 and out["pooled"]["runs"] == 18
    # the view offsets are gone: uncentred values would give another slope (view difficulty of both nets)
    alex, vgg = scenes["a"]
    assert not math.isclose(tool.slopes(alex.ravel() - alex.mean(), vgg.ravel() - vgg.mean()).rma, 0.45, rel_tol=0.05)


def test_with_disagreeing_nets_the_reduced_major_axis_recovers_the_slope_where_ols_does_not():
    tool = _tool()
    rng = np.random.default_rng(7)
    # the nets' disagreement as large as the models' differences (r about 0.5): OLS is attenuated to about
    # r * slope, its reverse inflated to slope / r; the reduced major axis is not (noise SDs in the slope's ratio)
    scenes = {name: _scene(rng, 0.6, runs=30, spread=0.01, noise=0.01) for name in ("a", "b", "c")}
    out = tool.estimate(scenes, boot=1000)
    pooled = out["pooled"]["per_view"]
    low, high = pooled["rma_ci"]
    assert low < 0.6 < high, pooled
    assert pooled["ols"] < low and pooled["ols_inverse"] > high  # both OLS outside the interval: attenuation shows
    assert 0.3 < pooled["r"] < 0.8
    for entry in out["scenes"].values():
        low, high = entry["per_view"]["rma_ci"]
        assert low < 0.6 < high, entry


def test_the_pool_weighs_every_scene_equally():
    tool = _tool()
    rng = np.random.default_rng(3)
    # scene "big" varies 100 times more than "small" and has twice the slope; noiseless, each scene's
    # centred values divided by its VGG RMS give sum(a^2) = slope^2 n and sum(v^2) = n each: the pooled RMA
    # slope is sqrt((2^2 + 1^2) n / 2n) = sqrt(2.5) = 1.581, where pooling raw values would give about 2
    scenes = {"big": _scene(rng, 2.0, spread=0.1), "small": _scene(rng, 1.0, spread=0.001)}
    out = tool.estimate(scenes, boot=100)
    assert math.isclose(out["pooled"]["per_view"]["rma"], math.sqrt(2.5), rel_tol=1e-12)
    raw = tool.slopes(np.concatenate([tool.centred(a).ravel() for a, _ in scenes.values()]),
                      np.concatenate([tool.centred(v).ravel() for _, v in scenes.values()]))
    assert raw.rma > 1.99


def test_the_threshold_is_the_published_share_on_the_alexnet_scale():
    tool = _tool()
    # 3DGS Table 1: 0.079 LPIPS-VGG for 1.73 dB; 0.1 dB's share of it, times the slope
    assert math.isclose(tool.threshold(1.0), 0.079 * 0.1 / 1.73)
    assert math.isclose(tool.threshold(0.5), 0.5 * 0.079 * 0.1 / 1.73)


def _record(run_id: str, scene: str, seed: int, status: str = "done") -> RunRecord:
    return RunRecord(run_id=run_id, experiment="grid", kind="train", scene=scene, seed=seed, status=status,
                     config={}, labels={"sh.degree": 0}, metrics={"test_psnr": 30.0, "test_lpips": 0.02,
                                                                  "lpips_net": "alex"},
                     curves={}, error=None if status == "done" else "X: y", seconds=1.0,
                     started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:01+00:00", worker="h:1")


def test_runs_not_done_held_or_without_a_model_are_left_alone_and_nothing_is_written(tmp_path, capsys):
    tool = _tool()
    results = tmp_path / "res"
    write_record(results, _record("aaaaaaaaaaaaaaaa", "fox", 0, status="failed"))
    write_record(results, _record("bbbbbbbbbbbbbbbb", "fox", 1))
    write_record(results, _record("cccccccccccccccc", "fox", 2))
    (results / "grid" / "claims").mkdir()
    (results / "grid" / "claims" / "bbbbbbbbbbbbbbbb.claim").write_text("h:1")
    (results / "grid" / "work" / "cccccccccccccccc").mkdir(parents=True)  # a work folder without its model
    before = sorted((p, p.stat().st_mtime_ns) for p in results.rglob("*"))
    assert tool.main([str(results), "grid", "--boot", "100"]) == 1
    out = capsys.readouterr()
    assert "skipped aaaaaaaaaaaaaaaa: status 'failed'" in out.out
    assert "skipped bbbbbbbbbbbbbbbb: held by a runner" in out.out
    assert "skipped cccccccccccccccc: config.toml, point_cloud.ply, result.json missing" in out.out
    assert "no scene with 2 or more runs" in out.err
    assert sorted((p, p.stat().st_mtime_ns) for p in results.rglob("*")) == before


def test_a_written_measurement_is_estimated_again_from_its_values(tmp_path, capsys):
    """``--from``: the per-view values a measurement wrote, estimated again without rendering; the pooled
    slope and the threshold it implies come out of the command as `estimate` gives them."""
    import json

    tool = _tool()
    rng = np.random.default_rng(5)
    runs = []
    for scene in ("fox", "maryrose"):
        alex, vgg = _scene(rng, 0.8, runs=4)
        runs += [tool.RunViews(f"{scene}{i}", scene, {"sh.degree": i}, 0, 30.0, 30.0, float(a.mean()), "alex",
                               a.tolist(), v.tolist()) for i, (a, v) in enumerate(zip(alex, vgg))]
    source, out = tmp_path / "m.json", tmp_path / "again.json"
    source.write_text(json.dumps({"experiment": "grid", "runs": [dataclasses.asdict(r) for r in runs]}))
    assert tool.main(["--from", str(source), "--out", str(out), "--boot", "100"]) == 0
    result = json.loads(out.read_text())
    assert math.isclose(result["pooled"]["per_view"]["rma"], 0.8, rel_tol=1e-12)  # noiseless (first test)
    assert math.isclose(result["threshold"]["alex"], 0.8 * 0.079 * 0.1 / 1.73, rel_tol=1e-12)
    assert [r["run_id"] for r in result["runs"]] == [r.run_id for r in runs]
    assert "| pooled (scenes weighed equally) | 8 |" in capsys.readouterr().out
    # a file that is not one: one line, no traceback
    source.write_text(json.dumps({"experiment": "grid", "runs": [{"run_id": "x"}]}))
    assert tool.main(["--from", str(source)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "not a tools/lpips_scale.py output" in err and len(err.splitlines()) == 1
