"""Training (issue 5 §1, §3-§5): config round trip and overrides, bad input before any
work, a short run that learns and writes a valid PLY, determinism, frozen groups,
the SH schedule (fixed and automatic) and the command line.

Datasets: ``tiny_diffuse`` is the `diffuse` scene rendered by Mitsuba at 32² (8 views,
4 spp), with its surface points (a few hundred at 32², thinned to at most 1500);
`synthetic_dataset` renders random Gaussians with splatbench itself (exactly
view-independent with SH degree 0, or with strong band-1 colour).
"""

from __future__ import annotations


import dataclasses
import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

import splatbench
from splatbench.cameras import Camera
from splatbench.data.dataset import Dataset, PointCloud, Split, load_dataset
from splatbench.errors import InputError
from splatbench.gaussians import Gaussians
from splatbench.train import TrainConfig, TrainResult, apply_overrides, load_config, save_config, train
from splatbench.train.config import EvalConfig, InitConfig, OptimConfig, SHConfig, StrategyConfig, parse_override
from splatbench.train.loop import Trainer, torch_threads
from splatbench.train.params import ExponentialLR, scene_extent
from splatbench.train.sh_schedule import BandMeasure, ShSchedule

THIN_POINTS = 1500


# ----------------------------------------------------------------------------- datasets
@pytest.fixture(scope="module")
def tiny_diffuse_dir(tmp_path_factory) -> Path:
    """The `diffuse` scene as a dataset folder: 32x32, 8 views (7 train + 1 test), 4 spp."""
    from splatbench.scenes.render import render_dataset

    out = tmp_path_factory.mktemp("scenes") / "diffuse-32"
    render_dataset("diffuse", out, resolution=32, views=8, spp=4, progress=False)
    return out


def thinned(dataset: Dataset, n: int = THIN_POINTS) -> Dataset:
    if len(dataset.points) <= n:
        return dataset
    idx = np.random.default_rng(0).choice(len(dataset.points), n, replace=False)
    idx.sort()
    return dataclasses.replace(dataset, points=PointCloud(dataset.points.xyz[idx], dataset.points.rgb[idx]))


@pytest.fixture(scope="module")
def tiny_diffuse(tiny_diffuse_dir) -> Dataset:
    return thinned(load_dataset(tiny_diffuse_dir))


def orbit_cameras(n: int, size: int = 32) -> list[Camera]:
    cams = []
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = [3.0 * np.cos(a), -1.2 + 0.4 * (i % 3), 3.0 * np.sin(a)]
        cams.append(Camera.look_at(eye=eye, target=[0, 0, 0], up=[0, -1, 0], width=size, height=size,
                                   fov_x_deg=45))
    return cams


def synthetic_dataset(root: Path, *, view_dependent: bool, views: int = 12, n: int = 400, seed: int = 0) -> Dataset:
    """Random Gaussians in a unit ball rendered by splatbench from an orbit: exactly
    view-independent (SH degree 0) or with strong degree-1 colour."""
    rng = np.random.default_rng(seed)
    means = rng.normal(size=(n, 3)) * 0.5
    sh = np.zeros((n, 4, 3))
    sh[:, 0] = rng.normal(size=(n, 3)) * 0.8
    if view_dependent:
        sh[:, 1:] = rng.normal(size=(n, 3, 3)) * 0.8
    truth = Gaussians(means=means, log_scales=np.full((n, 3), np.log(0.08)),
                      quats=np.tile([1.0, 0, 0, 0], (n, 1)), opacity_logits=np.full(n, 2.0), sh=sh)
    cams = orbit_cameras(views)
    images = np.stack([np.clip(splatbench.render(truth, c).rgb, 0, 1) for c in cams]).astype(np.float32)
    test = [i for i in range(views) if i % 4 == 0]
    train_ids = [i for i in range(views) if i % 4]

    def split(ids):
        return Split(images[ids], [cams[i] for i in ids], None, [f"v{i}.png" for i in ids])

    colours = np.clip(0.5 + 0.28209479177387814 * sh[:, 0], 0, 1)
    ds = Dataset("synthetic", split(train_ids), split(test), PointCloud(means, (colours * 255).astype(np.uint8)),
                 root, "blender")
    object.__setattr__(ds, "truth", truth)  # for the "truth" initializer of the SH tests
    return ds


def config(tmp_path: Path, **fields) -> TrainConfig:
    # the tests write their schedules in steps of their short runs
    base = dict(dataset="", out=str(tmp_path / "run"), iterations=20, log_every=5,
                schedule="absolute", strategy=StrategyConfig(name="none"))
    return TrainConfig(**{**base, **fields})


class CountingRasterize:
    """Stands in for `splatbench.rasterize` inside the trainer and counts calls."""

    def __init__(self) -> None:
        self.calls = 0
        self.requires_grad: list[tuple[bool, ...]] = []
        self.cameras: list[Camera] = []

    def __call__(self, *args, **kwargs):
        from splatbench.raster.torch_bridge import rasterize

        self.calls += 1
        self.requires_grad.append(tuple(bool(t.requires_grad) for t in args[:5]))
        self.cameras.append(args[5])
        return rasterize(*args, **kwargs)


@pytest.fixture
def counting(monkeypatch) -> CountingRasterize:
    spy = CountingRasterize()
    monkeypatch.setattr("splatbench.train.loop.rasterize", spy)
    return spy


# ----------------------------------------------------------------------------- config
def test_config_toml_round_trip_and_overrides(tmp_path):
    cfg = TrainConfig(dataset="data/x", iterations=123, background=[0.5, 0.25, 1.0], sh=SHConfig(degree="auto"), strategy=StrategyConfig(name="mcmc", options={"cap_max": 5000, "noise_lr": 5e5}))
    path = save_config(cfg, tmp_path / "c.toml")
    assert load_config(path) == cfg
    import tomllib

    assert tomllib.loads(path.read_text())["sh"]["degree"] == "auto"          # plain TOML, no code
    assert TrainConfig.from_toml(TrainConfig().to_toml()) == TrainConfig()

    out = apply_overrides(cfg, ["iterations=7000", "optim.lr_means=1", "sh.degree=2",
                                "background=[0, 0, 1]", "random_background=true",
                                "strategy.cap_max=100", "dataset=some/where"])
    assert (out.iterations, out.sh.degree, out.strategy.name, out.random_background, out.dataset) == \
        (7000, 2, "mcmc", True, "some/where")
    assert out.optim.lr_means == 1.0 and isinstance(out.optim.lr_means, float)  # int widened to float
    assert out.background == [0.0, 0.0, 1.0]
    assert out.strategy.options == {"cap_max": 100, "noise_lr": 5e5}
    assert apply_overrides(cfg, ["sh.degree=auto"]).sh.degree == "auto"        # bare string
    # one reader: a group as a TOML table, as dotted keys, or (strategy, init) by its name alone
    assert TrainConfig.from_dict({"sh": {"degree": 1}}) == TrainConfig.from_dict({"sh.degree": 1})
    assert apply_overrides(TrainConfig(), ["strategy=mcmc", "init=random"]) == \
        TrainConfig.from_toml('[strategy]\nname = "mcmc"\n[init]\nmethod = "random"\n')
    assert apply_overrides(TrainConfig(), ["background=1,1,1"]).background == [1.0, 1.0, 1.0]  # render's spelling
    assert parse_override("init = random") == ("init", "random")
    # a flat key of the config before its groups points to its place now; a top-level field written
    # inside a table (after a [table] header in TOML) says so
    with pytest.raises(InputError, match=r"^--set: sh_degree: now sh\.degree \(the config is in groups"):
        apply_overrides(cfg, ["sh_degree=2"])
    with pytest.raises(InputError, match=r"^c\.toml: data\.background: not a key of \[data\]: background is a top-level"):
        TrainConfig.from_toml('[data]\ndownscale = 2\nbackground = [1, 1, 1]\n', source="c.toml")
    assert cfg.iterations == 123                                               # the original is untouched
    # the config is validated on construction: MCMC's options under another strategy fail at once
    with pytest.raises(InputError, match=r"^strategy\.cap_max: not a field of strategy 'default' \(set strategy\.name: "
                                         r"cap_max is a field of mcmc\)$"):
        apply_overrides(cfg, ["strategy=default"])
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.iterations = 5  # frozen: change a copy with dataclasses.replace / apply_overrides


BAD_CONFIGS = [
    (["colour=1"], "colour"),                       # unknown key
    (["iterations=0"], "iterations"),
    (["iterations=ten"], "iterations"),             # bad value
    (["iterations=1.5"], "iterations"),
    (["optim.lr_means=-1e-4"], "optim.lr_means"),
    (["optim.lr_sh_rest=-1"], "optim.lr_sh_rest"),
    (["strategy=densest"], "strategy"),
    (["strategy.no_such_field=1"], "no_such_field"),
    (["init=poisson"], "init"),
    (["init.region=sky"], "init.region"),
    (["init.extent=0"], "init.extent"),
    (["init.jitter=-0.1"], "init.jitter"),
    (["init.sfm_poses=guessed"], "init.sfm_poses"),
    (["sh.degree=4"], "sh.degree"),
    (["sh.degree=high"], "sh.degree"),
    (["sh.auto_lookahead=3"], "sh.auto_lookahead"),   # 0..2: after band 1, at most bands 2 and 3
    (["sh.auto_lookahead=-1"], "sh.auto_lookahead"),
    (["sh.auto_lookahead=1.5"], "sh.auto_lookahead"),
    (["background=[2, 0, 0]"], "background"),
    (["loss.ssim_window=10"], "loss.ssim_window"),
]


