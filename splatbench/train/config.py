"""`TrainConfig`: every knob of a training run, in groups, with graphdeco-inria 3DGS defaults.

A run's settings are a frozen dataclass of a few top-level fields (the dataset, the output
folder, ``seed``, ``protocol``, ``iterations``, the device, ...) and one frozen dataclass per
group, each a TOML table and a dotted ``--set`` prefix:

=============  ====================  ===================================================
group          class                 what it holds
=============  ====================  ===================================================
``data``       `DataConfig`          how the dataset is read: layout, split, downscale, masks
``init``       `InitConfig`          the Gaussians training starts from
``sh``         `SHConfig`            the SH degree and its schedule (fixed or ``"auto"``)
``optim``      `OptimConfig`         Adam's learning rates and epsilon
``loss``       `LossConfig`          the photometric loss (L1 + D-SSIM)
``strategy``   `StrategyConfig`      the densification strategy and its options
``eval``       `EvalConfig`          test evaluations and their LPIPS convention
``raster``     `RasterOptions`       the rasterizer's options for every render of the run
=============  ====================  ===================================================

TOML and the command line read the same keys: ``[sh] degree = 3`` in a file is ``--set
sh.degree=3``; ``--set strategy=mcmc`` and ``--set init=random`` are short for
``strategy.name`` and ``init.method``. A ``--set`` value is a TOML literal (``3e-4``,
``true``, ``[1, 1, 1]``, ``"auto"``) or else a bare string; ``background`` also takes
``"1,1,1"``. `TrainConfig.from_dict` / `load_config` / `apply_overrides` are the one reader
of configs: dicts exist only there and in `TrainConfig.to_dict` (the TOML writer). Every
mistake -- unknown key, wrong type, negative learning rate, zero iterations, unknown strategy
or initialisation, a densification schedule whose last topology change falls in the final 10
% of the run, a ``raster.alpha_min`` at or above the initial opacity -- is a one-line
`InputError` naming the dotted field, raised when the (frozen) config is constructed, before
any data is read or rendered; ``dataclasses.replace`` or `apply_overrides` make a changed
copy. A setting that runs but likely defeats training (``raster.alpha_min`` at or above the
strategy's opacity reset value; opacity resets closer together than an opacity can climb
back) is a line of `TrainConfig.warnings`, said before training.

The device is set once, by ``device``: ``raster.device`` is not a setting, and the
constructor makes ``config.raster.device`` equal ``config.device``, so that
``config.raster`` is exactly the `RasterOptions` of every render of the run.

Schedules (refinement window, opacity reset, SH steps) are written in graphdeco's
30,000-iteration steps and scaled to ``iterations`` by default (``schedule = "scaled"``);
``schedule = "absolute"`` takes them as written (`splatbench.train.schedule`).
``protocol`` names how the schedule is laid out and where the run is evaluated:
``"quick"`` (over the run's own ``iterations``), or graphdeco's unscaled 30,000-step
schedule evaluated at 7,000 and 30,000 steps (``"graphdeco-30k"``) or stopped at 7,000
(``"graphdeco-7k"``); a protocol chosen without ``iterations`` brings its own
(`splatbench.train.protocol`).

A run id hashes `TrainConfig.to_dict` (`splatbench.experiments`): every field of every
group, at its default or not.

Example::

    cfg = TrainConfig(dataset="data/scenes/diffuse-128", iterations=2000, sh=SHConfig(degree=0))
    cfg = apply_overrides(cfg, ["sh.degree=auto", "strategy=none"])   # a new, validated config
    save_config(cfg, "run/config.toml"); load_config("run/config.toml") == cfg   # True
"""

from __future__ import annotations

import dataclasses
import functools
import math
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from splatbench.guards import check_keys, check_sh_degree, check_type, coerce, dataclass_from_mapping
from splatbench.devices import check_device
from splatbench.errors import InputError
from splatbench.fsutil import read_text
from splatbench.overrides import parse_override
from splatbench.raster.options import RasterOptions
from splatbench.report_files import write_text
from splatbench.train.sh_schedule import MAX_LOOKAHEAD

#: Dataset layouts ``data.layout`` names (``"auto"``: found from the folder's files; splatbench.data).
LAYOUTS = ("auto", "colmap", "blender", "llff")
#: Keys of the ``raster`` table: every `RasterOptions` field but ``device`` (``TrainConfig.device``).
RASTER_KEYS = tuple(f.name for f in dataclasses.fields(RasterOptions) if f.name != "device")


