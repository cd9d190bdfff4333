"""Training takes the rasterizer's options (issue 31 §2): ``TrainConfig.raster``.

``--set raster.alpha_min=0.005`` / a ``[raster]`` table / a grid's ``raster.*`` keys become one
`RasterOptions`, checked once (unknown keys, types, ranges: one line naming ``raster.KEY``);
every render of a run (training step, warm-up, SH probe, evaluation) uses it; the run records
it (config.toml, result.json, ``--json``; a grid's records and table rows); and the run ids of
configs that set no raster option are the ids they had before (committed results are keyed by
them).
"""

from __future__ import annotations

import dataclasses
import inspect
import json

import pytest
import torch
from click.testing import CliRunner

from splatbench.errors import InputError
from splatbench.experiments.configs import flatten
from splatbench.experiments.grid import expand, make_run_id
from splatbench.experiments.spec import parse_experiment
from splatbench.experiments.store import RunRecord
from splatbench.experiments.train_kind import TRAIN
from splatbench.raster.options import RasterOptions
from splatbench.train import TrainConfig, apply_overrides, load_config, save_config, train
from splatbench.train.config import RASTER_KEYS, EvalConfig, SHConfig
from splatbench.train.loop import Trainer, torch_threads
from tests.test_train import config, synthetic_dataset, tiny_diffuse_dir  # noqa: F401 (a fixture)

DEFAULT_ALPHA_MIN = 0.00392156862745098  # 1/255 as a TOML file writes it (the same float64)


# ----------------------------------------------------------------------------- the config
def test_raster_keys_are_set_one_at_a_time_and_round_trip_through_toml(tmp_path):
    cfg = apply_overrides(TrainConfig(), ["raster.alpha_min=0.008", "raster.tile_size=8", "raster.radius=opacity",
                                          "raster.eps2d=1", "raster.near=0.05"])
    assert cfg.raster == RasterOptions(alpha_min=0.008, tile_size=8, radius="opacity", eps2d=1.0, near=0.05)
    assert isinstance(cfg.raster.eps2d, float)                   # an int widens where a float is declared
    path = save_config(cfg, tmp_path / "c.toml")
    text = path.read_text(encoding="utf-8")
    assert "[raster]" in text and "alpha_min = 0.008" in text and "device" not in text.split("[raster]")[1]
    assert load_config(path) == cfg
    # a dotted key edits one option; the others (from the file) stay
    again = apply_overrides(load_config(path), ["raster.tile_size=4"])
    assert again.raster == dataclasses.replace(cfg.raster, tile_size=4)
    assert TrainConfig().raster == RasterOptions()               # nothing set: graphdeco's defaults


def test_a_small_tile_set_alone_takes_its_default_block_and_a_block_given_stays():
    """`raster.pixel_block` is at most the tile (a larger one is refused, not capped): a
    `--set raster.tile_size=2` on a config that never set the block takes the tile's default
    (2, recorded as such) rather than an error about a block the user never gave; back at 16,
    the default 4; a block the config gives stays, and one too large for the tile is named."""
    small = apply_overrides(TrainConfig(), ["raster.tile_size=2"])
    assert (small.raster.tile_size, small.raster.pixel_block) == (2, 2)
    assert small.to_dict()["raster"]["pixel_block"] == 2
    back = apply_overrides(small, ["raster.tile_size=16"])
    assert back.raster == RasterOptions() and back.raster.pixel_block == 4
    given = apply_overrides(TrainConfig(), ["raster.pixel_block=2"])
    assert apply_overrides(given, ["raster.tile_size=8"]).raster.pixel_block == 2
    assert apply_overrides(given, ["raster.tile_size=2"]).raster.pixel_block == 2
    with pytest.raises(InputError) as info:
        apply_overrides(TrainConfig(), ["raster.tile_size=2", "raster.pixel_block=4"])
    assert str(info.value) == ("raster.pixel_block: at most tile_size (2), got 4; use pixel_block <= 2, or leave it "
                               "out (the default follows a smaller tile)")