@pytest.mark.parametrize("overrides,field", BAD_CONFIGS, ids=[o[0] for o, _ in BAD_CONFIGS])
def test_bad_config_is_one_line_error_before_any_work(tmp_path, tiny_diffuse_dir, counting, overrides, field):
    with pytest.raises(InputError) as err:
        cfg = apply_overrides(config(tmp_path, dataset=str(tiny_diffuse_dir)), overrides)
        train(cfg)
    msg = str(err.value)
    assert "\n" not in msg and field in msg, msg
    assert counting.calls == 0
    assert not (tmp_path / "run").exists()


def _resized_copy(src: Path, dst: Path) -> Path:
    from PIL import Image

    shutil.copytree(src, dst)
    first = sorted((dst / "images").iterdir())[1]
    with Image.open(first) as im:
        im.resize((im.width // 2, im.height // 2)).save(first)
    return dst


def test_bad_dataset_is_one_line_error_before_any_work(tmp_path, tiny_diffuse_dir, counting):
    cases = [(tmp_path / "nowhere", "nowhere"),
             (_resized_copy(tiny_diffuse_dir, tmp_path / "resized"), "image size")]
    for path, needle in cases:
        with pytest.raises(InputError) as err:
            train(config(tmp_path, dataset=str(path)))
        assert "\n" not in str(err.value) and needle in str(err.value), str(err.value)
    with pytest.raises(InputError, match="dataset: no dataset folder"):
        train(config(tmp_path))
    no_points = dataclasses.replace(load_dataset(tiny_diffuse_dir), points=None)
    with pytest.raises(InputError, match="random_background"):
        train(config(tmp_path, random_background=True), dataset=no_points)
    assert counting.calls == 0


# ----------------------------------------------------------------------------- training
# 40 steps are few for 3DGS's rates: opacity and colour learn 4x faster in the short runs.
FAST = dict(optim=OptimConfig(lr_opacity_logits=0.1, lr_sh_dc=0.01))


def test_short_run_lowers_loss_and_writes_a_valid_ply(tmp_path):
    ds = synthetic_dataset(tmp_path, view_dependent=False)
    losses = []
    cfg = config(tmp_path, iterations=40, checkpoint_every=20, **FAST)
    result = train(cfg, dataset=ds, progress=lambda s: losses.append(s.loss))
    assert len(losses) == 40
    first, last = np.array(losses[:9]), np.array(losses[-9:])    # one epoch is 9 views
    assert first.mean() - last.mean() > 2 * first.std()           # a drop well beyond the spread over views
    assert isinstance(result, TrainResult) and result.iterations == 40
    assert result.test_psnr is not None and result.test_psnr > 15
    assert 0 < result.test_ssim <= 1 and result.test_views == 3
    assert result.num_gaussians == len(ds.points) and result.sh_degree == 0
    assert result.render_ms_per_view > 0 and result.peak_rss_mb > 0 and result.train_seconds > 0
    assert [p.step for p in result.history] == [0, 5, 10, 15, 20, 25, 30, 35, 39]
    ply = Path(result.ply_path)
    g = Gaussians.from_ply(ply)
    assert len(g) == len(ds.points) and g.sh_degree == 0
    assert sorted(p.name for p in (tmp_path / "run" / "checkpoints").iterdir()) == \
        ["iteration_20.ply", "iteration_20.pt", "iteration_40.ply", "iteration_40.pt"]
    assert Gaussians.from_ply(tmp_path / "run" / "checkpoints" / "iteration_40.ply").means.tobytes() == \
        g.means.tobytes()
    saved = json.loads((tmp_path / "run" / "result.json").read_text())
    assert TrainResult.from_dict(saved).history == result.history
    assert load_config(tmp_path / "run" / "config.toml") == cfg
    # LPIPS (AlexNet, scaled: the default) of the final model, the same number as the last curve point
    assert result.lpips_net == "alex" and result.lpips_scale_inputs
    assert 0 < result.test_lpips < 1 and result.evaluations[-1].lpips == result.test_lpips
    # the machine's load around the run, and the loop's CPU time (every step runs on this process's threads)
    assert {"load_before", "load_after", "load_other", "cores", "loaded"} <= set(result.load)
    assert result.cpu_seconds > 0 and saved["load"] == result.load


def test_final_lpips_follows_the_config_and_the_curves_use_alexnet(tmp_path):
    from splatbench.metrics import lpips

    ds = synthetic_dataset(tmp_path, view_dependent=False, views=8, n=60)
    cfg = config(tmp_path, iterations=4, background=[0.0, 0.0, 0.0], **FAST, eval=EvalConfig(every=2, lpips_net="vgg", lpips_scale_inputs=False))
    result = train(cfg, dataset=ds)
    assert result.lpips_net == "vgg" and not result.lpips_scale_inputs
    # the background the renders used is recorded, and where it came from (here: the config's)
    assert result.background == [0.0, 0.0, 0.0] and result.background_source == "config"
    # and the views and image size it trained and was evaluated at, as the dataset holds them
    height, width = ds.test.image_size
    assert (result.train_views, result.image_size) == (len(ds.train), [width, height])
    # each test view's PSNR at the end, in test-split order: their mean is the reported test PSNR (rounded to
    # 1e-6 dB per view, so the mean agrees to that)
    assert len(result.test_view_psnr) == len(ds.test)
    assert abs(float(np.mean(result.test_view_psnr)) - result.test_psnr) < 1e-6
    model = Gaussians.from_ply(result.ply_path)  # the final model, rendered again through the public API
    want = np.mean([lpips(splatbench.render(model, cam).rgb, gt, net="vgg", scale_inputs=False)
                    for cam, gt in zip(ds.test.cameras, ds.test.images)])
    # the same PLY rendered by the same rasterizer, the same network: equal up to float32 rounding
    assert result.test_lpips == pytest.approx(want, abs=1e-5)
    alex = [p.lpips for p in result.evaluations]
    assert len(alex) == 2 and all(0 < v < 1 for v in alex) and alex[-1] != pytest.approx(result.test_lpips, abs=1e-3)
    off = train(config(tmp_path, iterations=2, out=str(tmp_path / "off"), **FAST, eval=EvalConfig(lpips_net="none")), dataset=ds)
    assert off.test_lpips is None and off.lpips_net == "" and off.evaluations[-1].lpips is None
    with pytest.raises(InputError, match="eval.lpips_net: expected"):
        config(tmp_path, eval=EvalConfig(lpips_net="squeeze"))


def test_trained_sh0_model_saves_graphdecos_62_properties_and_reads_back_as_degree_0(tmp_path):
    from plyfile import PlyData

    from tests.test_ply import GRAPHDECO_62

    ds = synthetic_dataset(tmp_path, view_dependent=False, views=8, n=60)
    result = train(config(tmp_path, iterations=4, sh=SHConfig(degree=0)), dataset=ds)
    assert result.sh_degree == 0
    ply = PlyData.read(result.ply_path)
    assert [p.name for p in ply["vertex"].properties] == GRAPHDECO_62  # graphdeco's order, 45 f_rest
    assert not any(np.asarray(ply["vertex"][f"f_rest_{i}"]).any() for i in range(45))
    back = Gaussians.from_ply(result.ply_path)
    assert back.sh_degree == 0 and back.sh.shape == (60, 1, 3)


def test_saved_ply_records_the_datasets_up_and_the_background(tmp_path, tiny_diffuse):
    """A Mitsuba render declares its up (+y, the rig's): the PLY records it and the
    background trained on, for `splatbench render`; a dataset without a splatbench
    manifest (the synthetic one, as a capture) declares no up: the PLY records the one its
    training cameras share (`rig_up`)."""
    from splatbench.ply import read_view_hints

    trainer = Trainer(config(tmp_path, background=[0.25, 0.5, 0.75]), dataset=tiny_diffuse)
    hints = read_view_hints(trainer.save_ply(tmp_path / "mitsuba.ply"))
    assert hints.up == (0.0, 1.0, 0.0)
    assert hints.background == tuple(np.float32([0.25, 0.5, 0.75]).tolist())  # the float32 tensor it rendered with
    synthetic = synthetic_dataset(tmp_path, view_dependent=False, views=8, n=20)
    hints = read_view_hints(Trainer(config(tmp_path), dataset=synthetic).save_ply(tmp_path / "synthetic.ply"))
    from splatbench.scenes.orientation import rig_up
    assert np.allclose(hints.up, rig_up(synthetic.train.cameras), atol=1e-6)
    assert hints.background == (0.0, 0.0, 0.0)  # "auto" without empty pixels: black


def test_auto_initial_opacity_is_the_strategys_reference_value(tmp_path, tiny_diffuse):
    """graphdeco's create_from_pcd starts at 0.1, 3DGS-MCMC's at 0.5; a number overrides both."""
    assert config(tmp_path).initial_opacity == 0.1
    assert config(tmp_path, strategy=StrategyConfig(name="mcmc")).initial_opacity == 0.5
    assert config(tmp_path, strategy=StrategyConfig(name="mcmc"), init=InitConfig(opacity=0.2)).initial_opacity == 0.2
    trainer = Trainer(config(tmp_path, strategy=StrategyConfig(name="mcmc")), dataset=tiny_diffuse)
    # logit(0.5) = 0 exactly, so every opacity is 0.5 to float32 rounding of sigmoid(0)
    assert torch.equal(torch.sigmoid(trainer.params["opacity_logits"].detach()),
                       torch.full((len(tiny_diffuse.points),), 0.5))
    with pytest.raises(InputError, match="init.opacity: expected a number in \\(0, 1\\) or 'auto'"):
        config(tmp_path, init=InitConfig(opacity="half")).validate()


def test_same_seed_and_config_give_the_same_ply_bytes(tmp_path, tiny_diffuse):
    # the default strategy refining every 5 steps: densification is covered too
    opts = {"refine_start": 4, "refine_every": 5, "refine_stop": 11, "grad_threshold": 1e-5}  # two refinements
    plys = []
    for run in ("a", "b"):
        cfg = config(tmp_path, out=str(tmp_path / run), iterations=20, strategy=StrategyConfig(name="default", options=opts))
        plys.append(Path(train(cfg, dataset=tiny_diffuse).ply_path).read_bytes())
    assert plys[0] == plys[1]
    assert len(Gaussians.from_ply(tmp_path / "a" / "point_cloud.ply")) != len(tiny_diffuse.points)  # densified


#: Each strategy with state, refining on both sides of step 10 (MCMC: relocations and additions;
#: budget: a count schedule of 2 refinements toward 1.5 x the initial points).
CHECKPOINT_STRATEGIES = {
    "default": {"refine_start": 4, "refine_every": 5, "refine_stop": 16, "grad_threshold": 1e-5},
    "mcmc": {"refine_start": 4, "refine_every": 5, "refine_stop": 16, "cap_max": 10_000},
    "budget": {"refine_start": 4, "refine_every": 5, "refine_stop": 16, "grad_threshold": 1e-5, "budget": 1.5},
}


@pytest.mark.parametrize("strategy", sorted(CHECKPOINT_STRATEGIES))
def test_checkpoint_resumes_training_exactly(tmp_path, tiny_diffuse, strategy):
    """20 steps straight against 10, a checkpoint, and 10 more in a fresh trainer: the same
    parameters bit for bit, with refinements on both sides of the checkpoint (the
    strategy's accumulators, count schedule and generator, Adam's moments and the view order resume)."""
    opts = CHECKPOINT_STRATEGIES[strategy]
    base = dict(iterations=20, strategy=StrategyConfig(name=strategy, options=opts), sh=SHConfig(degree=1, interval=8))
    straight = train(config(tmp_path, out=str(tmp_path / "straight"), **base), dataset=tiny_diffuse)
    first = train(config(tmp_path, out=str(tmp_path / "first"), checkpoint_every=10, **base), dataset=tiny_diffuse)
    assert Path(first.ply_path).read_bytes() == Path(straight.ply_path).read_bytes()
    checkpoint = tmp_path / "first" / "checkpoints" / "iteration_10.pt"
    resumed = train(config(tmp_path, out=str(tmp_path / "resumed"), **base), dataset=tiny_diffuse, resume=checkpoint)
    a, b = Gaussians.from_ply(straight.ply_path), Gaussians.from_ply(resumed.ply_path)
    assert len(a) != len(tiny_diffuse.points)  # densified
    for name in ("means", "log_scales", "quats", "opacity_logits", "sh"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    assert resumed.history == straight.history and resumed.iterations == 20
    # the resumed run says so, first among its notes; a straight run does not
    assert resumed.notes[0] == f"resumed from {checkpoint} at step 10 of 20"
    assert not any(n.startswith("resumed from") for n in straight.notes + first.notes)
    # its train_seconds counts the checkpoint's 10 steps too (timed by the first run; the summary
    # line says so), and it knows where it resumed
    before = torch.load(checkpoint, map_location="cpu", weights_only=True)["extra"]["loop_seconds"]
    assert 0 < round(before, 3) < resumed.train_seconds
    assert (resumed.resumed_step, straight.resumed_step, first.resumed_step) == (10, None, None)
    # a different config is refused before any step, naming the field
    with pytest.raises(InputError, match="resume: .* was written with seed=0; this run has seed=1 "):
        train(config(tmp_path, out=str(tmp_path / "other"), seed=1, **base), dataset=tiny_diffuse, resume=checkpoint)
    with pytest.raises(InputError, match="resume: no such checkpoint"):
        train(config(tmp_path, out=str(tmp_path / "other"), **base), dataset=tiny_diffuse, resume=tmp_path / "missing.pt")


def test_result_records_what_the_strategy_did(tmp_path, tiny_diffuse):
    """`TrainResult.topology`: refinements, opacity resets and the cloned / split / pruned totals
    (what a report names as a setting's confounds). The schedule fixes the first two (refine at
    it = 5, 10, 15; reset at it = 6, 12, inside the refine window only); the totals must add up to
    the final count (a split replaces one Gaussian by two); result.json keeps them, and a result
    written before they were recorded reads back with None."""
    from splatbench.strategies import TopologyCounts, planned_counts

    opts = {"refine_start": 4, "refine_every": 5, "refine_stop": 16, "grad_threshold": 1e-5, "reset_every": 6}
    r = train(config(tmp_path, strategy=StrategyConfig(name="default", options=opts)), dataset=tiny_diffuse)
    t = r.topology
    assert (t.refinements, t.opacity_resets, t.relocated, t.added) == (3, 2, 0, 0)
    assert t.cloned + t.split > 0  # the low threshold grows the model
    assert len(tiny_diffuse.points) + t.cloned + t.split - t.pruned == r.num_gaussians
    assert 0 <= t.pruned_size <= t.pruned
    # what the schedule plans (what a report names for runs that did not record it) is what happened
    planned = planned_counts(config(tmp_path, strategy=StrategyConfig(name="default", options=opts)).make_strategy(), 20)
    assert (planned.refinements, planned.opacity_resets) == (t.refinements, t.opacity_resets)
    saved = json.loads((tmp_path / "run" / "result.json").read_text())
    assert saved["topology"]["opacity_resets"] == 2 and TrainResult.from_dict(saved).topology == t
    del saved["topology"]
    assert TrainResult.from_dict(saved).topology is None
    # reset_every = 0: no resets, and no size pruning either (it waits for the first reset)
    never = train(config(tmp_path, out=str(tmp_path / "never"), strategy=StrategyConfig(name="default", options={**opts, "reset_every": 0})), dataset=tiny_diffuse)
    assert never.topology.opacity_resets == 0 and never.topology.pruned_size == 0
    # MCMC relocates and adds (refine_start 4 < it < 16, every 5); no strategy changes nothing
    mcmc = train(config(tmp_path, out=str(tmp_path / "mcmc"), strategy=StrategyConfig(name="mcmc", options=CHECKPOINT_STRATEGIES["mcmc"])), dataset=tiny_diffuse)
    assert mcmc.topology.refinements == 3 and mcmc.topology.opacity_resets == 0  # it = 5, 10, 15
    assert planned_counts(config(tmp_path, strategy=StrategyConfig(name="mcmc", options=CHECKPOINT_STRATEGIES["mcmc"]))
                          .make_strategy(), 20).refinements == 3
    assert len(tiny_diffuse.points) + mcmc.topology.added == mcmc.num_gaussians
    none = train(config(tmp_path, out=str(tmp_path / "none")), dataset=tiny_diffuse)
    assert none.topology == TopologyCounts()


def test_evaluating_before_the_refinement_is_the_run_without_it_at_that_step(tmp_path, tiny_diffuse):
    """eval.before_refine (graphdeco's train.py order: a step's test evaluation before its densification):
    training step for step as without it; an evaluation at a refinement step equal, bit for bit, to the
    final one of a run stopped there with refine_stop at that step (the same model: nothing of that
    step's refinement); the last step's refinement left out, so the saved model is the evaluated one."""
    def run(name: str, iterations: int, stop: int, first: bool) -> TrainResult:
        opts = {"refine_start": 4, "refine_every": 5, "refine_stop": stop, "grad_threshold": 1e-5}
        # graphdeco's protocol stopped early (the quick one refuses a refinement in a run's last 10 %)
        return train(config(tmp_path, out=str(tmp_path / name), iterations=iterations, log_every=1,
                            protocol="graphdeco-7k", eval=EvalConfig(every=5, before_refine=first),
                            strategy=StrategyConfig(name="default", options=opts)), dataset=tiny_diffuse)

    after, first = run("after", 15, 16, False), run("first", 15, 16, True)  # refinements at 5, 10 (and 15)
    assert [(h.step, h.loss) for h in first.history[:-1]] == [(h.step, h.loss) for h in after.history[:-1]]
    assert after.topology.refinements == 3 and first.topology.refinements == 2  # the last one left out
    stopped_10, stopped_15 = run("stopped_10", 10, 10, False), run("stopped_15", 15, 15, False)
    at = {e.step: e.psnr for e in first.evaluations}
    assert at[10] == stopped_10.test_psnr != {e.step: e.psnr for e in after.evaluations}[10]
    assert (first.test_psnr, first.num_gaussians) == (stopped_15.test_psnr, stopped_15.num_gaussians)
    assert Path(first.ply_path).read_bytes() == Path(stopped_15.ply_path).read_bytes()
    assert first.num_gaussians != after.num_gaussians  # the refinement left out changed the model


def test_a_budget_run_below_its_budget_says_so_in_its_warnings(tmp_path, tiny_diffuse):
    """No Gaussian passes a threshold of 1 (NDC gradients are far smaller), so nothing grows and
    the run's warnings carry the strategy's (`BudgetStrategy.outcome_note`)."""
    opts = {"refine_start": 4, "refine_every": 5, "refine_stop": 16, "grad_threshold": 1.0, "budget": 1.5}
    result = train(config(tmp_path, strategy=StrategyConfig(name="budget", options=opts)), dataset=tiny_diffuse)
    n = len(tiny_diffuse.points)
    assert result.num_gaussians <= n
    assert any(note.startswith(f"warning: strategy 'budget' ended at {result.num_gaussians:,} Gaussians, below its "
                               f"budget of {round(1.5 * n):,}") for note in result.warnings), result.warnings


def test_a_strategy_outcome_without_warning_is_a_note(tmp_path, tiny_diffuse, monkeypatch):
    """An outcome that does not start with "warning:" (the budget strategy's prune in its last refinement:
    the rule worked as written) is recorded among the run's notes, not its warnings."""
    from splatbench.strategies.budget import BudgetStrategy

    monkeypatch.setattr(BudgetStrategy, "outcome_note", lambda self, state: "strategy 'budget' ended 2 below")
    opts = {"refine_start": 4, "refine_every": 5, "refine_stop": 16, "budget": 1.5}
    result = train(config(tmp_path, strategy=StrategyConfig(name="budget", options=opts)), dataset=tiny_diffuse)
    assert "strategy 'budget' ended 2 below" in result.notes and not any("ended 2" in w for w in result.warnings)


def test_frozen_groups_get_no_gradient_work(tmp_path, tiny_diffuse, counting):
    cfg = config(tmp_path, optim=OptimConfig(lr_quats=0.0, lr_means=0.0, lr_means_final=0.0, lr_sh_rest=0.0), sh=SHConfig(interval=1))
    with torch_threads(1):
        trainer = Trainer(cfg, dataset=tiny_diffuse)
        before = {k: v.detach().clone() for k, v in trainer.params.items()}
        for _ in range(3):
            trainer.step()
    # means, log_scales, quats, opacity_logits, sh (sh_dc trains, so the SH input needs grad)
    assert counting.requires_grad == [(False, True, False, True, True)] * 3
    for name in ("quats", "means", "sh_rest"):
        assert not trainer.params[name].requires_grad and trainer.params[name].grad is None
        assert torch.equal(trainer.params[name], before[name])
    for name in ("log_scales", "opacity_logits", "sh_dc"):
        assert not torch.equal(trainer.params[name], before[name])


def test_position_lr_decays_exponentially_times_the_extent():
    sched = ExponentialLR(1.6e-4, 1.6e-6, 1000, scale=5.0)
    assert sched(0) == pytest.approx(8e-4) and sched(1000) == pytest.approx(8e-6)
    assert sched(500) == pytest.approx(8e-5)                      # geometric midpoint
    assert ExponentialLR(0.0, 0.0, 10)(3) == 0.0
    cams = orbit_cameras(8)
    centres = np.stack([c.center for c in cams])
    assert scene_extent(cams) == pytest.approx(1.1 * np.linalg.norm(centres - centres.mean(0), axis=1).max())


# ----------------------------------------------------------------------------- SH schedule
def test_fixed_sh_schedule_raises_the_degree_every_interval():
    sched = ShSchedule(3, 1000)
    got = {s: sched.update(s) for s in (0, 999, 1000, 1999, 2000, 2999, 3000, 29999)}
    assert got == {0: 0, 999: 0, 1000: 1, 1999: 1, 2000: 2, 2999: 2, 3000: 3, 29999: 3}
    capped = ShSchedule(1, 10)
    assert [capped.update(s) for s in (0, 10, 20, 30)] == [0, 1, 1, 1]


def test_trainer_follows_the_sh_schedule(tmp_path, tiny_diffuse, counting):
    degrees = []
    cfg = config(tmp_path, iterations=9, sh=SHConfig(interval=3, degree=2))
    result = train(cfg, dataset=tiny_diffuse, progress=lambda s: degrees.append(s.sh_degree))
    assert degrees == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    assert result.sh_degree == 2 and Gaussians.from_ply(result.ply_path).sh_degree == 2


def scripted(gains: dict[tuple[int, int], float], calls: list | None = None):
    """A probe with no rendering: (degree, baseline) -> the scripted gain (dB)."""
    def probe(degree: int, baseline: int) -> BandMeasure:
        if calls is not None:
            calls.append((degree, baseline))
        return BandMeasure(gains[degree, baseline], 0.5, 4)
    return probe


def run_auto(probe, steps: int, **kw) -> tuple[ShSchedule, list[int]]:
    sched = ShSchedule("auto", 10, min_gain_db=0.1, **kw)
    degrees = [sched.update(s, probe) for s in range(steps)]
    sched.finish(steps, probe)
    return sched, degrees


def test_greedy_auto_sh_keeps_bands_that_gain_and_drops_the_first_that_does_not():
    probe = scripted({(1, 0): 2.0, (2, 1): 0.01})
    sched = ShSchedule("auto", 10, min_gain_db=0.1, lookahead=0)
    degrees = [sched.update(s, probe) for s in range(40)]
    assert degrees[:10] == [0] * 10 and degrees[10:20] == [1] * 10 and degrees[20:30] == [2] * 10
    assert degrees[30:] == [1] * 10                     # band 2 dropped at step 30, settled
    assert [(d.degree, d.baseline, d.kept) for d in sched.decisions] == [(1, 0, True), (2, 1, False)]
    assert "degree 2 gained 0.010 dB over degree 1 (< 0.1 dB" in sched.reason
    # the trial length is named as a trial (degree 2 trained steps 20..29), not as the run's length
    assert "after a 10-step trial of degree 2;" in sched.reason and "after 10 steps" not in sched.reason
    assert sched.finish(40, probe) == 1
    ended = ShSchedule("auto", 10)
    [ended.update(s, probe) for s in range(5)]
    assert ended.finish(5, probe) == 0 and "before band 1" in ended.reason


# glossy's case: band 1 alone gains 0.05 dB (< 0.1), bands 1-3 together 0.6 dB (>= 3 x 0.1)
WEAK_BAND_1 = {(1, 0): 0.05, (2, 0): 0.15, (3, 0): 0.6}   # per added band: 0.05, 0.075, 0.2 dB


def test_auto_sh_settles_at_3_with_look_ahead_and_at_0_without():
    gains, calls = WEAK_BAND_1, []
    sched, degrees = run_auto(scripted(gains, calls), 50)
    assert calls == [(1, 0), (2, 0), (3, 0)]            # each against the last kept degree, not d - 1
    assert degrees[10:20] == [1] * 10 and degrees[20:30] == [2] * 10 and degrees[30:] == [3] * 20
    assert [(d.degree, d.baseline, d.kept) for d in sched.decisions] == [(1, 0, False), (2, 0, False), (3, 0, True)]
    assert sched.degree == 3 and sched.settled and "degree 3 gained 0.600 dB over degree 0" in sched.reason
    exact, _ = run_auto(scripted({**gains, (3, 0): 0.3}), 50)   # exactly on the bar 0.1 x 3: kept
    assert exact.degree == 3 and exact.decisions[-1].needed_db == 0.3
    greedy, degrees = run_auto(scripted(gains), 50, lookahead=0)
    assert degrees[20:] == [0] * 30 and greedy.degree == 0
    assert [(d.degree, d.baseline, d.kept) for d in greedy.decisions] == [(1, 0, False)]
    one, _ = run_auto(scripted(gains), 50, lookahead=1)   # stops after bands 1 and 2 both failed
    assert one.degree == 0 and [d.degree for d in one.decisions] == [1, 2] and "2 band(s) in a row" in one.reason


def test_auto_sh_drops_every_trained_band_when_none_helps():
    sched, degrees = run_auto(scripted({(1, 0): 0.02, (2, 0): 0.1, (3, 0): 0.2}), 50)  # 0.02, 0.05, 0.067 per band
    assert degrees[30:40] == [3] * 10 and degrees[40:] == [0] * 10   # bands 1-3 trained, then dropped
    assert sched.degree == 0 and sched.kept == 0 and sched.settled
    assert [d.kept for d in sched.decisions] == [False, False, False]
    assert "degree 3 reached, bands above 0 dropped; settled at degree 0" in sched.reason


def test_auto_sh_keeps_band_1_when_bands_2_and_3_do_not_help():
    sched, degrees = run_auto(scripted({(1, 0): 0.8, (2, 1): 0.03, (3, 1): 0.1}), 50)  # 3 vs 1: 0.05 per band
    assert degrees[40:] == [1] * 10 and sched.degree == 1
    assert [(d.degree, d.baseline, d.kept) for d in sched.decisions] == [(1, 0, True), (2, 1, False), (3, 1, False)]


def test_auto_sh_judges_the_bands_on_trial_at_the_end_of_the_run():
    sched, _ = run_auto(scripted({(1, 0): 0.05, (2, 0): 0.3}), 25)   # ends with degree 2 on trial
    assert sched.degree == 2 and "degree 2 at the end" in sched.reason
    cut, _ = run_auto(scripted({(1, 0): 0.05, (2, 0): 0.1}), 25)
    assert cut.degree == 0 and "the run ended, bands above 0 dropped" in cut.reason


def test_run_ids_hash_every_group_field_and_a_default_written_out_equals_one_left_out():
    """The experiment runner hashes the resolved config (splatbench.experiments.grid), which
    holds every field of every group: any field changed makes a new run (sh.auto_lookahead
    too, on a fixed-degree run: no field is left out by hand), a field written at its
    default is the same run as one left out, and a group written as a table or as dotted
    keys is the same run."""
    from splatbench.experiments.grid import make_run_id
    from splatbench.experiments.train_kind import TRAIN

    def run_id(config):
        return make_run_id("train", TRAIN.resolve({"scene": "diffuse", "seed": 0, "iterations": 10, **config}))

    resolved = TRAIN.resolve({"scene": "diffuse", "seed": 0})
    assert set(resolved["sh"]) == {f.name for f in dataclasses.fields(SHConfig)}
    assert resolved["strategy"]["name"] == "default" and "revised_opacity" in resolved["strategy"]
    assert run_id({"sh.degree": 3}) == run_id({}) == run_id({"sh": {"degree": 3, "auto_lookahead": 2}})
    ids = {run_id(c) for c in ({}, {"sh.auto_lookahead": 0}, {"sh.degree": "auto"}, {"optim.lr_quats": 2e-3},
                               {"strategy.revised_opacity": True}, {"data.test_every": 4}, {"raster.tile_size": 8},
                               {"eval.lpips_net": "vgg"}, {"loss.ssim_lambda": 0.0}, {"eval.before_refine": True})}
    assert len(ids) == 10
    # eval.before_refine, added after runs were recorded: at its default it is left out of the resolved config,
    # so every run id from before stays
    assert "before_refine" not in resolved["eval"] and run_id({"eval.before_refine": False}) == run_id({})


AUTO = dict(iterations=30, sh=SHConfig(degree="auto", interval=15, auto_probe_views=0), optim=OptimConfig(lr_sh_rest=2e-2))


@pytest.fixture
def truth_init(monkeypatch):
    """init="truth": the true Gaussians with their SH cut to degree 0 (a plug-in initializer),
    so that only the view dependence is left to learn."""
    from splatbench.train.initializers import INITIALIZERS

    def truth(dataset, settings):
        return dataset.truth.with_sh_degree(0).with_sh_degree(settings.sh_degree)

    monkeypatch.setitem(INITIALIZERS, "truth", truth)


def test_auto_sh_picks_0_for_a_view_independent_scene(tmp_path, truth_init):
    result = train(config(tmp_path, **AUTO, init=InitConfig(method="truth")), dataset=synthetic_dataset(tmp_path, view_dependent=False))
    assert result.sh_degree == 0, result.sh_degree_reason
    assert [(d["degree"], d["baseline"], d["kept"]) for d in result.sh_decisions] == [(1, 0, False)]
    assert "degree 1 gained" in result.sh_degree_reason and Gaussians.from_ply(result.ply_path).sh_degree == 0


def test_auto_sh_keeps_band_1_for_a_view_dependent_scene(tmp_path, truth_init):
    result = train(config(tmp_path, **AUTO, init=InitConfig(method="truth")), dataset=synthetic_dataset(tmp_path, view_dependent=True))
    assert result.sh_degree == 1, result.sh_degree_reason
    assert [(d["degree"], d["baseline"], d["kept"]) for d in result.sh_decisions] == [(1, 0, True)]
    assert result.sh_decisions[0]["gain_db"] >= 0.1


def test_auto_sh_holds_views_out_of_training_until_the_degree_settles(tmp_path, truth_init, counting):
    ds = synthetic_dataset(tmp_path, view_dependent=False)
    cfg = config(tmp_path, **{**AUTO, "sh": dataclasses.replace(AUTO["sh"], auto_holdout_every=4)},
                 init=InitConfig(method="truth"))
    with torch_threads(1):
        trainer = Trainer(cfg, dataset=ds)
        assert trainer.holdout == [2, 6]                          # i % 4 == 2 of 9 training views
        held = {id(ds.train.cameras[i]) for i in trainer.holdout}
        for _ in range(cfg.iterations):
            trainer.step()
        assert not held & {id(c) for c in counting.cameras}      # never trained on while undecided
        trainer.sh.finish(trainer.step_index, trainer.probe_band)    # measured on the held-out views
        assert trainer.sh.settled and "held-out training views" in trainer.sh.reason
        seen = len(counting.cameras)
        for _ in range(2 * len(ds.train)):                        # two epochs after settling
            trainer.step()
        assert held <= {id(c) for c in counting.cameras[seen:]}


# ----------------------------------------------------------------------------- command line
def test_cli_prints_one_json_line_and_one_line_errors(tmp_path, tiny_diffuse_dir):
    from splatbench.cli import main

    cfg = tmp_path / "c.toml"
    save_config(TrainConfig(iterations=2, strategy=StrategyConfig(name="none"), init=InitConfig(method="random", random_points=300)), cfg)
    runner = CliRunner()
    res = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                               "--json", "--quiet", "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    lines = [line for line in res.stdout.splitlines() if line.strip()]
    assert len(lines) == 1
    data = json.loads(lines[0])
    assert data["iterations"] == 3 and data["num_gaussians"] == 300 and Path(data["ply_path"]).is_file()
    bad = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--set", "optim.lr_quats=-1", "--quiet"])
    assert bad.exit_code == 2
    assert bad.stderr.strip().splitlines() == [bad.stderr.strip()] and "lr_quats" in bad.stderr
    # --resume reaches train(): the run's own checkpoint resumes to the same result; a
    # missing one is one line
    res = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                               "--set", "checkpoint_every=2", "--json", "--quiet", "--out", str(tmp_path / "c")])
    assert res.exit_code == 0, res.output
    checkpoint = tmp_path / "c" / "checkpoints" / "iteration_2.pt"
    again = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                                 "--resume", str(checkpoint), "--json",
                                 "--quiet", "--out", str(tmp_path / "r")])
    assert again.exit_code == 0, again.output
    assert (tmp_path / "r" / "point_cloud.ply").read_bytes() == (tmp_path / "c" / "point_cloud.ply").read_bytes()
    assert json.loads(again.stdout)["notes"][0] == f"resumed from {checkpoint} at step 2 of 3"
    # --resume alone continues with the checkpoint's own config: no DATASET, --config or --set
    alone = runner.invoke(main, ["train", "--resume", str(checkpoint), "--json", "--quiet", "--out", str(tmp_path / "a")])
    assert alone.exit_code == 0, alone.output
    assert (tmp_path / "a" / "point_cloud.ply").read_bytes() == (tmp_path / "c" / "point_cloud.ply").read_bytes()
    # ... in the folder the checkpoint sits in, wherever that folder has moved (not the config's `out`)
    import os
    import shutil

    shutil.copytree(tmp_path / "c", tmp_path / "moved")
    (tmp_path / "moved" / "point_cloud.ply").unlink()
    moved = runner.invoke(main, ["train", "--resume", str(tmp_path / "moved" / "checkpoints" / "iteration_2.pt"),
                                 "--quiet"])
    assert moved.exit_code == 0, moved.output
    assert (tmp_path / "moved" / "point_cloud.ply").read_bytes() == (tmp_path / "c" / "point_cloud.ply").read_bytes()
    # a run started with a relative DATASET resumes from any working folder (paths are kept absolute)
    cwd = os.getcwd()
    try:
        os.chdir(tiny_diffuse_dir.parent)
        rel = runner.invoke(main, ["train", tiny_diffuse_dir.name, "--config", str(cfg), "--set", "iterations=3",
                                   "--set", "checkpoint_every=2", "--quiet", "--out", str(tmp_path / "rel")])
        assert rel.exit_code == 0, rel.output
        os.chdir(tmp_path)  # somewhere else than where it started
        (tmp_path / "rel" / "point_cloud.ply").unlink()
        again_rel = runner.invoke(main, ["train", "--resume", str(tmp_path / "rel" / "checkpoints" / "iteration_2.pt"),
                                         "--quiet"])
        assert again_rel.exit_code == 0, again_rel.output
    finally:
        os.chdir(cwd)
    assert (tmp_path / "rel" / "point_cloud.ply").read_bytes() == (tmp_path / "c" / "point_cloud.ply").read_bytes()
    # a config that differs is refused naming every field that differs, and the way out
    other = runner.invoke(main, ["train", "--set", "iterations=4", "--set", "seed=7", "--resume", str(checkpoint),
                                 "--quiet", "--out", str(tmp_path / "d")])
    assert other.exit_code == 2 and len(other.stderr.strip().splitlines()) == 1, other.stderr
    assert "was written with seed=0, iterations=3; this run has seed=7, iterations=4 (" in other.stderr, other.stderr
    assert f"--resume {checkpoint} alone, with no --config or --set," in other.stderr
    nothing = runner.invoke(main, ["train", "--quiet"])
    assert nothing.exit_code == 2 and nothing.stderr.strip().startswith("splatbench: error: DATASET: give the "
                                                                        "dataset folder"), nothing.stderr
    ply = checkpoint.with_suffix(".ply")   # the model beside it, given by mistake: pointed to the .pt
    wrong = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                                 "--resume", str(ply), "--quiet", "--out", str(tmp_path / "w")])
    assert wrong.exit_code == 2 and wrong.stderr.strip() == (
        f"splatbench: error: resume: {str(ply)!r} is not a readable checkpoint (not torch's zip archive: "
        f"BadZipFile); the checkpoint is the .pt file beside it: --resume {checkpoint}"), wrong.stderr
    (tmp_path / "junk.pt").write_bytes(b"not a pickle")   # no .pt beside it: where checkpoints live
    junk = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                                "--resume", str(tmp_path / "junk.pt"), "--quiet", "--out", str(tmp_path / "j")])
    assert junk.exit_code == 2 and len(junk.stderr.strip().splitlines()) == 1, junk.stderr
    assert junk.stderr.strip().endswith("; checkpoints are the checkpoints/iteration_<step>.pt files "
                                        "of a run's output folder"), junk.stderr
    gone = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                                "--resume", str(tmp_path / "none.pt"), "--quiet", "--out", str(tmp_path / "g")])
    assert gone.exit_code == 2 and gone.stderr.strip() == \
        f"splatbench: error: resume: no such checkpoint {str(tmp_path / 'none.pt')!r}"
    # with the progress bar, the line comes once, on stderr, as the run starts (before the bar),
    # and the bar counts on from the checkpoint's step; the summary does not repeat it
    shown = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                                 "--resume", str(checkpoint), "--out", str(tmp_path / "s")])
    assert shown.exit_code == 0, shown.output
    line = f"resumed from {checkpoint} at step 2 of 3"
    assert shown.stderr.startswith(line + "\n") and shown.stderr.count("resumed from") == 1
    assert "3/3" in shown.stderr and "1/3" not in shown.stderr and "resumed from" not in shown.stdout
    # the summary says what its time covers: the checkpoint's steps, timed by the run that wrote it
    assert re.search(r"^3 iterations \(2 before the checkpoint, 1 in this resumed run\) "
                     r"in \d+\.\d s in all \(", shown.stdout, re.M), shown.stdout
    fresh = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                                 "--quiet", "--out", str(tmp_path / "f")])
    assert fresh.exit_code == 0 and re.search(r"^3 iterations in \d+\.\d s ", fresh.stdout, re.M), fresh.output
    assert re.search(r"^3 iterations in .* MB, rasterized on (cpu \(Dr\.Jit LLVM\)|cuda \(Dr\.Jit CUDA\))$",
                     fresh.stdout, re.M), fresh.stdout  # what device=auto resolved to
    # --quiet: no bar and no line as it starts; the summary's notes carry it
    quiet = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--config", str(cfg), "--set", "iterations=3",
                                 "--resume", str(checkpoint), "--quiet", "--out", str(tmp_path / "q")])
    assert quiet.exit_code == 0, quiet.output
    assert f"note: {line}" in quiet.stdout.splitlines() and "resumed from" not in quiet.stderr