class _Group:
    """A config group: a frozen dataclass whose fields are checked on construction against
    their annotated types (`guards.check_type`) and then by the group's `_check`; every
    message names the dotted field (``sh.degree: ...``)."""

    PREFIX: ClassVar[str] = ""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check_type(self.PREFIX + f.name, getattr(self, f.name), _types(type(self))[f.name])
        self._check()

    def _check(self) -> None:
        """Ranges and choices (types are checked already)."""

    def _fail(self, name: str, expected: str) -> typing.NoReturn:
        raise InputError(f"{self.PREFIX}{name}: expected {expected}, got {getattr(self, name)!r}")

    def _at_least(self, low: int, *names: str) -> None:
        for name in names:
            if getattr(self, name) < low:
                self._fail(name, f"an int >= {low}")

    @classmethod
    def from_table(cls, table: Any, source: str = ""):
        """The group of a TOML table / ``--set`` values (unknown keys and wrong types: one line)."""
        if not isinstance(table, dict):
            raise InputError(f"{_where(source)}{cls.PREFIX[:-1]}: expected a table of "
                             f"{', '.join(f.name for f in dataclasses.fields(cls))}, got {table!r}")
        return dataclass_from_mapping(cls, table, prefix=cls.PREFIX, source=source)

    def to_table(self) -> dict[str, Any]:
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}


@dataclass(frozen=True, kw_only=True)
class DataConfig(_Group):
    """How the dataset is read (`splatbench.data.load_dataset`)."""

    PREFIX: ClassVar[str] = "data."
    layout: str = "auto"         # "auto" (found from the folder's files), "colmap", "blender" or "llff"
    test_every: int = 8          # hold out every n-th view (sorted by name) when the dataset gives no split
    downscale: int = 1           # divide the image size by N (images_N/ when present; splatbench.data)
    masks: bool = True           # a capture's masks/ (or masks_N/) become each image's alpha; false ignores them

    def _check(self) -> None:
        if self.layout not in LAYOUTS:
            self._fail("layout", f"one of {', '.join(map(repr, LAYOUTS))}")
        self._at_least(0, "test_every")
        self._at_least(1, "downscale")


@dataclass(frozen=True, kw_only=True)
class InitConfig(_Group):
    """The Gaussians a run starts from (`splatbench.train.initializers`, docs/training.md)."""

    PREFIX: ClassVar[str] = "init."
    method: str = "auto"         # "auto" (the dataset's points when it has them, else "sfm"; never random unless
                                 # asked), "surface" (the dataset's own points), "sfm" (pycolmap on the training
                                 # views, cached in $SPLATBENCH_CACHE/sfm), "random" (uniform in `region`)
    random_points: int = 100_000  # points of method="random" (graphdeco's NeRF-synthetic count)
    region: str = "auto"         # where "random" samples: "convergence" (a ball where the optical axes meet),
                                 # "camera_cube" (gsplat: +-extent scene scales around the cameras),
                                 # "nerf_synthetic" ([-1.3, 1.3]^3, graphdeco's Blender box) or "auto"
                                 # (initializers.REGIONS says which and where each fails)
    extent: float = 3.0          # region="camera_cube": half-side in scene scales (gsplat's init_extent)
    jitter: float = 0.5          # surface / sfm points: each moved by a normal draw of this x its neighbour
                                 # spacing, seeded by `seed` (so seeds vary the start); 0 = as given
    sfm_poses: str = "known"     # method="sfm": "known" (triangulate with the dataset's poses) or "estimated"
                                 # (incremental mapping, aligned to the dataset's frame)
    opacity: float | str = "auto"  # initial opacity of every Gaussian in (0, 1), or "auto": the strategy's
                                 # reference value (default/none 0.1 as graphdeco, mcmc 0.5 as 3DGS-MCMC)

    def _check(self) -> None:
        from splatbench.sfm import POSE_MODES
        from splatbench.train.initializers import INITIALIZERS, REGIONS

        if self.method not in INITIALIZERS:
            raise InputError(f"init.method: unknown initialisation {self.method!r} (expected one of: "
                             f"{', '.join(INITIALIZERS)})")
        if self.region not in REGIONS:
            self._fail("region", f"one of {', '.join(REGIONS)}")
        if self.sfm_poses not in POSE_MODES:
            self._fail("sfm_poses", f"one of {', '.join(POSE_MODES)}")
        self._at_least(1, "random_points")
        if not self.extent > 0:
            self._fail("extent", "a number > 0")
        if not self.jitter >= 0:
            self._fail("jitter", "a number >= 0 (0 = the points as given)")
        if isinstance(self.opacity, str) and self.opacity != "auto" or \
                not isinstance(self.opacity, str) and not 0 < self.opacity < 1:
            self._fail("opacity", "a number in (0, 1) or 'auto'")


@dataclass(frozen=True, kw_only=True)
class SHConfig(_Group):
    """Spherical harmonics: the degree and when each band starts (`splatbench.train.sh_schedule`)."""

    PREFIX: ClassVar[str] = "sh."
    degree: int | str = 3        # maximum SH degree 0..3, or "auto" (measure each band, keep what helps)
    interval: int = 1000         # raise the active degree by one every this many steps (scaled by `schedule`)
    auto_min_gain_db: float = 0.1  # auto: dB of probe-view PSNR each added band must earn to be kept
    auto_lookahead: int = 2      # auto: bands still tried after a band fails, judged together with it against
                                 # the last kept degree (0..2; 0 = greedy, 2 = up to degree 3)
    auto_probe_views: int = 8    # auto: training views rendered to measure a band's gain (0 = all)
    auto_holdout_every: int = 8  # auto: hold every n-th training view out of training until the degree settles
                                 # and measure bands on those views instead (0 = off)

    def _check(self) -> None:
        check_sh_degree("sh.degree", self.degree, allow_auto=True)
        self._at_least(1, "interval")
        self._at_least(0, "auto_probe_views", "auto_holdout_every")
        if not self.auto_min_gain_db >= 0:
            self._fail("auto_min_gain_db", "a number >= 0")
        if not 0 <= self.auto_lookahead <= MAX_LOOKAHEAD:
            self._fail("auto_lookahead", f"an int in 0..{MAX_LOOKAHEAD} (bands tried after one fails; 0 = greedy, "
                                         f"{MAX_LOOKAHEAD} = up to degree 3)")

    @property
    def max_degree(self) -> int:
        """The highest degree the run may use (3 under ``"auto"``)."""
        return 3 if self.degree == "auto" else int(self.degree)


