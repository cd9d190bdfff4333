"""`TrainConfig`: every knob of a training run, with graphdeco-inria 3DGS defaults.

The config is a flat dataclass (one comment per field) that reads and writes TOML
(`tomllib` / `tomli_w`, never ``eval``). Command-line overrides are ``key=value``
strings whose value is parsed as a TOML literal (``3e-4``, ``true``, ``[1, 1, 1]``,
``"auto"``) and falls back to a bare string (``strategy=mcmc``); a dotted key edits
the strategy options (``strategy_options.cap_max=50000``), the dataset's loading
(``data.downscale=8``) or the rasterizer's options (``raster.alpha_min=0.005``,
``raster.tile_size=8``, ``raster.radius=opacity``: `RasterOptions`, the ``[raster]``
table of a TOML file). Every mistake -- unknown
key, wrong type, negative learning rate, zero iterations, unknown strategy or
initialisation, a densification schedule whose last topology change falls in the
final 10 % of the run, a ``raster.alpha_min`` at or above the initial opacity (every
Gaussian would be skipped, with no gradient, from the start) -- is a one-line `InputError`
naming the field, raised by
`TrainConfig.validate` when the (frozen) config is constructed, before any data is
read or rendered; ``dataclasses.replace`` or `apply_overrides` make a changed copy. A
setting that runs but likely defeats training (``raster.alpha_min`` at or above the
strategy's opacity reset value; opacity resets closer together than an opacity can climb
back from the reset value to 0.5) is a line of `TrainConfig.warnings`, said before training.

The device is set once, by ``device``: ``raster.device`` is not a setting (a ``[raster]``
table or ``--set`` that names it is an error naming ``device``), and the constructor makes
``config.raster.device`` equal ``config.device``, so that ``config.raster`` is exactly the
`RasterOptions` of every render of the run, and ``replace(config, device="cuda")`` moves
both.

Schedules (refinement window, opacity reset, SH steps) are written in graphdeco's
30,000-iteration steps and scaled to ``iterations`` by default (``schedule =
"scaled"``); ``schedule = "absolute"`` takes them as written
(`splatbench.train.schedule`). ``protocol`` names how the schedule is laid out and where
the run is evaluated: ``"quick"`` (over the run's own ``iterations``), or graphdeco's
unscaled 30,000-step schedule evaluated at 7,000 and 30,000 steps (``"graphdeco-30k"``)
or stopped at 7,000 (``"graphdeco-7k"``); a protocol chosen without ``iterations`` in a
TOML file, a grid or ``--set`` brings its own (`TrainConfig.from_dict`, `apply_overrides`;
the constructor takes ``iterations`` as given: ``TrainConfig(protocol="graphdeco-7k",
iterations=7000)``); `splatbench.train.protocol`.

Example::

    cfg = TrainConfig(dataset="data/scenes/diffuse-128", iterations=2000)
    cfg = apply_overrides(cfg, ["sh_degree=auto", "strategy=none"])   # a new, validated config
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
from typing import Any

from splatbench.checks import check_keys, check_sh_degree, check_type, coerce
from splatbench.devices import check_device
from splatbench.errors import InputError
from splatbench.fsutil import read_text
from splatbench.overrides import parse_override
from splatbench.raster.options import RasterOptions
from splatbench.report_files import write_text
from splatbench.train.sh_schedule import MAX_LOOKAHEAD

#: Keys of the ``data`` table.
DATA_KEYS = ("downscale", "masks")
#: Keys of the ``raster`` table: every `RasterOptions` field but ``device`` (``TrainConfig.device``).
RASTER_KEYS = tuple(f.name for f in dataclasses.fields(RasterOptions) if f.name != "device")
#: Learning-rate fields (Adam, one optimizer per parameter group); 0 freezes a group.
LR_FIELDS = ("lr_means", "lr_means_final", "lr_log_scales", "lr_quats", "lr_opacity_logits", "lr_sh_dc",
             "lr_sh_rest")


@dataclass(frozen=True)
class TrainConfig:
    """One training run. Defaults follow graphdeco-inria's 3DGS (``arguments/__init__.py``)."""

    # --- data and output
    dataset: str = ""                 # dataset folder (COLMAP or Blender layout, see splatbench.data)
    out: str = "runs/train"           # output folder: point_cloud.ply, checkpoints/, config.toml, result.json
    layout: str = "auto"              # dataset layout: "auto", "colmap", "blender" or "llff"
    test_every: int = 8               # hold out every n-th view when the dataset gives no split
    data: dict[str, Any] = field(default_factory=dict)  # how the dataset is loaded (`--set data.downscale=8`):
                                      # downscale = N divides the image size (images_N/ when present;
                                      # splatbench.data.load_dataset); masks = false ignores a
                                      # capture's masks/; DATA_KEYS
    seed: int = 0                     # seeds torch, numpy, the view order, random backgrounds and the start
                                      # (init="random"'s draws, init_jitter)
    # --- initialisation
    init: str = "auto"                # "auto" (the dataset's points when it has them, else "sfm"; never random
                                      # unless asked), "surface" (the dataset's own points: true-surface samples
                                      # of a rendered scene, points3D of a COLMAP folder), "sfm" (pycolmap on the
                                      # training views, cached in $SPLATBENCH_CACHE/sfm), "random" (uniform in
                                      # init_region); splatbench.train.initializers, docs/training.md
    init_random_points: int = 100_000  # number of points of init="random" (graphdeco's NeRF-synthetic count)
    init_region: str = "auto"         # where init="random" samples: "convergence" (a ball where the optical axes
                                      # meet), "camera_cube" (gsplat: +-init_extent scene scales around the
                                      # cameras), "nerf_synthetic" ([-1.3, 1.3]^3, graphdeco's Blender box) or
                                      # "auto" (initializers.REGIONS says which and where each fails)
    init_extent: float = 3.0          # init_region="camera_cube": half-side in scene scales (gsplat's init_extent)
    init_jitter: float = 0.5          # surface / sfm points: each moved by a normal draw of this x its neighbour
                                      # spacing, seeded by `seed` (so seeds vary the start); 0 = as given
    init_sfm_poses: str = "known"     # init="sfm": "known" (triangulate with the dataset's poses, fixed) or
                                      # "estimated" (incremental mapping, aligned to the dataset's frame)
    init_opacity: float | str = "auto"  # initial opacity of every Gaussian in (0, 1), or "auto": the
                                      # strategy's reference value (default/none 0.1 as graphdeco, mcmc 0.5
                                      # as 3DGS-MCMC); docs/training.md#defaults-and-their-sources
    # --- schedule
    protocol: str = "quick"           # "quick": the schedule laid over `iterations` (scaled, below);
                                      # "graphdeco-30k": graphdeco's 30,000-step schedule unscaled, evaluated
                                      # in full at 7,000 and 30,000; "graphdeco-7k": that schedule stopped at
                                      # 7,000 (splatbench.train.protocol; docs/training.md#protocols)
    iterations: int = 30_000          # optimisation steps, one training view each (a protocol's own when it
                                      # is given without iterations)
    schedule: str = "scaled"          # how the step fields below and in strategy_options (refine_start,
                                      # refine_stop, reset_every, sh_interval) are read: "scaled" = in steps
                                      # of graphdeco's 30,000-iteration run, times iterations / 30,000
                                      # (graphdeco's proportions at any length); "absolute" = steps as
                                      # written (splatbench.train.schedule)
    sh_degree: int | str = 3          # maximum SH degree 0..3, or "auto" (measure each band, keep what helps)
    sh_interval: int = 1000           # raise the active SH degree by one every this many steps (scaled)
    sh_auto_min_gain_db: float = 0.1  # auto: dB of probe-view PSNR each added band must earn to be kept
    sh_auto_lookahead: int = 2        # auto: bands still tried after a band fails, judged together with it
                                      # against the last kept degree (0..2; 0 = greedy, 2 = up to degree 3)
    sh_auto_probe_views: int = 8      # auto: training views rendered to measure a band's gain (0 = all)
    sh_auto_holdout_every: int = 8    # auto: hold every n-th training view out of training until the degree
                                      # settles and measure bands on those views instead (0 = off)
    # --- learning rates (Adam, eps below); lr 0 freezes a group: no gradient is computed for it
    lr_means: float = 1.6e-4          # positions at step 0, times the scene extent
    lr_means_final: float = 1.6e-6    # positions at the last step, times the scene extent (exponential decay)
    lr_log_scales: float = 5e-3       # log scales
    lr_quats: float = 1e-3            # rotations (quaternions)
    lr_opacity_logits: float = 2.5e-2  # opacity logits
    lr_sh_dc: float = 2.5e-3          # SH band 0 (base colour)
    lr_sh_rest: float = 1.25e-4       # SH bands 1..3 (= lr_sh_dc / 20)
    adam_eps: float = 1e-15           # Adam epsilon (3DGS: 1e-15)
    # --- loss
    ssim_lambda: float = 0.2          # loss = (1 - lambda) L1 + lambda (1 - SSIM)
    ssim_window: int = 11             # SSIM Gaussian window side (pixels, odd)
    background: list[float] | str = "auto"  # RGB in [0, 1] behind the splats, or "auto": the mean colour of
                                      # the training pixels the dataset marks as empty (alpha 0, else depth 0 =
                                      # nothing hit, e.g. a constant sky), black when it marks none (3DGS)
    random_background: bool = False   # a uniformly random background colour per training step
    # --- densification (splatbench.strategies)
    strategy: str = "default"         # "none", "default" (3DGS), "absgrad" (AbsGS), "mcmc" (3DGS-MCMC), "budget" (Taming 3DGS)
    strategy_options: dict[str, Any] = field(default_factory=dict)  # fields of the strategy's dataclass
    # --- evaluation, logging, checkpoints
    eval_every: int = 0               # evaluate on the test views every this many steps (0 = only at the end)
    eval_steps: list[int] = field(default_factory=list)  # steps of a full test evaluation (PSNR, SSIM, LPIPS of
                                      # lpips_net in both input conventions, Gaussians; TrainResult.
                                      # step_evaluations), besides the protocol's and the end
    lpips_net: str = "alex"           # LPIPS v0.1 of the final test evaluation: "alex" (gsplat, NerfBaselines),
                                      # "vgg" (graphdeco's metrics.py; ~20x AlexNet's time) or "none"; the
                                      # eval_every evaluations use AlexNet (splatbench.metrics.lpips)
    lpips_scale_inputs: bool = True   # feed LPIPS images scaled to [-1, 1] (the lpips package's convention);
                                      # false: [0, 1] unscaled, as graphdeco's metrics.py does
    log_every: int = 100              # record (step, loss, PSNR, N) in the history every this many steps
    checkpoint_every: int = 0         # write checkpoints/iteration_<step>.ply every this many steps (0 = off)
    device: str = "auto"              # rasterizer backend: "cpu" (Dr.Jit LLVM), "cuda" or "auto"; the one
                                      # device setting (raster.device follows it)
    raster: RasterOptions = field(default_factory=RasterOptions)  # the rasterizer's options for every render
                                      # of the run (training steps, warm-up, SH probes, evaluation):
                                      # `--set raster.alpha_min=0.005`, a [raster] table; RASTER_KEYS.
                                      # Its device is always `device` (set on construction, never here)
    torch_threads: int = 1            # torch intra-op threads during the run (0 = torch's default); the
                                      # rasterizer has its own thread pool, and small torch ops (loss, Adam)
                                      # are fastest without oversubscribing the cores

    # ------------------------------------------------------------------ checks
    def __post_init__(self) -> None:
        if isinstance(self.raster, RasterOptions) and self.raster.device != self.device and \
                isinstance(self.device, str):  # `device` is the one device setting (module doc)
            object.__setattr__(self, "raster", dataclasses.replace(self.raster, device=self.device))
        self.validate()  # a TrainConfig that exists is valid; change one with dataclasses.replace

    def validate(self) -> TrainConfig:
        """Check every field; raise a one-line `InputError` naming the first bad one.
        Called on construction (``__post_init__``), so callers never need to.

        Also resolves ``strategy`` with ``strategy_options`` through
        `splatbench.strategies.make_strategy` (cheap: no data is touched). Returns self.
        """
        for f in dataclasses.fields(self):
            if f.name == "raster":  # a typed record, checked by its own constructor
                if not isinstance(self.raster, RasterOptions):
                    raise InputError(f"raster: expected RasterOptions (in TOML a [raster] table of "
                                     f"{', '.join(RASTER_KEYS)}), got {self.raster!r}")
                continue
            check_type(f.name, getattr(self, f.name), _field_types()[f.name])
        if self.iterations < 1:
            raise InputError(f"iterations: expected an int >= 1, got {self.iterations}")
        from splatbench.train.protocol import get_protocol

        protocol = get_protocol(self.protocol)
        protocol.check_iterations(self.iterations)
        for step in self.eval_steps:
            if not 1 <= step <= self.iterations:
                raise InputError(f"eval_steps: expected steps in 1..{self.iterations} (iterations), got {step}")
        for name in LR_FIELDS:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"{name}: expected a learning rate >= 0, got {value!r}")
        if (self.lr_means_final > 0) != (self.lr_means > 0):
            raise InputError(f"lr_means_final: expected a rate > 0 when lr_means > 0 and 0 when lr_means is 0 "
                             f"(means frozen), got {self.lr_means_final!r} with lr_means {self.lr_means!r}")
        if not (math.isfinite(self.adam_eps) and self.adam_eps > 0):
            raise InputError(f"adam_eps: expected a number > 0, got {self.adam_eps!r}")
        from splatbench.train.initializers import INITIALIZERS

        if self.init not in INITIALIZERS:
            raise InputError(f"init: unknown initialisation {self.init!r} (expected one of: {', '.join(INITIALIZERS)})")
        from splatbench.sfm import POSE_MODES
        from splatbench.train.initializers import REGIONS

        if self.init_region not in REGIONS:
            raise InputError(f"init_region: expected one of {', '.join(REGIONS)}, got {self.init_region!r}")
        if self.init_sfm_poses not in POSE_MODES:
            raise InputError(f"init_sfm_poses: expected one of {', '.join(POSE_MODES)}, got {self.init_sfm_poses!r}")
        if not (math.isfinite(self.init_extent) and self.init_extent > 0):
            raise InputError(f"init_extent: expected a number > 0, got {self.init_extent!r}")
        if not (math.isfinite(self.init_jitter) and self.init_jitter >= 0):
            raise InputError(f"init_jitter: expected a number >= 0 (0 = the points as given), got "
                             f"{self.init_jitter!r}")
        if self.layout not in ("auto", "colmap", "blender", "llff"):
            raise InputError(f"layout: expected 'auto', 'colmap', 'blender' or 'llff', got {self.layout!r}")
        for key, value in self.data.items():
            if key not in DATA_KEYS:
                raise InputError(f"data.{key}: unknown key (known: {', '.join(DATA_KEYS)})")
            if key == "masks":  # read a capture's masks/ as alphas (default true)
                if not isinstance(value, bool):
                    raise InputError(f"data.masks: expected true or false, got {value!r}")
            elif not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                raise InputError(f"data.{key}: expected an int >= 1, got {value!r}")
        check_sh_degree("sh_degree", self.sh_degree, allow_auto=True)
        positive = ("sh_interval", "log_every", "init_random_points", "ssim_window")
        for name in positive:
            if getattr(self, name) < 1:
                raise InputError(f"{name}: expected an int >= 1, got {getattr(self, name)}")
        if self.ssim_window % 2 == 0:
            raise InputError(f"ssim_window: expected an odd window side, got {self.ssim_window}")
        for name in ("test_every", "eval_every", "checkpoint_every", "sh_auto_probe_views", "sh_auto_holdout_every",
                     "torch_threads"):
            if getattr(self, name) < 0:
                raise InputError(f"{name}: expected an int >= 0, got {getattr(self, name)}")
        if isinstance(self.init_opacity, str):
            if self.init_opacity != "auto":
                raise InputError(f"init_opacity: expected a number in (0, 1) or 'auto', got {self.init_opacity!r}")
        elif not 0 < self.init_opacity < 1:
            raise InputError(f"init_opacity: expected a number in (0, 1) or 'auto', got {self.init_opacity!r}")
        if not 0 <= self.ssim_lambda <= 1:
            raise InputError(f"ssim_lambda: expected a number in [0, 1], got {self.ssim_lambda!r}")
        if not (math.isfinite(self.sh_auto_min_gain_db) and self.sh_auto_min_gain_db >= 0):
            raise InputError(f"sh_auto_min_gain_db: expected a number >= 0, got {self.sh_auto_min_gain_db!r}")
        if not 0 <= self.sh_auto_lookahead <= MAX_LOOKAHEAD:
            raise InputError(f"sh_auto_lookahead: expected an int in 0..{MAX_LOOKAHEAD} (bands tried after one "
                             f"fails; 0 = greedy, {MAX_LOOKAHEAD} = up to degree 3), got {self.sh_auto_lookahead}")
        if isinstance(self.background, str):
            if self.background != "auto":
                raise InputError(f"background: expected 3 values in [0, 1] or 'auto', got {self.background!r}")
        elif len(self.background) != 3 or not all(0 <= c <= 1 for c in self.background):
            raise InputError(f"background: expected 3 values in [0, 1] or 'auto', got {self.background!r}")
        if self.lpips_net not in ("alex", "vgg", "none"):
            raise InputError(f"lpips_net: expected 'alex', 'vgg' or 'none', got {self.lpips_net!r}")
        check_device(self.device, "device")
        from splatbench.train.schedule import SCHEDULES, check_final_window

        if self.schedule not in SCHEDULES:
            raise InputError(f"schedule: expected one of {', '.join(map(repr, SCHEDULES))}, got {self.schedule!r}")
        strategy = self.make_strategy()
        if protocol.final_window_check:
            check_final_window(strategy, self.iterations, self.schedule)
        self._check_alpha_min()
        if self.lr_means == 0 and strategy.reads_mean_gradients:
            # frozen means have no screen-space gradient (the rasterizer's backward skips it), and this
            # strategy declares that it reads it (the Strategy protocol's reads_mean_gradients)
            from splatbench.strategies import STRATEGIES

            free = [name for name, (cls, _) in STRATEGIES.items() if not cls.reads_mean_gradients]
            raise InputError(f"lr_means: 0 freezes the means, but strategy {self.strategy!r} densifies from their "
                             f"screen-space gradients (use a positive lr_means, or strategy={' or '.join(free)})")
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
                             f"{self.initial_opacity!r} (init_opacity), and alpha = opacity x G never exceeds the "
                             f"opacity: every Gaussian would be skipped and get no gradient; lower raster.alpha_min "
                             f"or raise init_opacity")

    def warnings(self) -> list[str]:
        """One line per setting that runs but likely defeats training (said before the first
        step and kept among the result's notes): an ``raster.alpha_min`` at or above the
        strategy's opacity reset value (graphdeco's 0.01) in a run with resets. After each reset
        alpha = opacity x G <= the reset value, so compositing skips every Gaussian and gives it
        no gradient; the model renders the background until nothing is left to recover. And a
        schedule whose opacity resets (two or more in the run) come sooner after each other
        than an opacity can climb back from the reset value to 0.5 (`opacity_recovery_steps`
        after the first reset): the quick protocol's scaled schedule at 100 steps resets every
        10, where the climb takes 176; the committed 2,000-step grids (every 200, climb 81)
        and graphdeco's 3,000 (climb 32) are not warned."""
        from splatbench.strategies import planned_counts

        out = []
        strategy = self.make_strategy()
        alpha_min, reset = self.raster.alpha_min, getattr(strategy, "reset_value", None)
        if reset is not None and reset <= alpha_min and planned_counts(strategy, self.iterations).opacity_resets:
            out.append(f"warning: raster.alpha_min={alpha_min!r} is at or above the opacity reset value {reset!r} of "
                       f"strategy {self.strategy!r}: after each opacity reset every Gaussian is skipped (alpha = "
                       f"opacity x G never exceeds the opacity) and gets no gradient, so training cannot recover; "
                       f"lower raster.alpha_min, raise strategy_options.reset_value, or set "
                       f"strategy_options.reset_every = 0 (no resets)")
        every = getattr(strategy, "reset_every", 0)
        if reset is not None and every and planned_counts(strategy, self.iterations).opacity_resets >= 2:
            climb = opacity_recovery_steps(self.lr_opacity_logits, reset, every, self.adam_eps)
            if climb > every:
                out.append(f"warning: strategy {self.strategy!r} resets opacities every {every} steps in this run, "
                           f"sooner than an opacity can climb back from the reset value {reset:g} to "
                           f"{RECOVERY_OPACITY:g} ({climb} steps at lr_opacity_logits {self.lr_opacity_logits:g} under "
                           f"a steady gradient): each reset comes before the model has recovered from the last; train "
                           f"longer, or set strategy_options.reset_every = 0 (no resets) or a fraction of the run "
                           f"(\"50%\") at least {climb} steps long")
        return out

    def make_strategy(self, *, scaled: bool = True):
        """The densification strategy this config names (`InputError` if unknown). A
        strategy with a ``seed`` field gets the run's ``seed`` unless the options set one.
        ``scaled``: its schedule fields in this run's steps (``schedule``, laid over
        `schedule_length`); False: as written. Step fields written as a fraction of the run
        ("25%", "1/4": of `schedule_length`) are in run steps either way."""
        from splatbench.strategies import STRATEGIES, make_strategy, strategy_fields
        from splatbench.train.schedule import resolve_run_fractions, scaled_strategy

        options = dict(self.strategy_options)
        if "seed" in strategy_fields(self.strategy) and "seed" not in options:
            options["seed"] = self.seed
        options, fixed = resolve_run_fractions(STRATEGIES[self.strategy][0].run_fraction_fields, options,
                                               self.schedule_length)
        strategy = make_strategy(self.strategy, **options)
        return scaled_strategy(strategy, self.schedule_length, self.schedule, fixed=fixed) if scaled else strategy

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

        return evaluation_steps(self.protocol, self.eval_steps, self.iterations)

    @property
    def initial_opacity(self) -> float:
        """``init_opacity``, with ``"auto"`` resolved to the strategy's ``initial_opacity``."""
        if isinstance(self.init_opacity, str):
            return float(self.make_strategy(scaled=False).initial_opacity)
        return float(self.init_opacity)

    @property
    def sh_steps(self) -> int:
        """``sh_interval`` in this run's steps (scaled under ``schedule = "scaled"``)."""
        from splatbench.train.schedule import scale_step

        return scale_step(self.sh_interval, self.schedule_length, self.schedule, interval=True)

    @property
    def downscale(self) -> int:
        """``data.downscale`` (1 when not set)."""
        return int(self.data.get("downscale", 1))

    @property
    def masks(self) -> bool:
        """``data.masks`` (true when not set): a capture's masks become its alphas."""
        return bool(self.data.get("masks", True))

    @property
    def max_sh_degree(self) -> int:
        """The highest SH degree the run may use (3 under ``"auto"``)."""
        return 3 if self.sh_degree == "auto" else int(self.sh_degree)

    # ------------------------------------------------------------------ TOML
    def to_dict(self) -> dict[str, Any]:
        """Plain TOML-ready values (lists and dicts copied; ``raster`` as the table of
        `RASTER_KEYS`, ``near`` / ``far`` left out while they are the camera's)."""
        out = {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}
        out["raster"] = {k: v for k, v in self.raster.to_dict().items() if k != "device"}
        return out

    def to_toml(self) -> str:
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, source: str = "config") -> TrainConfig:
        """A config from a mapping; unknown keys and wrong types are `InputError`."""
        if not isinstance(data, dict):
            raise InputError(f"{source}: expected a table of fields, got {type(data).__name__}")
        check_keys(data, (f.name for f in dataclasses.fields(cls)), source=source)
        types = _field_types()
        data = dict(data)
        if "raster" in data:
            data["raster"] = raster_options(data["raster"])
        for key, value in data.items():  # types before construction (whose checks assume them)
            if key != "raster":
                check_type(key, coerce(value, types[key]), types[key])
        data = {k: v if k == "raster" else coerce(v, types[k]) for k, v in data.items()}
        if "protocol" in data and "iterations" not in data:
            data["iterations"] = _protocol_iterations(data["protocol"], cls.iterations)
        return cls(**data)

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
    (1,000 steps), 81 at 200 (the committed 2,000-step grids, every 200) and 32 at graphdeco's
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
    """A copy of ``config`` with ``key=value`` overrides applied (types coerced). A
    ``raster.tile_size`` set without ``raster.pixel_block``, on a config whose block is the
    default for its tile, takes the default for the new tile (`RasterOptions.pixel_block`)."""
    data = config.to_dict()
    keys = set()
    for item in overrides:
        key, value = parse_override(item)
        keys.add(key)
        table = key.split(".", 1)[0]
        if "." in key and table in ("strategy_options", "data", "raster"):
            sub = key.split(".", 1)[1]
            if not sub:
                raise InputError(f"--set: empty {table} key in {item!r}")
            data[table] = {**data[table], sub: value}
        else:
            data[key] = value
    if "protocol" in keys and "iterations" not in keys and data["protocol"] != config.protocol:
        data["iterations"] = _protocol_iterations(data["protocol"], config.iterations)  # the protocol's length
    if "raster.tile_size" in keys and "raster.pixel_block" not in keys and isinstance(data["raster"], dict) and \
            config.raster.pixel_block == RasterOptions(tile_size=config.raster.tile_size).pixel_block:
        data["raster"] = {k: v for k, v in data["raster"].items() if k != "pixel_block"}  # the default follows the tile
    return TrainConfig.from_dict(data, source="--set")


# ---------------------------------------------------------------------- helpers
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


def _protocol_iterations(name: Any, otherwise: int) -> int:
    """The iterations protocol ``name`` runs when none are given (``otherwise`` when it
    sets none, or is not a protocol: validation names that)."""
    from splatbench.train.protocol import PROTOCOLS

    protocol = PROTOCOLS.get(name) if isinstance(name, str) else None
    return otherwise if protocol is None or protocol.iterations is None else protocol.iterations


@functools.cache
def _field_types() -> dict[str, Any]:
    """TrainConfig's field types, resolved once per process: `typing.get_type_hints` compiles every
    annotation string again on each call, and validation asks for them once per field, which made
    expanding a training grid cost about 0.1 s per run (read only; never mutated)."""
    return typing.get_type_hints(TrainConfig)


def _plain(value: Any) -> Any:
    if isinstance(value, list):
        return list(value)
    if isinstance(value, dict):
        return dict(value)
    return value


__all__ = ["TrainConfig", "LR_FIELDS", "RASTER_KEYS", "raster_options", "load_config", "save_config", "parse_override",
           "apply_overrides"]