def test_cli_rejects_graphdecos_absolute_schedule_on_a_short_run_before_reading_data(tmp_path, tiny_diffuse_dir):
    from splatbench.cli import main

    runner = CliRunner()
    # no dataset exists at this path: the schedule is rejected before any data is read
    bad = runner.invoke(main, ["train", str(tmp_path / "missing"), "--set", "iterations=600", "--set",
                               "schedule=absolute", "--quiet"])
    assert bad.exit_code == 2
    line = bad.stderr.strip()
    assert line.splitlines() == [line] and "refine window 500..15000" in line and "final 10 %" in line
    # the scaled default (refine 0..10, opacity reset every 2 of 20 steps) trains
    ok = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--set", "iterations=20", "--set", "init=random",
                              "--set", "init.random_points=300", "--json", "--quiet", "--out", str(tmp_path / "o")])
    assert ok.exit_code == 0, ok.output
    assert json.loads(ok.stdout.strip().splitlines()[-1])["iterations"] == 20


# ----------------------------------------------------------------------------- benchmark harness
def test_bench_train_reports_throughput_and_a_time_split_that_adds_up(tmp_path):
    from splatbench.metrics.machine import machine_info
    from splatbench.bench.train import TrainBenchSettings, format_table, run_size, write_csv, write_json

    settings = TrainBenchSettings(sizes=(16,), gaussians=60, views=3, iterations=3, warmup=1)
    settings.validate()
    r = run_size(16, settings)
    assert (r.width, r.n, r.iterations, len(r.step_runs_ms)) == (16, 60, 3, 3)
    # seconds is rounded to 1 ms, so 3 / seconds carries a relative error up to 0.5 ms / seconds
    # (over 1 % when 3 tiny steps take ~30 ms); it_per_s itself is rounded to 1e-3.
    assert r.it_per_s == pytest.approx(3 / r.seconds, rel=5e-4 / r.seconds + 1e-4, abs=1e-3)
    shares = r.raster_forward_pct + r.raster_backward_pct + r.loss_pct + r.optimizer_pct + r.other_pct
    assert shares == pytest.approx(100, abs=0.5)
    assert "16x16" in format_table([r])
    write_csv([r], tmp_path / "train.csv")
    write_json([r], machine_info("cpu"), settings, tmp_path / "train.json")
    assert json.loads((tmp_path / "train.json").read_text())["results"][0]["n"] == 60
    with pytest.raises(InputError, match="--iterations"):
        TrainBenchSettings(iterations=0).validate()