#: Learning-rate fields of `OptimConfig` (Adam, one optimizer per parameter group); 0 freezes a group.
LR_FIELDS = ("lr_means", "lr_means_final", "lr_log_scales", "lr_quats", "lr_opacity_logits", "lr_sh_dc",
             "lr_sh_rest")


@dataclass(frozen=True, kw_only=True)
class OptimConfig(_Group):
    """Adam, one optimizer per parameter group; an lr of 0 freezes a group (no gradient is computed)."""

    PREFIX: ClassVar[str] = "optim."
    lr_means: float = 1.6e-4     # positions at step 0, times the scene extent
    lr_means_final: float = 1.6e-6  # positions at the last step of the schedule, times the extent (exponential)
    lr_log_scales: float = 5e-3  # log scales
    lr_quats: float = 1e-3       # rotations (quaternions)
    lr_opacity_logits: float = 2.5e-2  # opacity logits
    lr_sh_dc: float = 2.5e-3     # SH band 0 (base colour)
    lr_sh_rest: float = 1.25e-4  # SH bands 1..3 (= lr_sh_dc / 20)
    adam_eps: float = 1e-15      # Adam epsilon (3DGS: 1e-15)

    def _check(self) -> None:
        for name in LR_FIELDS:
            if not getattr(self, name) >= 0:
                self._fail(name, "a learning rate >= 0")
        if (self.lr_means_final > 0) != (self.lr_means > 0):
            raise InputError(f"optim.lr_means_final: expected a rate > 0 when optim.lr_means > 0 and 0 when it is 0 "
                             f"(means frozen), got {self.lr_means_final!r} with lr_means {self.lr_means!r}")
        if not self.adam_eps > 0:
            self._fail("adam_eps", "a number > 0")

    def rates(self) -> dict[str, float]:
        """Parameter group -> its learning rate (the means' at step 0)."""
        return {"means": self.lr_means, "log_scales": self.lr_log_scales, "quats": self.lr_quats,
                "opacity_logits": self.lr_opacity_logits, "sh_dc": self.lr_sh_dc, "sh_rest": self.lr_sh_rest}


@dataclass(frozen=True, kw_only=True)
class LossConfig(_Group):
    """loss = (1 - ssim_lambda) L1 + ssim_lambda (1 - SSIM)."""

    PREFIX: ClassVar[str] = "loss."
    ssim_lambda: float = 0.2     # weight of the D-SSIM term
    ssim_window: int = 11        # SSIM Gaussian window side (pixels, odd)

    def _check(self) -> None:
        if not 0 <= self.ssim_lambda <= 1:
            self._fail("ssim_lambda", "a number in [0, 1]")
        if self.ssim_window < 1 or self.ssim_window % 2 == 0:
            self._fail("ssim_window", "an odd window side >= 1")


@dataclass(frozen=True, kw_only=True)
class StrategyConfig:
    """The densification strategy (`splatbench.strategies`): ``name`` and the fields of its
    dataclass to change (``options``; in TOML the other keys of the ``[strategy]`` table,
    ``--set strategy.cap_max=50000``). Step fields may be written as a fraction of the run
    ("25%", "1/4"). Checked on construction by building the strategy."""

    name: str = "default"        # "none", "default" (3DGS), "absgrad" (AbsGS), "mcmc" (3DGS-MCMC), "budget" (Taming)
    options: dict[str, Any] = field(default_factory=dict)  # fields of the strategy's dataclass, as written

    def __post_init__(self) -> None:
        check_type("strategy.name", self.name, str)
        check_type("strategy", self.options, dict[str, Any])
        if "name" in self.options:
            raise InputError("strategy.name: the strategy's name is not one of its options")
        from splatbench.strategies import STRATEGIES, strategy_fields

        if self.name in STRATEGIES:
            own = strategy_fields(self.name)
            for key in self.options:
                others = [n for n in STRATEGIES if n != self.name and key in strategy_fields(n)]
                if key not in own and others:
                    raise InputError(f"strategy.{key}: not a field of strategy {self.name!r} (set strategy.name: "
                                     f"{key} is a field of {', '.join(others)})")
        self.build(iterations=None, schedule="absolute", seed=0)

    def build(self, *, iterations: int | None, schedule: str, seed: int, scaled: bool = True):
        """The strategy: its preset with ``options`` applied; a strategy with a ``seed`` field gets
        ``seed`` unless the options set one; run fractions resolved against ``iterations`` (the
        schedule's length; None: checked only), and, when ``scaled``, its step fields laid over
        that length as ``schedule`` says (`splatbench.train.schedule.scaled_strategy`)."""
        from splatbench.strategies import STRATEGIES, make_strategy, strategy_fields
        from splatbench.train.schedule import resolve_run_fractions, scaled_strategy

        options = dict(self.options)
        if "seed" in strategy_fields(self.name) and "seed" not in options:
            options["seed"] = seed
        length = iterations or 30_000  # for checking alone: any length resolves the fractions
        options, fixed = resolve_run_fractions(STRATEGIES[self.name][0].run_fraction_fields, options, length)
        strategy = make_strategy(self.name, **options)
        return scaled_strategy(strategy, length, schedule, fixed=fixed) if scaled and iterations else strategy

    @classmethod
    def from_table(cls, table: Any, source: str = "") -> StrategyConfig:
        """``"mcmc"`` or ``{"name": "mcmc", "cap_max": 50000, ...}``."""
        if isinstance(table, str):
            return cls(name=table)
        if not isinstance(table, dict):
            raise InputError(f"{_where(source)}strategy: expected a strategy name or a table of name and its "
                             f"options, got {table!r}")
        table = dict(table)
        return cls(name=table.pop("name", cls.name), options=table)

    def to_table(self) -> dict[str, Any]:
        return {"name": self.name, **{k: _plain(v) for k, v in self.options.items()}}