@pytest.mark.parametrize("override, message", [
    ("raster.alpha_mn=0.1", "raster.alpha_mn: unknown key (did you mean 'alpha_min'?)"),
    ("raster.bogus=1", "raster.bogus: unknown key (known: alpha_max, alpha_min, antialiased, eps2d, far, near, "
                       "pixel_block, radius, tile_size, transmittance_min)"),
    ("raster.tile_size=12", "raster.tile_size: expected a power of two in [1, 64], got 12"),
    ("raster.tile_size=8.0", "raster.tile_size: expected an int, got 8.0"),
    ("raster.alpha_min=x", "raster.alpha_min: expected a finite number, got 'x'"),
    ("raster.alpha_min=0.995", "raster.alpha_min: expected a value in (0, alpha_max), got 0.995"),
    ("raster.radius=4sigma", "raster.radius: expected one of ('3sigma', 'opacity'), got '4sigma'"),
    ("raster=3", "raster: expected a table of rasterizer options (" + ", ".join(RASTER_KEYS) + "), got 3"),
])
def test_a_bad_raster_key_is_one_line_naming_it(override, message):
    with pytest.raises(InputError) as info:
        apply_overrides(TrainConfig(), [override])
    assert str(info.value) == message


def test_clip_planes_in_the_wrong_order_are_refused_before_anything_is_written():
    # a new user's `--set raster.near=0.5 --set raster.far=0.1` used to fail only at the first render,
    # after config.toml was written, naming "near, far" rather than the key
    with pytest.raises(InputError) as info:
        apply_overrides(TrainConfig(), ["raster.near=0.5", "raster.far=0.1"])
    assert str(info.value) == "raster.near: expected a value below far (0.1), got 0.5"


def test_the_device_is_set_once_by_device():
    """``raster.device`` is not a setting: it always equals ``TrainConfig.device``."""
    with pytest.raises(InputError, match=r"^raster\.device: the rasterizer runs on the run's `device`"):
        apply_overrides(TrainConfig(), ["raster.device=cuda"])
    cfg = TrainConfig(device="cpu", raster=RasterOptions(alpha_min=0.008))
    assert cfg.raster == RasterOptions(alpha_min=0.008, device="cpu")
    assert dataclasses.replace(cfg, device="auto").raster.device == "auto"   # moved together
    assert apply_overrides(cfg, ["device=auto"]).raster == RasterOptions(alpha_min=0.008, device="auto")
    assert "device" not in cfg.to_dict()["raster"]
    with pytest.raises(InputError, match=r"^raster: expected RasterOptions"):
        TrainConfig(raster={"alpha_min": 0.02})                   # the constructor takes the typed record