def test_a_step_after_warm_up_compiles_no_kernel_for_a_new_view():
    """Issue #12: no per-step kernel recompilation. After `Trainer.warm_up` and two steps,
    a step on a view not seen yet (another camera, learning rate, background) runs only
    kernels Dr.Jit finds in its in-memory cache: nothing per step is baked into a kernel."""
    import drjit as dr

    from splatbench.bench.train import synthetic_scene

    dataset, _ = synthetic_scene(24, 60, 4, 0)
    cfg = TrainConfig(dataset="", out="", iterations=10, schedule="absolute", seed=0, device="cpu", strategy=StrategyConfig(name="none"), sh=SHConfig(degree=3, interval=1))
    trainer = Trainer(cfg, dataset=dataset)
    trainer.warm_up()
    trainer.step()
    trainer.step()  # views are drawn without replacement per epoch: the next step's view is new
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # clears it
        trainer.step()
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    jit = [k for k in history if k["type"] == dr.KernelType.JIT]
    # cache_hit is also set for a kernel loaded from ~/.drjit; cache_disk marks those loads
    assert jit and all(k.get("cache_hit") and not k.get("cache_disk") for k in jit), \
        [(k.get("cache_hit"), k.get("cache_disk"), k.get("size")) for k in jit]


def test_psnr_is_one_function_for_tensors_and_float64_arrays():
    """`train.metrics.psnr` is the only PSNR (the raster run kind calls it with clamp=False)."""
    from splatbench.metrics.image import psnr

    a = np.full((4, 4, 3), 1.5)          # above 1: only the clamp can bring it to the target
    b = np.full((4, 4, 3), 0.9)
    assert psnr(a, b) == pytest.approx(-10 * np.log10(0.01))            # clamped to 1: MSE 0.1²
    assert psnr(a, b, clamp=False) == pytest.approx(-10 * np.log10(0.36))  # MSE 0.6²
    assert psnr(torch.as_tensor(b, dtype=torch.float32), torch.as_tensor(b, dtype=torch.float32)) == np.inf