@dataclass(frozen=True, kw_only=True)
class EvalConfig(_Group):
    """Test evaluations: when, and LPIPS's convention (`splatbench.metrics.lpips`)."""

    PREFIX: ClassVar[str] = "eval."
    every: int = 0               # evaluate on the test views every this many steps (0 = only at the end)
    steps: list[int] = field(default_factory=list)  # steps of a full test evaluation (PSNR, SSIM, LPIPS in both
                                 # input conventions, Gaussians; TrainResult.step_evaluations), besides the
                                 # protocol's and the end
    lpips_net: str = "alex"      # LPIPS v0.1 of the final evaluation: "alex" (gsplat, NerfBaselines), "vgg"
                                 # (graphdeco's metrics.py; ~20x AlexNet's time) or "none"; `every` uses AlexNet
    lpips_scale_inputs: bool = True  # feed LPIPS images scaled to [-1, 1] (the lpips package); false: [0, 1]
                                 # unscaled, as graphdeco's metrics.py does
    before_refine: bool = False  # evaluate a step before its refinement / opacity reset, as graphdeco's
                                 # train.py (the last step's is then left out: its model is the one
                                 # evaluated); false: after them (docs/training.md, "Evaluation order")

    def _check(self) -> None:
        self._at_least(0, "every")
        if self.lpips_net not in ("alex", "vgg", "none"):
            self._fail("lpips_net", "'alex', 'vgg' or 'none'")


#: The flat keys of TrainConfig before it was grouped, with their place now: named in the one-line error
#: of a config that still uses one (read nowhere else: an old key is an error, never reinterpreted).
FORMER_KEYS = {"layout": "data.layout", "test_every": "data.test_every", "init_random_points": "init.random_points",
               "init_region": "init.region", "init_extent": "init.extent", "init_jitter": "init.jitter",
               "init_sfm_poses": "init.sfm_poses", "init_opacity": "init.opacity", "sh_degree": "sh.degree",
               "sh_interval": "sh.interval", "sh_auto_min_gain_db": "sh.auto_min_gain_db",
               "sh_auto_lookahead": "sh.auto_lookahead", "sh_auto_probe_views": "sh.auto_probe_views",
               "sh_auto_holdout_every": "sh.auto_holdout_every", "ssim_lambda": "loss.ssim_lambda",
               "ssim_window": "loss.ssim_window", "eval_every": "eval.every", "eval_steps": "eval.steps",
               "lpips_net": "eval.lpips_net", "lpips_scale_inputs": "eval.lpips_scale_inputs",
               "strategy_options": "strategy (its fields beside strategy.name)", "adam_eps": "optim.adam_eps",
               "downscale": "data.downscale", "masks": "data.masks",
               **{k: f"optim.{k}" for k in ("lr_means", "lr_means_final", "lr_log_scales", "lr_quats",
                                             "lr_opacity_logits", "lr_sh_dc", "lr_sh_rest")}}

#: The groups: top-level key -> its class (`RasterOptions` is read by `raster_options`).
GROUPS: dict[str, type] = {"data": DataConfig, "init": InitConfig, "sh": SHConfig, "optim": OptimConfig,
                           "loss": LossConfig, "strategy": StrategyConfig, "eval": EvalConfig}
#: A group given a bare value (``--set strategy=mcmc``) sets this field of it.
SHORTHANDS = {"strategy": "name", "init": "method"}