# ----------------------------------------------------------------------------- the trainer
class OptionsSpy:
    """Stands in for `splatbench.rasterize` in the trainer: records, per call, the trainer
    method that rendered and the `RasterOptions` it passed."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, RasterOptions]] = []

    def __call__(self, *args, **kwargs):
        from splatbench.raster.torch_bridge import rasterize

        caller = inspect.stack()[2].function  # rasterize <- Trainer._render <- the render's purpose
        assert isinstance(kwargs["options"], RasterOptions)  # the config's typed record, as it is
        self.calls.append((caller, kwargs["options"]))
        return rasterize(*args, **kwargs)


def test_every_render_of_a_run_uses_the_configs_raster_options(tmp_path, monkeypatch):
    spy = OptionsSpy()
    monkeypatch.setattr("splatbench.train.loop.rasterize", spy)
    options = RasterOptions(alpha_min=0.02, tile_size=8, radius="opacity")
    # auto SH (a probe every 2 steps), an evaluation every 3 steps and the final one
    cfg = config(tmp_path, iterations=6, sh=SHConfig(degree="auto", interval=2, auto_probe_views=2),
                 eval=EvalConfig(every=3, lpips_net="none"), device="cpu", raster=options)
    result = train(cfg, dataset=synthetic_dataset(tmp_path, view_dependent=True))
    callers = {caller for caller, _ in spy.calls}
    assert {"step", "warm_up", "probe_band", "evaluate"} <= callers, callers
    assert all(opts == dataclasses.replace(options, device="cpu") for _, opts in spy.calls)
    # the run records them: result.json / --json and config.toml
    assert result.raster == dataclasses.replace(options, device="cpu")
    assert json.loads((tmp_path / "run" / "result.json").read_text())["raster"]["tile_size"] == 8
    assert load_config(tmp_path / "run" / "config.toml").raster == cfg.raster


def test_alpha_min_reaches_the_kernel_and_changes_the_training_step(tmp_path):
    """Every initial Gaussian has opacity 0.1 (strategy "none": graphdeco's initial opacity), and
    alpha = opacity x G: with alpha_min = 0.09 compositing keeps only the cores where G > 0.9,
    so the render shows much less of each Gaussian than with the default 1/255 (more
    background), and the first step's loss differs."""
    ds = synthetic_dataset(tmp_path, view_dependent=False)
    camera = ds.train.cameras[0]
    losses, renders = {}, {}
    default = RasterOptions().alpha_min
    for alpha_min in (default, 0.09):
        cfg = config(tmp_path, iterations=2, device="cpu", raster=RasterOptions(alpha_min=alpha_min))
        with torch_threads(1):
            trainer = Trainer(cfg, dataset=ds)
            assert cfg.initial_opacity == pytest.approx(0.1)
            with torch.no_grad():
                renders[alpha_min] = trainer._render(camera, 0, trainer.background.tolist())[1]  # alpha [H, W]
            losses[alpha_min] = trainer.step().loss
    # coverage: a Gaussian's footprint above alpha 1/255 reaches G = 1/25.5 (2.5 sigma), above
    # 0.09 only G = 0.9 (0.46 sigma): far less of the image is covered
    assert float(renders[0.09].sum()) < 0.5 * float(renders[default].sum())
    assert losses[0.09] != losses[default]


def test_an_alpha_min_at_or_above_the_initial_opacity_is_refused():
    """alpha = opacity x G never exceeds the opacity: with alpha_min at or above the initial
    opacity every Gaussian is skipped on every pixel from the first step and gets no gradient."""
    with pytest.raises(InputError) as info:
        apply_overrides(TrainConfig(), ["raster.alpha_min=0.1"])
    assert str(info.value).startswith("raster.alpha_min: 0.1 is at or above the initial opacity 0.1") \
        and "\n" not in str(info.value)
    apply_overrides(TrainConfig(), ["raster.alpha_min=0.1", "init.opacity=0.2"])  # the way out it names


def test_an_alpha_min_at_or_above_the_reset_value_is_warned_about():
    """After graphdeco's opacity reset (to 0.01) alpha <= 0.01 everywhere: with alpha_min 0.01 a
    60-step smoke run stopped learning at the first reset and rendered the background alone. The
    run is allowed (it may be the question asked) and says so in one line, kept in its warnings;
    the ways out the line names give no warning."""
    cfg = apply_overrides(TrainConfig(), ["iterations=2000", "raster.alpha_min=0.01"])
    (line,) = cfg.warnings()
    assert line.startswith("warning: raster.alpha_min=0.01 is at or above the opacity reset value 0.01 of "
                           "strategy 'default'") and "\n" not in line
    for way_out in ("strategy.reset_every=0", "strategy.reset_value=0.02", "strategy=mcmc",
                    "raster.alpha_min=0.008"):
        assert apply_overrides(cfg, [way_out]).warnings() == [], way_out
    assert TrainConfig().warnings() == []


def test_cli_train_records_the_raster_options(tmp_path, tiny_diffuse_dir):  # noqa: F811 (the fixture)
    from splatbench.cli import main

    runner = CliRunner()
    out = tmp_path / "o"
    res = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--set", "raster.alpha_min=0.01", "--set",
                               "raster.tile_size=8", "--set", "iterations=3", "--set", "strategy=none", "--set",
                               "eval.lpips_net=none", "--json", "--quiet", "--out", str(out)])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout.strip().splitlines()[-1])
    assert data["raster"]["alpha_min"] == 0.01 and data["raster"]["tile_size"] == 8
    assert load_config(out / "config.toml").raster == RasterOptions(alpha_min=0.01, tile_size=8)
    # the device as set ("auto") stays the config's (run ids); the device that ran is the result's, and a grid's
    # metric.device (a new user could not tell Dr.Jit's LLVM backend from CUDA)
    from splatbench.experiments.train_kind import TrainRun
    from splatbench.metrics.machine import resolve_device
    from splatbench.train import TrainResult

    assert data["raster"]["device"] == "auto" and load_config(out / "config.toml").device == "auto"
    assert data["device"] == resolve_device("auto") and data["device"] in ("cpu", "cuda")
    assert json.loads((out / "result.json").read_text())["device"] == data["device"]
    assert TrainRun.of(TrainResult.from_dict(data), None).device == data["device"]
    older = {k: v for k, v in data.items() if k != "device"}  # a result.json written before it was recorded
    assert TrainResult.from_dict(older).device == "" and TrainRun.of(TrainResult.from_dict(older), None).device is None
    bad = runner.invoke(main, ["train", str(tiny_diffuse_dir), "--set", "raster.alpah_min=0.01", "--quiet"])
    assert bad.exit_code == 2
    assert bad.stderr.strip().splitlines() == [bad.stderr.strip()]
    assert "raster.alpah_min: unknown key (did you mean 'alpha_min'?)" in bad.stderr