def test_frozen_means_with_a_gradient_densifier_is_one_line():
    # the rasterizer's backward skips the screen-space mean gradient of frozen means
    # (tests/test_raster_frozen.py), which the default strategy densifies from
    from splatbench.train import TrainConfig

    with pytest.raises(InputError, match="optim.lr_means: 0 freezes the means, but strategy 'default' densifies"):
        TrainConfig(dataset="d", out="o", optim=OptimConfig(lr_means=0.0, lr_means_final=0.0))
    TrainConfig(dataset="d", out="o", optim=OptimConfig(lr_means=0.0, lr_means_final=0.0), strategy=StrategyConfig(name="mcmc"))  # no screen gradient used


def test_frozen_means_check_follows_the_strategys_declaration(monkeypatch):
    # the check reads the Strategy protocol's reads_mean_gradients, not the strategy's class:
    # a default-like strategy declaring that it reads no mean gradient is accepted with frozen
    # means, a no-op one declaring that it does is refused, and the error lists the strategies
    # that would do
    import dataclasses
    from typing import ClassVar

    from splatbench.strategies import STRATEGIES, DefaultStrategy, NoneStrategy
    from splatbench.train import TrainConfig

    @dataclasses.dataclass(frozen=True)
    class Gradless(DefaultStrategy):
        reads_mean_gradients: ClassVar[bool] = False

    @dataclasses.dataclass(frozen=True)
    class Reader(NoneStrategy):
        reads_mean_gradients: ClassVar[bool] = True

    monkeypatch.setitem(STRATEGIES, "gradless", (Gradless, {}))
    monkeypatch.setitem(STRATEGIES, "reader", (Reader, {}))
    frozen = dict(dataset="d", out="o", optim=OptimConfig(lr_means=0.0, lr_means_final=0.0))
    assert TrainConfig(**frozen, strategy=StrategyConfig(name="gradless")).strategy.name == "gradless"
    with pytest.raises(InputError) as err:
        TrainConfig(**frozen, strategy=StrategyConfig(name="reader"))
    assert str(err.value) == ("optim.lr_means: 0 freezes the means, but strategy 'reader' densifies from their screen-space "
                              "gradients (use a positive optim.lr_means, or strategy=none or mcmc or gradless)")