@dataclass(frozen=True)
class TrainConfig:
    """One training run. Defaults follow graphdeco-inria's 3DGS (``arguments/__init__.py``)."""

    dataset: str = ""                 # dataset folder (COLMAP, Blender, instant-ngp or LLFF layout: splatbench.data)
    out: str = "runs/train"           # output folder: point_cloud.ply, checkpoints/, config.toml, result.json
    seed: int = 0                     # seeds torch, numpy, the view order, random backgrounds and the start
    protocol: str = "quick"           # "quick": the schedule laid over `iterations`; "graphdeco-30k": graphdeco's
                                      # 30,000-step schedule unscaled, evaluated at 7,000 and 30,000;
                                      # "graphdeco-7k": that schedule stopped at 7,000 (splatbench.train.protocol)
    iterations: int = 30_000          # optimisation steps, one training view each (a protocol's own when it is
                                      # given without iterations)
    schedule: str = "scaled"          # how step fields (strategy.refine_start / refine_stop / reset_every,
                                      # sh.interval) are read: "scaled" = in steps of graphdeco's 30,000-step run,
                                      # times iterations / 30,000; "absolute" = as written
    background: list[float] | str = "auto"  # RGB in [0, 1] behind the splats ("1,1,1" too), or "auto": white for a
                                      # masked capture, else the mean colour of the training pixels the dataset
                                      # marks empty (alpha 0, else depth 0), black when it marks none (3DGS)
    random_background: bool = False   # a uniformly random background colour per training step (needs alphas)
    log_every: int = 100              # record (step, loss, PSNR, N) in the history every this many steps
    checkpoint_every: int = 0         # write checkpoints/iteration_<step>.ply every this many steps (0 = off)
    device: str = "auto"              # rasterizer backend: "cpu" (Dr.Jit LLVM), "cuda" or "auto"
    torch_threads: int = 1            # torch intra-op threads during the run (0 = torch's default)
    data: DataConfig = field(default_factory=DataConfig)
    init: InitConfig = field(default_factory=InitConfig)
    sh: SHConfig = field(default_factory=SHConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    strategy: StrategyConfig = field(default_factory=StrategyConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    raster: RasterOptions = field(default_factory=RasterOptions)  # every render of the run; its device is `device`

    # ------------------------------------------------------------------ checks
    def __post_init__(self) -> None:
        for name, cls in {**GROUPS, "raster": RasterOptions}.items():
            if not isinstance(getattr(self, name), cls):
                raise InputError(f"{name}: expected {cls.__name__} (in TOML a [{name}] table), "
                                 f"got {getattr(self, name)!r}")
        if isinstance(self.device, str) and self.raster.device != self.device:  # the one device setting
            object.__setattr__(self, "raster", dataclasses.replace(self.raster, device=self.device))
        self.validate()  # a TrainConfig that exists is valid; change one with dataclasses.replace

    def validate(self) -> TrainConfig:
        """Check the top-level fields and what spans groups; raise a one-line `InputError`
        naming the first bad field (each group checked itself on construction). Returns self."""
        for f in dataclasses.fields(self):
            if f.name not in GROUPS and f.name != "raster":
                check_type(f.name, getattr(self, f.name), _types(TrainConfig)[f.name])
        if self.iterations < 1:
            raise InputError(f"iterations: expected an int >= 1, got {self.iterations}")
        from splatbench.train.protocol import get_protocol

        protocol = get_protocol(self.protocol)
        protocol.check_iterations(self.iterations)
        for step in self.eval.steps:
            if not 1 <= step <= self.iterations:
                raise InputError(f"eval.steps: expected steps in 1..{self.iterations} (iterations), got {step}")
        for name in ("log_every",):
            if getattr(self, name) < 1:
                raise InputError(f"{name}: expected an int >= 1, got {getattr(self, name)}")
        for name in ("checkpoint_every", "torch_threads"):
            if getattr(self, name) < 0:
                raise InputError(f"{name}: expected an int >= 0, got {getattr(self, name)}")
        if isinstance(self.background, str):
            if self.background != "auto":
                raise InputError(f"background: expected 3 values in [0, 1] or 'auto', got {self.background!r}")
        elif len(self.background) != 3 or not all(0 <= c <= 1 for c in self.background):
            raise InputError(f"background: expected 3 values in [0, 1] or 'auto', got {self.background!r}")
        check_device(self.device, "device")
        from splatbench.train.schedule import SCHEDULES, check_final_window

        if self.schedule not in SCHEDULES:
            raise InputError(f"schedule: expected one of {', '.join(map(repr, SCHEDULES))}, got {self.schedule!r}")
        strategy = self.make_strategy()
        if protocol.final_window_check:
            check_final_window(strategy, self.iterations, self.schedule)
        self._check_alpha_min()
        if self.optim.lr_means == 0 and strategy.reads_mean_gradients:
            # frozen means have no screen-space gradient (the rasterizer's backward skips it), and this
            # strategy declares that it reads it (the Strategy protocol's reads_mean_gradients)
            from splatbench.strategies import STRATEGIES

            free = [name for name, (cls, _) in STRATEGIES.items() if not cls.reads_mean_gradients]
            raise InputError(f"optim.lr_means: 0 freezes the means, but strategy {self.strategy.name!r} densifies "
                             f"from their screen-space gradients (use a positive optim.lr_means, or "
                             f"strategy={' or '.join(free)})")
        return self

    def _check_alpha_min(self) -> None:
        """A run that cannot train: alpha = opacity x G never exceeds the opacity (G <= 1), and
        compositing skips alpha below ``raster.alpha_min`` with no gradient, so a Gaussian whose
        opacity is at or below it is skipped on every pixel and can never grow back. That is every
        Gaussian at the start when the initial opacity is (refused); after each opacity reset when
        the strategy's reset value is (a run that may be asked for on purpose: `warnings`)."""
        alpha_min = self.raster.alpha_min
        if self.initial_opacity <= alpha_min:
            raise InputError(f"raster.alpha_min: {alpha_min!r} is at or above the initial opacity "
                             f"{self.initial_opacity!r} (init.opacity), and alpha = opacity x G never exceeds the "
                             f"opacity: every Gaussian would be skipped and get no gradient; lower raster.alpha_min "
                             f"or raise init.opacity")

    def warnings(self) -> list[str]:
        """One line per setting that runs but likely defeats training (said before the first
        step and kept among the result's notes): an ``raster.alpha_min`` at or above the
        strategy's opacity reset value (graphdeco's 0.01) in a run with resets. After each reset
        alpha = opacity x G <= the reset value, so compositing skips every Gaussian and gives it
        no gradient; the model renders the background until nothing is left to recover. And a
        schedule whose opacity resets (two or more in the run) come sooner after each other
        than an opacity can climb back from the reset value to 0.5 (`opacity_recovery_steps`
        after the first reset): the quick protocol's scaled schedule at 100 steps resets every
        10, where the climb takes 176; the 2,000-step quick runs (every 200, climb 81) and
        graphdeco's 3,000 (climb 32) are not warned."""
        from splatbench.strategies import planned_counts

        out = []
        strategy = self.make_strategy()
        name = self.strategy.name
        alpha_min, reset = self.raster.alpha_min, getattr(strategy, "reset_value", None)
        if reset is not None and reset <= alpha_min and planned_counts(strategy, self.iterations).opacity_resets:
            out.append(f"warning: raster.alpha_min={alpha_min!r} is at or above the opacity reset value {reset!r} of "
                       f"strategy {name!r}: after each opacity reset every Gaussian is skipped (alpha = "
                       f"opacity x G never exceeds the opacity) and gets no gradient, so training cannot recover; "
                       f"lower raster.alpha_min, raise strategy.reset_value, or set strategy.reset_every = 0 "
                       f"(no resets)")
        every = getattr(strategy, "reset_every", 0)
        if reset is not None and every and planned_counts(strategy, self.iterations).opacity_resets >= 2:
            climb = opacity_recovery_steps(self.optim.lr_opacity_logits, reset, every, self.optim.adam_eps)
            if climb > every:
                out.append(f"warning: strategy {name!r} resets opacities every {every} steps in this run, "
                           f"sooner than an opacity can climb back from the reset value {reset:g} to "
                           f"{RECOVERY_OPACITY:g} ({climb} steps at optim.lr_opacity_logits "
                           f"{self.optim.lr_opacity_logits:g} under a steady gradient): each reset comes before the "
                           f"model has recovered from the last; train longer, or set strategy.reset_every = 0 (no "
                           f"resets)" + (f" or a fraction of the run (\"50%\") at least {climb} steps long"
                                         if climb < self.iterations else ""))  # none is, in a shorter run
        return out

    def make_strategy(self, *, scaled: bool = True):
        """The densification strategy this config names, with the run's ``seed`` where it has a
        seed field the options do not set. ``scaled``: its schedule fields in this run's steps
        (``schedule``, laid over `schedule_length`); False: as written. Step fields written as a
        fraction of the run ("25%", "1/4": of `schedule_length`) are in run steps either way."""
        return self.strategy.build(iterations=self.schedule_length, schedule=self.schedule, seed=self.seed,
                                   scaled=scaled)

    @property
    def schedule_length(self) -> int:
        """The steps the schedules and the position learning-rate decay are laid over:
        ``iterations`` under the quick protocol, 30,000 under graphdeco's (however
        early the run stops)."""
        from splatbench.train.protocol import get_protocol

        return get_protocol(self.protocol).schedule_length or self.iterations

    @property
    def evaluation_steps(self) -> list[int]:
        """Steps of a full test evaluation (`splatbench.train.protocol.evaluation_steps`)."""
        from splatbench.train.protocol import evaluation_steps

        return evaluation_steps(self.protocol, self.eval.steps, self.iterations)

    @property
    def initial_opacity(self) -> float:
        """``init.opacity``, with ``"auto"`` resolved to the strategy's ``initial_opacity``."""
        if isinstance(self.init.opacity, str):
            return float(self.make_strategy(scaled=False).initial_opacity)
        return float(self.init.opacity)

    @property
    def sh_steps(self) -> int:
        """``sh.interval`` in this run's steps (scaled under ``schedule = "scaled"``)."""
        from splatbench.train.schedule import scale_step

        return scale_step(self.sh.interval, self.schedule_length, self.schedule, interval=True)

    # ------------------------------------------------------------------ TOML
    def to_dict(self) -> dict[str, Any]:
        """Plain TOML-ready values: the top-level fields, then one table per group (``raster``
        as the table of `RASTER_KEYS`)."""
        out = {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)
               if f.name not in GROUPS and f.name != "raster"}
        out.update({name: getattr(self, name).to_table() for name in GROUPS})
        out["raster"] = {k: v for k, v in self.raster.to_dict().items() if k != "device"}
        return out

    def to_toml(self) -> str:
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, source: str = "config") -> TrainConfig:
        """A config from a mapping of top-level fields and group tables; a dotted key
        (``"sh.degree"``) is read as its table's key, as TOML reads one. Unknown keys and
        wrong types are one-line `InputError`s naming the dotted field."""
        if not isinstance(data, dict):
            raise InputError(f"{source or 'config'}: expected a table of fields, got {type(data).__name__}")
        data = nest(data)
        names = [f.name for f in dataclasses.fields(cls)]
        for key in data:
            if key not in names and key in FORMER_KEYS:
                raise InputError(f"{_where(source)}{key}: now {FORMER_KEYS[key]} (the config is in groups: "
                                 f"docs/training.md, \"Config\")")
        check_keys(data, names, source=source)
        types = _types(cls)
        values: dict[str, Any] = {}
        for key, value in data.items():
            if key in GROUPS:  # a top-level key written after a [table] lands in it (raster names its own)
                misplaced = [k for k in (value if isinstance(value, dict) else ()) if k in names
                             and not (key == "strategy" and _a_strategy_field(k))]
                if misplaced:
                    raise InputError(f"{_where(source)}{key}.{misplaced[0]}: not a key of [{key}]: {misplaced[0]} is a "
                                     f"top-level field (in TOML, write it before the first [table])")
            if key == "raster":
                values[key] = raster_options(value)
            elif key in GROUPS:
                if key in SHORTHANDS and not isinstance(value, dict):
                    value = {SHORTHANDS[key]: value}
                values[key] = GROUPS[key].from_table(value, source)
            else:
                if key == "background" and isinstance(value, str) and value != "auto":
                    value = _rgb(value)
                value = coerce(value, types[key])
                check_type(key, value, types[key])  # types before construction (whose checks assume them)
                values[key] = value
        if "protocol" in values and "iterations" not in values:
            values["iterations"] = _protocol_iterations(values["protocol"], cls.iterations)
        return cls(**values)

    @classmethod
    def from_toml(cls, text: str, *, source: str = "config") -> TrainConfig:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"{source}: invalid TOML ({exc})") from None
        return cls.from_dict(data, source=source)