# ----------------------------------------------------------------------------- grids and run ids
def _id(config: dict) -> str:
    return make_run_id("train", TRAIN.identity(TRAIN.resolve(config)))


def test_raster_options_are_in_the_run_id():
    """The id hashes the resolved config with its whole ``raster`` table: options written at their
    defaults are the same run; a set one is a new run."""
    base = {"scene": "diffuse", "seed": 0, "iterations": 2000}
    resolved = TRAIN.resolve(base)
    assert resolved["raster"] == {k: v for k, v in RasterOptions().to_dict().items() if k != "device"}
    assert TRAIN.identity(resolved) == resolved
    assert _id({**base, "raster": {"alpha_min": DEFAULT_ALPHA_MIN, "tile_size": 16, "radius": "3sigma"}}) == _id(base)
    changed = TRAIN.identity(TRAIN.resolve({**base, "raster": {"alpha_min": 0.008}}))
    assert changed == {**resolved, "raster": {**resolved["raster"], "alpha_min": 0.008}}
    assert _id({**base, "raster": {"alpha_min": 0.008}}) != _id(base)


def test_a_grid_sweeps_raster_options_and_its_rows_carry_them():
    spec = {"name": "t", "kind": "train", "scenes": ["diffuse"], "seeds": [0], "base": {"iterations": 2000},
            "axes": {"raster": {"alpha_min": [DEFAULT_ALPHA_MIN, 0.008], "tile_size": [16, 8]}}}
    runs = expand(parse_experiment(spec))
    assert [tuple(r.labels.values()) for r in runs] == [(DEFAULT_ALPHA_MIN, 16), (DEFAULT_ALPHA_MIN, 8),
                                                        (0.008, 16), (0.008, 8)]
    plain = expand(parse_experiment({k: v for k, v in spec.items() if k != "axes"}))
    assert runs[0].run_id == plain[0].run_id                      # the default cell is the grid's plain run
    assert len({r.run_id for r in runs}) == 4
    record = RunRecord(run_id=runs[3].run_id, experiment="t", kind="train", scene="diffuse", seed=0, status="done",
                       config=runs[3].config, labels=dict(runs[3].labels))
    row = record.row()
    assert row["config.raster.alpha_min"] == 0.008 and row["config.raster.tile_size"] == 8
    assert row["axis.raster.alpha_min"] == 0.008
    assert flatten(runs[0].config)["raster.alpha_min"] == DEFAULT_ALPHA_MIN   # every row, the defaults too


@pytest.mark.parametrize("where, table, message", [
    ("base", {"base": {"raster.alpah_min": 0.1}}, "x.toml: base: raster.alpah_min: unknown key (did you mean "
                                                  "'alpha_min'?)"),
    ("axis", {"axes": {"raster.tile_size": [16, 12]}}, "x.toml: axes.raster.tile_size = 12: raster.tile_size: "
                                                       "expected a power of two in [1, 64], got 12"),
    ("base value an axis sets inside", {"base": {"raster": "fast"}, "axes": {"raster.alpha_min": [0.005]}},
     "x.toml: base.raster: a value (\"fast\"), but axes.raster.alpha_min = 0.005 sets raster.alpha_min inside it; "
     "write [base.raster] as a table, or leave it out"),
    ("dead run", {"axes": {"raster.alpha_min": [0.005, 0.1]}},
     "x.toml: axes.raster.alpha_min = 0.1: raster.alpha_min: 0.1 is at or above the initial opacity 0.1 "
     "(init.opacity), and alpha = opacity x G never exceeds the opacity: every Gaussian would be skipped and get "
     "no gradient; lower raster.alpha_min or raise init.opacity"),
])
def test_a_grid_names_a_bad_raster_key_in_one_line(where, table, message):
    spec = {"name": "t", "kind": "train", "scenes": ["diffuse"], "seeds": [0], "base": {"iterations": 2000}}
    for key, value in table.items():
        spec[key] = {**spec.get(key, {}), **value}
    with pytest.raises(InputError) as info:
        expand(parse_experiment(spec, source="x.toml"))
    assert str(info.value) == message