def test_a_model_pruned_to_nothing_trains_on_and_says_so(tmp_path, tiny_diffuse):
    # every Gaussian starts below the prune threshold (opacity 0.001 < 0.005), so the first
    # refinement (step 4) removes them all; the run must go on (an empty model steps: empty
    # gradients) and its result must say that the model is empty and from when. alpha_min is
    # lowered below that opacity (at the default 1/255 > 0.001 the config is refused: nothing
    # would render or get a gradient)
    from splatbench.raster.options import RasterOptions

    opts = {"refine_start": 4, "refine_every": 5, "refine_stop": 8}
    r = train(config(tmp_path, iterations=12, log_every=1, raster=RasterOptions(alpha_min=5e-4), strategy=StrategyConfig(name="default", options=opts), init=InitConfig(opacity=0.001)), dataset=tiny_diffuse)
    assert r.num_gaussians == 0 and r.iterations == 12
    warning = [n for n in r.warnings if n.startswith("warning: the model is empty")]
    assert len(warning) == 1 and "none left from step 4 on" in warning[0]


def test_surface_init_without_points_is_one_line_naming_the_ways_out(tiny_diffuse_dir):
    """init=surface means the dataset's points: a capture without any (transforms.json) is refused
    in one line naming auto / sfm / random, never silently started from random points."""
    from splatbench.train.initializers import InitSettings, initialize
    no_points = dataclasses.replace(load_dataset(tiny_diffuse_dir), points=None)
    with pytest.raises(InputError) as err:
        initialize("surface", no_points, InitSettings(sh_degree=0, opacity=0.1, random_points=50, seed=0))
    text = str(err.value)
    assert "\n" not in text and "needs the dataset's points" in text and "init=auto" in text and "init=random" in text