#: The opacity a Gaussian must regain between two opacity resets (`opacity_recovery_steps`).
RECOVERY_OPACITY = 0.5


def opacity_recovery_steps(lr: float, reset_value: float, reset_step: int, eps: float = 1e-15,
                           target: float = RECOVERY_OPACITY) -> int:
    """The fewest steps in which Adam (betas 0.9, 0.999, as `splatbench.train.adam`) can bring
    an opacity logit from ``logit(reset_value)`` back up to ``logit(target)`` after an opacity
    reset at step ``reset_step``: a gradient of one sign every step (the fastest climb; a real
    Gaussian's gradient changes sign and climbs slower), with the moments zeroed by the reset
    (`splatbench.strategies.ops.reset_opacity`, as graphdeco) and Adam's step count kept. At the
    defaults (lr 0.025, reset 0.01) the climb to 0.5 takes 176 steps after a reset at step 10
    (a 100-step quick run, resets every 10), 132 at step 60 (600 steps, every 60), 111 at 100
    (1,000 steps), 81 at 200 (2,000-step quick runs, every 200) and 32 at graphdeco's
    3,000: the bias correction of moments zeroed late in a run makes the first steps up to ~6x
    the learning rate. Resets closer together than this leave no Gaussian half-opaque between
    them (`TrainConfig.warnings`). Capped at 100,000 steps (an lr of 0)."""
    goal, x = math.log(target / (1.0 - target)), math.log(reset_value / (1.0 - reset_value))
    m = v = 0.0
    beta1, beta2 = 0.9, 0.999
    for k in range(1, 100_001):
        t = reset_step + k
        m, v = beta1 * m + (1.0 - beta1), beta2 * v + (1.0 - beta2)  # gradient 1 (scale-free but for eps)
        x += lr * (m / (1.0 - beta1 ** t)) / (math.sqrt(v / (1.0 - beta2 ** t)) + eps)
        if x >= goal:
            return k
    return 100_000