def test_auto_init_starts_from_the_dataset_points_or_else_sfm_with_known_poses(tiny_diffuse, monkeypatch):
    """The default: the dataset's own points when it has them; else SfM with the dataset's poses
    (never random); the summary says what ran and that auto chose it, a note says why."""
    import splatbench.sfm as sfm_module
    from splatbench.sfm import SfmRun, Similarity
    from splatbench.train.initializers import InitSettings, initialize

    assert TrainConfig().init.method == "auto" and TrainConfig().init.sfm_poses == "known"
    settings = InitSettings(sh_degree=0, opacity=0.1, random_points=50, seed=0)
    have = initialize("auto", tiny_diffuse, settings)
    assert have.summary["method"] == "surface" and have.summary["asked"] == "auto"
    np.testing.assert_array_equal(have.gaussians.means, tiny_diffuse.points.xyz.astype(np.float32))  # jitter 0
    assert have.note.startswith("init auto: surface (the dataset's own points")
    calls = []
    xyz = np.random.default_rng(0).normal(size=(40, 3))

    def fake(dataset, **kw):  # what SfM returns is tested in tests/test_sfm_init.py; here, what auto asks
        calls.append(kw["poses"])
        return SfmRun(7, 7, 0.0, 1.0, xyz, np.zeros((40, 3), np.uint8), Similarity(1.0, np.eye(3), np.zeros(3)),
                      Path("m/0"), 1, [], 0.1, kw["poses"]), True

    monkeypatch.setattr(sfm_module, "cached_sfm", fake)
    none = initialize("auto", dataclasses.replace(tiny_diffuse, points=None), settings)
    assert calls == ["known"] and none.summary["method"] == "sfm" and none.summary["asked"] == "auto"
    assert none.summary["poses"] == "known" and len(none.gaussians) == 40
    assert none.note.startswith("init auto: sfm (SfM with known poses: the dataset has no point cloud")


def _starts(tmp_path, dataset, **fields):
    """The initial means [N, 3] of a Trainer built with ``fields`` (nothing trained)."""
    return Trainer(config(tmp_path, **fields), dataset=dataset).params["means"].detach().numpy().copy()


def test_seeds_vary_the_default_start_of_a_rendered_scene(tmp_path, tiny_diffuse):
    """Issue 29 item 3: a seed varies what a rerun varies, the start included. Under the default
    init (a rendered scene: its surface points) two seeds start from different points, the same
    seed from the same points; the jitter is a fraction of each point's neighbour spacing, so the
    cloud stays where the surfaces are."""
    from splatbench.gaussians_from_points import knn_mean_sq_dist

    a0, a0_again, a1 = (_starts(tmp_path, tiny_diffuse, seed=s) for s in (0, 0, 1))
    np.testing.assert_array_equal(a0, a0_again)
    moved = np.linalg.norm(a0 - a1, axis=1)
    assert (moved > 0).mean() > 0.99
    given = tiny_diffuse.points.xyz
    spacing = np.sqrt(knn_mean_sq_dist(given))
    # each coordinate moves by N(0, (0.5 spacing)^2): |offset| / spacing is 0.5 x a chi with 3 degrees of
    # freedom (mean 0.5 x 1.596 = 0.80); two seeds differ by sqrt(2) x that. Its mean over 1500 points is
    # within 0.05 of 1.128 (the chi's standard deviation is 0.67, /sqrt(1500) x sqrt(2) x 0.5 ~ 0.012)
    assert abs(np.mean(moved / spacing) - 0.5 * math.sqrt(2) * 1.5958) < 0.05
    assert np.abs(a0 - given).max() < 6 * 0.5 * spacing.max()  # never beyond 6 standard deviations
    plain = _starts(tmp_path, tiny_diffuse, seed=1, init=InitConfig(jitter=0.0))  # 0: the points as given, any seed
    np.testing.assert_array_equal(plain, given.astype(np.float32))
    r0, r0_again, r1 = (_starts(tmp_path, tiny_diffuse, seed=s, init=InitConfig(method="random", random_points=300))
                        for s in (0, 0, 1))
    np.testing.assert_array_equal(r0, r0_again)
    assert not np.allclose(r0, r1)


def _rig(eyes, target, size=(64, 48), fov=50.0):
    return [Camera.look_at(e, target, [0, 1, 0], size[0], size[1], fov) for e in eyes]


def _posed(cams, root=Path("."), layout="colmap") -> Dataset:
    images = np.zeros((len(cams), cams[0].height, cams[0].width, 3), np.float32)
    split = Split(images, cams, None, [f"v{i}.png" for i in range(len(cams))])
    return Dataset("rig", split, Split(images[:0], [], None, []), None, root, layout)


def test_random_init_samples_where_the_inward_cameras_look(tmp_path):
    """Cameras on a ring of radius 4 around (5, 1, -2), looking at it (the scene is there, not
    in the box of the camera centres, which surrounds it only by chance of the ring). auto picks
    the convergence ball: centred on the meeting point, radius 4 tan(half the narrower fov)."""
    from splatbench.train.initializers import InitSettings, initialize, random_region

    target = np.array([5.0, 1.0, -2.0])
    eyes = [target + 4 * np.array([math.cos(a), 0.3, math.sin(a)]) / math.hypot(1, 0.3)
            for a in np.linspace(0, math.pi, 9)]  # a half ring: the centres' box misses the target
    ds = _posed(_rig(eyes, target))
    cams = ds.train.cameras
    region = random_region(ds, "auto")
    half_fov = math.atan(0.5 * cams[0].height / cams[0].fy)  # 48 px high: the narrower
    assert region.chosen == "convergence" and region.shape == "ball"
    np.testing.assert_allclose(region.center, target, atol=1e-9)
    assert abs(region.size - 4 * math.tan(half_fov)) < 1e-9 and "convergence" in region.note
    init = initialize("random", ds, InitSettings(sh_degree=0, opacity=0.1, random_points=4000, seed=3))
    pts = init.gaussians.means.astype(np.float64)
    dist = np.linalg.norm(pts - target, axis=1)
    assert dist.max() <= region.size * (1 + 1e-6)
    # uniform in the ball: the fraction within half the radius is 1/8 (binomial sd 0.0052 at n = 4000)
    assert abs(np.mean(dist < region.size / 2) - 0.125) < 0.025
    assert init.summary["region"] == "convergence" and init.summary["method"] == "random"
    # the ball lies in each view: in front of every camera, and inside its image but for the rim
    # of the ball nearer the camera (the ball's tangent cone has half-angle asin(tan h) > h: at
    # h = 25.6 deg a few per cent of the volume lies outside the cone of half-angle h)
    for cam in cams:
        uv, z = cam.project(pts)
        inside = (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] <= cam.width) & (uv[:, 1] <= cam.height)
        assert (z > 0).all() and inside.mean() > 0.95, inside.mean()
    # gsplat's cube: +-3 scene scales around the centroid of the centres
    from splatbench.train.params import scene_extent

    cube = random_region(ds, "camera_cube")
    centres = np.stack([c.center for c in cams])
    np.testing.assert_allclose(cube.center, centres.mean(0))
    assert cube.shape == "cube" and abs(cube.size - 3 * scene_extent(cams)) < 1e-9
    assert abs(random_region(ds, "camera_cube", extent=2.0).size - 2 * scene_extent(cams)) < 1e-9
    nerf = random_region(ds, "nerf_synthetic")
    assert nerf.shape == "cube" and nerf.size == 1.3 and not nerf.center.any()