def load_config(path: str | Path) -> TrainConfig:
    """Read a TOML config file (`InputError` if missing or invalid)."""
    p = Path(path)
    text = read_text(p, "config")
    return TrainConfig.from_toml(text, source=str(p))


def save_config(config: TrainConfig, path: str | Path) -> Path:
    """Write ``config`` as TOML (creating the folder), atomically (`report_files.write_text`)."""
    return write_text(path, config.to_toml())


def apply_overrides(config: TrainConfig, overrides: list[str] | tuple[str, ...]) -> TrainConfig:
    """A copy of ``config`` with ``key=value`` overrides applied (types coerced): ``key`` a
    top-level field, ``group.key`` a group's (``strategy=NAME`` / ``init=METHOD`` set the
    group's name / method and keep its other keys). A ``raster.tile_size`` set without
    ``raster.pixel_block``, on a config whose block is the default for its tile, takes the
    default for the new tile (`RasterOptions.pixel_block`)."""
    data = config.to_dict()
    keys = set()
    for item in overrides:
        key, value = parse_override(item)
        table, _, sub = key.partition(".")
        if table in SHORTHANDS and not sub:
            key, sub = f"{table}.{SHORTHANDS[table]}", SHORTHANDS[table]
        keys.add(key)
        if table in data and isinstance(data[table], dict) and "." in key:
            if not sub:
                raise InputError(f"--set: empty {table} key in {item!r}")
            data[table] = {**data[table], sub: value}
        else:
            data[key] = value
    if "protocol" in keys and "iterations" not in keys and data["protocol"] != config.protocol:
        data["iterations"] = _protocol_iterations(data["protocol"], config.iterations)  # the protocol's length
    if "raster.tile_size" in keys and "raster.pixel_block" not in keys and \
            config.raster.pixel_block == RasterOptions(tile_size=config.raster.tile_size).pixel_block:
        data["raster"] = {k: v for k, v in data["raster"].items() if k != "pixel_block"}  # the default follows the tile
    return TrainConfig.from_dict(data, source="--set")


# ---------------------------------------------------------------------- helpers
def nest(data: dict[str, Any]) -> dict[str, Any]:
    """``{"sh.degree": 0, "raster": {...}}`` -> ``{"sh": {"degree": 0}, "raster": {...}}``: dotted keys
    into their tables (one level, as the groups are), merged with a table given as such."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        table, dot, sub = str(key).partition(".")
        if not dot:
            if isinstance(value, dict) and isinstance(out.get(key), dict):
                out[key] = {**value, **out[key]}
            else:
                out[key] = value
            continue
        if table in out and not isinstance(out[table], dict):
            if table in SHORTHANDS:
                out[table] = {SHORTHANDS[table]: out[table]}
            else:
                raise InputError(f"{table}: set both as a value and as a table ({key})")
        out[table] = {**out.get(table, {}), sub: value}
    return out


def raster_options(table: Any) -> RasterOptions:
    """The `RasterOptions` of a ``raster`` table (`RASTER_KEYS`; a `RasterOptions` as it
    is). One `InputError` line naming ``raster.KEY`` for an unknown key (with the keys it
    may be), a wrong type or range, and for ``raster.device`` (the device is ``device``)."""
    if isinstance(table, RasterOptions):
        return table
    if not isinstance(table, dict):
        raise InputError(f"raster: expected a table of rasterizer options ({', '.join(RASTER_KEYS)}), got {table!r}")
    if "device" in table:
        raise InputError("raster.device: the rasterizer runs on the run's `device` (set device=cpu, cuda or auto, "
                         "e.g. --set device=cuda), not a raster option")
    check_keys(table, RASTER_KEYS, prefix="raster.")
    return RasterOptions.from_dict(table, prefix="raster.")


def _rgb(text: str) -> Any:
    """``"1,1,1"`` -> [1.0, 1.0, 1.0] (the spelling `splatbench render --background` takes); other
    strings as they are (validation names them)."""
    parts = text.split(",")
    try:
        return [float(p) for p in parts] if len(parts) == 3 else text
    except ValueError:
        return text


def _a_strategy_field(key: str) -> bool:
    """Whether ``key`` is a field of some strategy (``seed`` is, and a top-level field too)."""
    from splatbench.strategies import STRATEGIES, strategy_fields

    return any(key in strategy_fields(name) for name in STRATEGIES)


def _where(source: str) -> str:
    return f"{source}: " if source else ""


def _protocol_iterations(name: Any, otherwise: int) -> int:
    """The iterations protocol ``name`` runs when none are given (``otherwise`` when it
    sets none, or is not a protocol: validation names that)."""
    from splatbench.train.protocol import PROTOCOLS

    protocol = PROTOCOLS.get(name) if isinstance(name, str) else None
    return otherwise if protocol is None or protocol.iterations is None else protocol.iterations


@functools.cache
def _types(cls: type) -> dict[str, Any]:
    """A config class's field types, resolved once per process: `typing.get_type_hints` compiles
    every annotation string again on each call, and validation asks for them once per field,
    which made expanding a training grid cost about 0.1 s per run (read only; never mutated)."""
    return typing.get_type_hints(cls)


def _plain(value: Any) -> Any:
    if isinstance(value, list):
        return list(value)
    if isinstance(value, dict):
        return dict(value)
    return value


__all__ = ["TrainConfig", "DataConfig", "InitConfig", "SHConfig", "OptimConfig", "LossConfig", "StrategyConfig",
           "EvalConfig", "GROUPS", "LAYOUTS", "LR_FIELDS", "RASTER_KEYS", "raster_options", "load_config",
           "save_config", "parse_override", "apply_overrides", "nest"]