def test_random_init_on_a_nerf_synthetic_layout_is_graphdecos_box(tmp_path):
    """transforms_train.json with cameras on a sphere of radius 4 looking at the origin: graphdeco's
    [-1.3, 1.3]^3 (auto says so); the same rig in a COLMAP folder gets the convergence ball."""
    from splatbench.train.initializers import InitSettings, initialize, random_region

    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(20, 3))
    dirs[:, 1] = np.abs(dirs[:, 1])
    eyes = 4.03 * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    (tmp_path / "transforms_train.json").write_text("{}")
    ds = _posed(_rig(eyes, np.zeros(3), size=(32, 32), fov=39.6), tmp_path, "blender")
    region = random_region(ds, "auto")
    assert region.chosen == "nerf_synthetic" and "graphdeco" in region.note
    init = initialize("random", ds, InitSettings(sh_degree=0, opacity=0.1, random_points=2000, seed=0))
    pts = init.gaussians.means
    assert np.abs(pts).max() <= 1.3 + 1e-6 and np.abs(pts).max() > 1.2  # fills the box
    assert random_region(_posed(ds.train.cameras, tmp_path, "colmap"), "auto").chosen == "convergence"


def test_random_init_on_a_forward_facing_rig_says_no_region_contains_the_scene(tmp_path):
    """Cameras on a small patch all looking down -z (the `far` scene's kind of rig): no meeting
    point, so convergence is refused in one line, and auto falls back to gsplat's cube with a
    warning that names the problem (never silently)."""
    from splatbench.train.initializers import InitSettings, initialize, random_region

    eyes = [np.array([x, y, 0.0]) for x in (-0.3, 0.0, 0.3) for y in (-0.2, 0.2)]
    cams = [Camera.look_at(e, e + np.array([0.02 * e[0], 0.0, -1.0]), [0, 1, 0], 64, 48, 55) for e in eyes]
    ds = _posed(cams)
    with pytest.raises(InputError) as err:
        random_region(ds, "convergence")
    assert "\n" not in str(err.value) and "forward-facing" in str(err.value)
    said = []
    init = initialize("random", ds, InitSettings(sh_degree=0, opacity=0.1, random_points=100, seed=0,
                                                say=said.append))
    assert init.summary["region"] == "camera_cube"
    assert init.note.startswith("warning:") and "forward-facing" in init.note and said == [init.note]
    assert init.warning  # a run keeps it among its warnings (TrainResult.warnings), not its notes
    asked = initialize("random", ds, InitSettings(sh_degree=0, opacity=0.1, random_points=100, seed=0,
                                                  region="camera_cube"))
    assert not asked.warning and asked.summary["region"] == "camera_cube"  # asked for: nothing to warn of


def test_train_says_the_init_choice_live_before_the_bar_and_only_once(tmp_path, tiny_diffuse_dir):
    """`init_region auto: ...` / `init auto: ...` go to stderr as the start is made (ahead of the
    progress bar), with --json too, and are not printed again among the final notes."""
    from click.testing import CliRunner

    from splatbench.cli import main

    for extra in (["--json"], []):
        res = CliRunner().invoke(main, ["train", str(tiny_diffuse_dir), "--out", str(tmp_path / f"r{len(extra)}"),
                                        "--set", "init='random'", "--set", "iterations=2", "--set", "sh.degree=0",
                                        "--set", "strategy='none'", *extra])
        assert res.exit_code == 0, res.output
        err = [line for line in res.stderr.splitlines() if line.strip()]
        said = [i for i, line in enumerate(err) if line.startswith("init.region auto: ")]
        bar = next(i for i, line in enumerate(err) if line.startswith("train"))
        assert len(said) == 1 and said[0] < bar, res.stderr
        if extra:  # still among the result's notes
            assert err[said[0]] in json.loads(res.stdout)["notes"]
        else:  # not printed again at the end
            assert "init.region auto" not in res.stdout


def test_auto_init_note_separates_its_choice_from_the_sfm_result(tiny_diffuse, monkeypatch):
    """init=auto falling back to SfM: one note, said once, "...random points); SfM: ..."."""
    import splatbench.sfm as sfm_module
    from splatbench.sfm import SfmRun, Similarity
    from splatbench.train.initializers import InitSettings, initialize

    xyz = np.random.default_rng(0).normal(size=(40, 3))
    monkeypatch.setattr(sfm_module, "cached_sfm", lambda dataset, **kw: (SfmRun(
        7, 7, 0.0, 1.0, xyz, np.zeros((40, 3), np.uint8), Similarity(1.0, np.eye(3), np.zeros(3)), Path("m/0"), 1, [],
        0.1, kw["poses"]), True))
    said: list[str] = []
    init = initialize("auto", dataclasses.replace(tiny_diffuse, points=None),
                      InitSettings(sh_degree=0, opacity=0.1, random_points=50, seed=0, say=said.append))
    assert said == [init.note] and "init=random for random points); SfM: 40 points" in init.note


def test_train_help_lists_the_protocols_inits_and_random_regions():
    """`splatbench train --help` names every choice of protocol, init and init.region (the
    help is written out, so that --help does not import torch: this keeps it in step)."""
    from splatbench.cli import main
    from splatbench.train.initializers import INITIALIZERS, REGIONS
    from splatbench.train.protocol import PROTOCOLS

    text = " ".join(CliRunner().invoke(main, ["train", "--help"]).output.split())
    for label, names in (("protocol:", PROTOCOLS), ("init (init.method):", ("auto", "surface", "sfm", "random")),
                         ("init.region (init=random):", REGIONS)):
        listed = text.split(label, 1)[1].split(";")[0].split(". ")[0]
        assert all(re.search(rf"\b{re.escape(n)}\b", listed) for n in names), (label, listed)
    assert set(INITIALIZERS) >= {"auto", "surface", "sfm", "random"}


def test_opacity_resets_closer_than_an_opacity_can_recover_are_warned_about():
    """A new user's 100-step run under the quick protocol reset opacities every 10 steps (graphdeco's
    3,000 scaled) and said nothing of it. The warning fires where the climb from the reset value back
    to opacity 0.5 (`opacity_recovery_steps`) takes longer than the spacing of the resets, and not on
    the committed 2,000-step grids (every 200: 81 steps), at graphdeco's schedule or without resets."""
    from splatbench.strategies import ops
    from splatbench.train.adam import FusedAdam
    from splatbench.train.config import opacity_recovery_steps

    (line,) = apply_overrides(TrainConfig(), ["iterations=100"]).warnings()
    assert line.startswith("warning: strategy 'default' resets opacities every 10 steps in this run, sooner than "
                           "an opacity can climb back from the reset value 0.01 to 0.5 (176 steps") and "\n" not in line
    assert 'strategy.reset_every = 0' in line
    # no fraction of a 100-step run is 176 steps long: that way out is offered only where one is
    assert '("50%")' not in line
    (longer,) = apply_overrides(TrainConfig(), ["iterations=600"]).warnings()  # resets every 60 steps
    assert 'or a fraction of the run ("50%") at least' in longer
    quiet = ["iterations=2000", "iterations=30000", "protocol=graphdeco-7k", "strategy=mcmc",
             "strategy.reset_every=0", 'strategy.reset_every="50%"']
    for way in quiet:
        assert apply_overrides(TrainConfig(), ["iterations=100", way]).warnings() == [], way
    for every in ("10%", "20%"):  # densification_schedules' cells at 2,000 steps
        assert apply_overrides(TrainConfig(), ["iterations=2000", f'strategy.reset_every="{every}"']
                               ).warnings() == []
    # the climb is the project's own Adam's: a steady gradient after a reset (moments zeroed, step count kept)
    for reset_step in (10, 200):
        p = torch.nn.Parameter(torch.full((1,), 2.0))
        params = {"opacity_logits": p}
        optimizers = {"opacity_logits": FusedAdam(p, lr=0.025, eps=1e-15, name="opacity_logits")}
        for _ in range(reset_step):
            params["opacity_logits"].grad = torch.full((1,), 0.3)
            optimizers["opacity_logits"].step()
        ops.reset_opacity(params, optimizers, 0.01)
        steps = 0
        while params["opacity_logits"].item() < 0.0:
            params["opacity_logits"].grad = torch.full((1,), -1.0)
            optimizers["opacity_logits"].step()
            steps += 1
        assert steps == opacity_recovery_steps(0.025, 0.01, reset_step)


def test_paths_in_a_config_file_are_relative_to_the_file(tmp_path, tiny_diffuse_dir, monkeypatch):
    """`train --config` reads a relative `dataset` / `out` from the config file's folder (as an
    experiment file's paths), and keeps them absolute, so its checkpoint resumes from any folder."""
    import os

    from splatbench.cli import main

    conf = tmp_path / "conf"
    conf.mkdir()
    rel = os.path.relpath(tiny_diffuse_dir, conf)
    (conf / "c.toml").write_text(f'dataset = "{rel}"\nout = "run"\niterations = 2\n[strategy]\nname = "none"\n'
                                 f'[eval]\nlpips_net = "none"\n', encoding="utf-8")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # the working folder is neither the file's nor the dataset's
    res = CliRunner().invoke(main, ["train", "--config", str(conf / "c.toml"), "--json"])
    assert res.exit_code == 0, res.output
    written = load_config(conf / "run" / "config.toml")
    assert written.dataset == str(tiny_diffuse_dir.resolve()) and written.out == str((conf / "run").resolve())
