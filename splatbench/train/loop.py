"""The training loop: `train(config) -> TrainResult`, built on `Trainer`.

One step (graphdeco-inria's order, with gsplat's strategy hooks):

1. SH schedule and position learning rate for this step; next view of a seeded
   permutation (a fresh one every epoch); background (fixed or random).
2. ``splatbench.rasterize`` of the current parameters (SH sliced to the active
   degree; frozen groups carry no gradient), ``absgrad`` only if the strategy uses it.
3. Loss ``(1 - λ) L1 + λ (1 - SSIM)`` plus the strategy's regularisation;
   ``strategy.pre_backward``; backward -- the regularisation's, then one from the loss
   through the rasterizer (a hook on the image times the two parts for benchmarks);
   one Adam step per group; ``strategy.post_backward`` (densify / prune / relocate).

Everything random is seeded from ``config.seed`` (torch's global generator, a
dedicated `torch.Generator` for view order and backgrounds, numpy for random init),
and the rasterizer is bit-deterministic, so a seed and a config give the same PLY
bytes on the same machine.

Size (~450 lines, over the ~400 guideline on purpose): `Trainer` (one step, its
state) and `train` (the run around it: evaluation, checkpoints, resume, interrupt)
are one job, a training run; what is separable already lives beside it (config,
params, schedule, sh_schedule, losses, dssim, metrics, checkpoint, result).
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import drjit as dr
import numpy as np
import torch

from splatbench.errors import InputError
from splatbench.interrupt import Interrupted, deferred
from splatbench.ply import ViewHints
from splatbench.raster.torch_bridge import parameter_device, rasterize
from splatbench.report_files import write_text
from splatbench.scenes.orientation import dataset_up, rig_up
from splatbench.strategies import topology_counts
from splatbench.strategies.base import StepContext
from splatbench.train.config import TrainConfig, save_config
from splatbench.train.initializers import InitSettings, initialize
from splatbench.train.losses import photometric_loss
from splatbench.metrics.image import psnr, ssim_metric
from splatbench.metrics.timing import device_sync
from splatbench.train.protocol import get_protocol
from splatbench.train.params import (ExponentialLR, gaussians_from_params, make_optimizers, params_from_gaussians,
                                     refreeze, scene_extent, set_lr)
from splatbench.train.result import EvalPoint, HistoryPoint, StepEvaluation, TrainResult
from splatbench.train.sh_schedule import BandMeasure, ShSchedule


class StepStatus(NamedTuple):
    """What one step reports to a progress callback."""

    step: int            # 0-based index of the step just run
    loss: float          # its training loss
    psnr: float          # PSNR (dB) of its training view
    num_gaussians: int   # N after the step
    sh_degree: int       # active SH degree


@dataclass
class StepTimes:
    """Seconds spent per phase, summed over steps (read by ``splatbench bench train``)."""

    raster_forward: float = 0.0   # splatbench.rasterize (Dr.Jit forward, copies to torch)
    loss: float = 0.0             # loss forward and its backward down to the rendered image
    raster_backward: float = 0.0  # the rasterizer's backward (image cotangent -> parameter gradients)
    optimizer: float = 0.0        # zero_grad and one Adam step per group
    strategy: float = 0.0         # strategy hooks (pre/post backward, regularisation)
    other: float = 0.0            # schedules, view choice, bookkeeping
    steps: int = 0                # steps timed

    def total(self) -> float:
        return self.raster_forward + self.loss + self.raster_backward + self.optimizer + self.strategy + self.other


@dataclass
class Evaluation:
    """Test-split metrics of the current model."""

    psnr: float | None
    ssim: float | None
    lpips: dict[tuple[str, bool], float]  # (net, scale_inputs) -> mean LPIPS, for each one asked for
    render_ms_per_view: float | None
    views: int
    per_view_psnr: list[float] = field(default_factory=list)
    per_view_lpips: dict[tuple[str, bool], list[float]] = field(default_factory=dict)  # (net, scale_inputs) -> each test view's LPIPS


#: Where a run's background came from (`resolve_background`; `TrainResult.background_source`).
BACKGROUND_SOURCES = ("config", "masks", "alpha", "depth", "none")


def resolve_background(background: list[float] | str, split, masks: str = "") -> tuple[torch.Tensor, str, str]:
    """The render background [3], where it came from (one of `BACKGROUND_SOURCES`) and how it
    was chosen, in words.

    ``"auto"``: white for a masked capture (``masks``: the folder its alphas came from;
    the object on white, as NeRF-synthetic is evaluated; source "masks"); else the mean
    ground-truth colour of the pixels the split marks as empty -- alpha 0 when it has
    alphas ("alpha"), else depth 0 ("depth": nothing hit, a constant environment shows
    there) -- or black when it marks none ("none": 3DGS's default). A given RGB: "config"."""
    if not isinstance(background, str):
        return torch.tensor(background, dtype=torch.float32), "config", f"background {list(background)} (config)"
    if masks:
        return torch.ones(3), "masks", (
            f"background auto: white [1.0, 1.0, 1.0] (a masked capture, {masks}/: the object on white, as "
            f"NeRF-synthetic; training targets and test views are composited over it with their masks; set "
            f"background or random_background for another)")
    empty = None
    if split.alpha_pixels is not None:
        empty, source, how = split.alpha_pixels == 0, "alpha", "alpha 0"  # 8-bit 0 is exactly alpha 0
    elif split.depths is not None:
        empty, source, how = split.depths == 0, "depth", "depth 0 (nothing hit)"
    if empty is None or not empty.any():
        return torch.zeros(3), "none", "background auto: black (the dataset marks no empty pixels)"
    # the empty pixels of each view in turn (one float view at a time), in the order of a boolean
    # index over the whole stack, so the mean is the same sum as before
    pixels = np.concatenate([split.image(i)[empty[i]] for i in range(len(split))])
    colour = pixels.astype(np.float64).mean(axis=0)
    rgb = [round(float(c), 4) for c in colour]
    return torch.tensor(rgb, dtype=torch.float32), source, \
        f"background auto: {rgb}, the mean of {int(empty.sum())} training pixels with {how}"


class Trainer:
    """A training run in progress. ``Trainer(config)`` validates everything and sets up
    (no rendering); `step` runs one iteration; `evaluate` measures the test split."""

    def __init__(self, config: TrainConfig, *, dataset=None, say: Callable[[str], None] | None = None,
                 resuming: bool = False) -> None:
        # ``say``: set-up lines as they happen; the start made (init's note) only when not
        # ``resuming`` (a resumed run's model is its checkpoint's; the note stays among its notes)
        self.config = config  # validated on construction
        self.strategy = config.make_strategy()
        if dataset is None:
            if not config.dataset:
                raise InputError("dataset: no dataset folder given")
            from splatbench.data.dataset import load_dataset

            dataset = load_dataset(config.dataset, layout=config.data.layout, test_every=config.data.test_every,
                                   background=self._gt_background(config), downscale=config.data.downscale,
                                   masks=config.data.masks, say=say)
        self.dataset = dataset
        train = dataset.train
        if len(train) == 0:
            raise InputError(f"dataset: {str(dataset.root)!r} has no training views")
        if config.random_background and train.alpha_pixels is None:
            raise InputError("random_background: the dataset's images have no alpha channel, so a random "
                             "background cannot be composited under the ground truth")
        torch.manual_seed(config.seed)
        np.random.seed(config.seed % 2**32)
        init = initialize(config.init.method, dataset, InitSettings(
            config.sh.max_degree, config.initial_opacity, config.init.random_points, config.seed, say=say,
            region=config.init.region, extent=config.init.extent, jitter=config.init.jitter,
            sfm_poses=config.init.sfm_poses, say_note=not resuming))
        gaussians, self.init_summary, self.init_note = init.gaussians, init.summary, init.note
        self.init_warns = init.warning
        self.extent = scene_extent(train.cameras)
        self.lrs = config.optim.rates()
        # parameters, Adam's moments, the strategy's state, targets and the loss live where the
        # rasterizer runs (torch's CUDA device on CUDA): no host round trip per step
        self.device = parameter_device(config.device)
        # the step's stage times wait for the GPU's queued work at each boundary (on the CPU: nothing)
        self._sync = device_sync(self.device)
        self.params = params_from_gaussians(gaussians, self.lrs, self.device)
        self.optimizers = make_optimizers(self.params, self.lrs, config.optim.adam_eps)
        # decays over the protocol's schedule (30,000 steps under graphdeco's, however early the run stops)
        self.means_lr = ExponentialLR(config.optim.lr_means, config.optim.lr_means_final, config.schedule_length, self.extent)
        self.state = self.strategy.initialize_state(self.params)
        self.absgrad = bool(self.strategy.absgrad)  # declared by the Strategy protocol
        self.sh = ShSchedule(config.sh.degree, config.sh_steps, min_gain_db=config.sh.auto_min_gain_db,
                             lookahead=config.sh.auto_lookahead)
        # the training views stay as the dataset holds them (8-bit); each step converts its own (`target`)
        # RGBA ground truth is composited on `gt_background` (by load_dataset); renders use `background`
        gt_background = torch.tensor(self._gt_background(config), dtype=torch.float32)
        background, self.background_source, self.background_note = resolve_background(
            config.background, train, getattr(dataset, "masks", ""))
        # host copies (float32 values) for each render's background argument and the compositing
        # check: reading them back from the device every step would wait for the GPU
        self._gt_rgb, self._background_rgb = gt_background.tolist(), background.tolist()
        self.gt_background, self.background = gt_background.to(self.device), background.to(self.device)
        # recorded in the saved PLY for `splatbench render`: a splatbench render's declared up, else
        # (a capture) the up its cameras share (`rig_up`), said in a note
        self.world_up, self.up_note = dataset_up(dataset.root, train.cameras), None
        if self.world_up is None and len(train.cameras):
            self.world_up = rig_up(train.cameras)
            self.up_note = (f"world up {np.round(self.world_up, 3).tolist()} estimated from the training cameras "
                            f"(recorded in the PLY for splatbench render; --up overrides it there)")
        self.generator = torch.Generator().manual_seed(config.seed)
        self._order: list[int] = []
        k = config.sh.auto_holdout_every if self.sh.auto else 0
        # auto SH with a holdout: these training views are kept out of training until the degree settles
        self.holdout = [i for i in range(len(train)) if i % k == k // 2] if k and len(train) >= 2 * k else []
        self.step_index = 0
        self.times = StepTimes()

    @staticmethod
    def _gt_background(config: TrainConfig) -> list[float]:
        return [0.0, 0.0, 0.0] if isinstance(config.background, str) else list(config.background)

    # ------------------------------------------------------------------ state
    @property
    def num_gaussians(self) -> int:
        return int(self.params["means"].shape[0])

    def gaussians(self):
        """The current model as `splatbench.Gaussians`, SH truncated to the active degree."""
        return gaussians_from_params(self.params, self.sh.degree)

    def save_ply(self, path: str | Path) -> Path:
        """Write the current model as a graphdeco 3DGS PLY (atomically: temp file + rename),
        with the dataset's up (when declared) and the background in its header comments."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        up = None if self.world_up is None else tuple(self.world_up.tolist())
        self.gaussians().to_ply(p, ViewHints(up=up, background=tuple(self._background_rgb)))
        return p

    def _sh(self, degree: int) -> torch.Tensor:
        k = (degree + 1) ** 2
        return torch.cat([self.params["sh_dc"], self.params["sh_rest"][:, : k - 1]], dim=1)

    def _render(self, camera, degree: int, background) -> tuple:
        p = self.params
        return rasterize(p["means"], p["log_scales"], p["quats"], p["opacity_logits"], self._sh(degree), camera,
                         sh_degree=degree, background=background, absgrad=self.absgrad, options=self.config.raster)

    def _next_view(self) -> int:
        if not self._order:
            views = torch.randperm(len(self.dataset.train), generator=self.generator).tolist()
            if self.holdout and not self.sh.settled:
                views = [v for v in views if v not in self.holdout]
            self._order = views
        return self._order.pop()

    def target(self, view: int) -> torch.Tensor:
        """Training view ``view`` as float32 [H, W, 3] (converted from the dataset's 8-bit
        pixels for this step only; `splatbench.data.Split.image`)."""
        return torch.from_numpy(self.dataset.train.image(view)).to(self.device)

    # ------------------------------------------------------------------ one step
    def step(self, before_refine: Callable[[], None] | None = None, refine: bool = True) -> StepStatus:
        """Run one optimisation step and return its status. ``before_refine``: called after the step's
        optimizer update, before the strategy's `post_backward` (its refinement, opacity reset), not
        timed as the step's (an evaluation in graphdeco's order: `EvalConfig.before_refine`);
        ``refine=False`` leaves that `post_backward` out (the last step of such a run: nothing follows
        its evaluation, so its model is the one evaluated)."""
        cfg, t, sync = self.config, self.times, self._sync
        t0 = time.perf_counter()
        step, n_before = self.step_index, self.num_gaussians
        degree = self.sh.update(step, self.probe_band)
        lr = self.means_lr(step)
        set_lr(self.optimizers["means"], lr)
        view = self._next_view()
        camera = self.dataset.train.cameras[view]
        target = self.target(view)
        if cfg.random_background:
            drawn = torch.rand(3, generator=self.generator)  # the CPU stream on every device
            bg, bg_rgb = drawn.to(self.device), drawn.tolist()
        else:
            bg, bg_rgb = self.background, list(self._background_rgb)
        alphas = self.dataset.train.alpha_pixels
        if alphas is not None and bg_rgb != self._gt_rgb:
            alpha = torch.from_numpy(self.dataset.train.alpha(view)).to(self.device)
            target = target + (bg - self.gt_background) * (1 - alpha)[..., None]
        for opt in self.optimizers.values():
            opt.zero_grad(set_to_none=True)
        sync()
        t1 = time.perf_counter()
        rgb, _, _, info = self._render(camera, degree, bg_rgb)
        sync()
        t2 = time.perf_counter()
        loss = photometric_loss(rgb, target, cfg.loss.ssim_lambda, cfg.loss.ssim_window)
        sync()
        t3 = time.perf_counter()
        reg = self.strategy.regularization(self.params, step)
        ctx = StepContext(step=step, info=info, scene_extent=self.extent, means_lr=lr, loss=float(loss.detach()))
        self.strategy.pre_backward(self.params, self.optimizers, self.state, ctx)
        sync()
        t4 = time.perf_counter()
        if isinstance(reg, torch.Tensor) and reg.requires_grad:
            reg.backward()  # first: the parameters' gradients are reg's, then the rasterizer's added
        t5 = t4
        if rgb.requires_grad:
            # one backward from the scalar loss (no explicit cotangent: `Tensor.backward(grad)` would
            # import torch.fx's sympy, ~33 MB resident); the hook marks where the loss's part ends
            # and the rasterizer's begins, for the stage times
            def mark(_grad):
                nonlocal t5
                sync()
                t5 = time.perf_counter()

            rgb.register_hook(mark)
            loss.backward()
        else:
            sync()
            t5 = time.perf_counter()
        sync()
        t6 = time.perf_counter()
        for opt in self.optimizers.values():
            opt.step()
        sync()
        t7 = t7b = time.perf_counter()
        if before_refine is not None:
            before_refine()
            sync()
            t7b = time.perf_counter()
        if refine:
            self.strategy.post_backward(self.params, self.optimizers, self.state, ctx)
        refreeze(self.params, self.lrs)
        if self.num_gaussians != n_before:
            # Dr.Jit keeps freed buffers in its allocation cache for reuse; those sized for the
            # old N go mostly unused, so hand them back (docs/benchmarks.md, "Training": the
            # resident set and its peak; the next step pays the page faults once)
            dr.flush_malloc_cache()
        sync()
        t8 = time.perf_counter()
        self.step_index += 1
        t.raster_forward += t2 - t1
        t.loss += (t3 - t2) + (t5 - t4)
        t.raster_backward += t6 - t5
        t.optimizer += t7 - t6
        t.strategy += (t4 - t3) + (t8 - t7b)
        t.other += t1 - t0
        t.steps += 1
        total = float(loss.detach()) + float(reg.detach() if isinstance(reg, torch.Tensor) else reg)
        return StepStatus(step, total, psnr(rgb.detach(), target), self.num_gaussians, degree)

    # ------------------------------------------------------------------ warm-up
    def warm_up(self) -> None:
        """Compile (or load from Dr.Jit's cache) every rasterizer kernel training and
        evaluation will use -- forward and backward at each SH degree the schedule can
        reach, and the forward without gradients -- and the SSIM kernels of the loss and
        of the evaluation, so that no timed section pays for compilation. Changes no
        parameter, optimizer state or random stream: the gradients it leaves are cleared
        by the next step's ``zero_grad``."""
        camera = self.dataset.train.cameras[0]
        for degree in range(self.config.sh.max_degree + 1):
            rgb, _, _, _ = self._render(camera, degree, list(self._background_rgb))
            if rgb.requires_grad:
                rgb.sum().backward()
            with torch.no_grad():
                self._render(camera, degree, list(self._background_rgb))
        # the Dr.Jit kernels of the loss's D-SSIM and of the evaluation's SSIM (`splatbench.metrics.ssim`)
        image, target = rgb.detach().requires_grad_(True), self.target(0)
        photometric_loss(image, target, self.config.loss.ssim_lambda, self.config.loss.ssim_window)
        ssim_metric(image.detach(), target, self.config.loss.ssim_window)
        for opt in self.optimizers.values():
            opt.zero_grad(set_to_none=True)

    # ------------------------------------------------------------------ SH probe
    @torch.no_grad()
    def probe_band(self, degree: int, baseline: int) -> BandMeasure:
        """Probe-view PSNR gain of SH degree ``degree`` over degree ``baseline`` (< degree)
        and the relative coefficient energy of bands ``baseline+1..degree``."""
        cams = self.dataset.train.cameras
        k = self.config.sh.auto_probe_views
        if self.holdout:
            idx = self.holdout
        elif k == 0 or k >= len(cams):
            idx = list(range(len(cams)))
        else:
            idx = sorted({int(i) for i in np.linspace(0, len(cams) - 1, k).round()})
        gains, visible = [], torch.zeros(self.num_gaussians, device=self.device)
        for i in idx:
            with_band, _, _, info = self._render(cams[i], degree, list(self._background_rgb))
            without, _, _, _ = self._render(cams[i], baseline, list(self._background_rgb))
            target = self.target(i)
            gains.append(psnr(with_band, target) - psnr(without, target))
            visible += info.visible.to(self.device).float()
        w = torch.sigmoid(self.params["opacity_logits"]) * visible
        lo, hi = (baseline + 1) ** 2 - 1, (degree + 1) ** 2 - 1  # rows of bands baseline+1..degree in sh_rest
        e_band = (w[:, None, None] * self.params["sh_rest"][:, lo:hi] ** 2).sum()
        e_dc = (w[:, None, None] * self.params["sh_dc"] ** 2).sum()
        ratio = float(torch.sqrt(e_band / e_dc)) if float(e_dc) > 0 else 0.0
        return BandMeasure(float(np.mean(gains)), ratio, len(idx), bool(self.holdout))

    # ------------------------------------------------------------------ evaluation
    @torch.no_grad()
    def evaluate(self, lpips: Sequence[tuple[str, bool]] = ()) -> Evaluation:
        """PSNR, SSIM and LPIPS (each ``(net, scale_inputs)`` of ``lpips``,
        `splatbench.metrics.lpips`) of the current model on the test views."""
        from splatbench.metrics import lpips as lpips_distance

        test = self.dataset.test
        if len(test) == 0:
            return Evaluation(None, None, {}, None, 0)
        psnrs, ssims, seconds = [], [], 0.0
        lps: dict[tuple[str, bool], list[float]] = {spec: [] for spec in lpips}
        for i, camera in enumerate(test.cameras):
            t0 = time.perf_counter()
            rgb, _, _, _ = self._render(camera, self.sh.degree, list(self._background_rgb))
            seconds += time.perf_counter() - t0
            gt = torch.from_numpy(test.image(i)).to(self.device)  # one view as float at a time
            if test.alpha_pixels is not None and self._background_rgb != self._gt_rgb:
                # composited over the render background, as the training targets are (`step`)
                alpha = torch.from_numpy(test.alpha(i)).to(self.device)
                gt = gt + (self.background - self.gt_background) * (1 - alpha)[..., None]
            psnrs.append(psnr(rgb, gt))
            ssims.append(ssim_metric(rgb, gt, self.config.loss.ssim_window))
            for (net, scaled), values in lps.items():
                values.append(lpips_distance(rgb, gt, net=net, scale_inputs=scaled))
        return Evaluation(float(np.mean(psnrs)), float(np.mean(ssims)), {k: float(np.mean(v)) for k, v in lps.items()},
                          1e3 * seconds / len(test), len(test), psnrs, lps)


#: The LPIPS of the ``eval_every`` evaluations (the curves): AlexNet, inputs scaled (cheap: ~1/20 of VGG).
CURVE_LPIPS = ("alex", True)


def lpips_nets(config: TrainConfig, num_test: int) -> tuple[list[tuple[str, bool]], list[tuple[str, bool]], str]:
    """(the final evaluation's LPIPS ``[(net, scale_inputs)]``, the curves', a note when LPIPS is
    skipped) before the images' size is known: none with ``lpips_net="none"``, no test views, or
    without the weights installed (`lpips_plan` then drops what the images are too small for)."""
    from splatbench.metrics.perceptual import weights_path

    if config.eval.lpips_net == "none" or num_test == 0:
        return [], [], ""
    try:
        weights_path(config.eval.lpips_net), weights_path(CURVE_LPIPS[0])
    except InputError as exc:
        return [], [], f"LPIPS skipped: {exc}"
    return [(config.eval.lpips_net, config.eval.lpips_scale_inputs)], [CURVE_LPIPS], ""


def lpips_plan(config: TrainConfig, test) -> tuple[list[tuple[str, bool]], list[tuple[str, bool]], str]:
    """(the final evaluation's LPIPS ``[(net, scale_inputs)]``, the curves', a note when
    LPIPS is skipped): `lpips_nets`, less each net whose first layers need more pixels a side
    than the test images have (`splatbench.metrics.perceptual.MIN_SIDE`: AlexNet 31, VGG 16)."""
    from splatbench.metrics.perceptual import MIN_SIDE

    final, curves, note = lpips_nets(config, len(test))
    height, width = test.image_size if final else (0, 0)
    small = sorted({net for net, _ in (*final, *curves) if MIN_SIDE[net] > min(height, width)})
    if not final or not small:
        return final, curves, note
    need = ", ".join(f"{net} {MIN_SIDE[net]} px" for net in small)
    return ([n for n in final if n[0] not in small], [n for n in curves if n[0] not in small],
            f"LPIPS ({', '.join(small)}) skipped: test images of {width}x{height} px are under what the "
            f"net needs a side ({need}); a larger data.resolution or a smaller data.downscale computes it")


def step_lpips(final: list[tuple[str, bool]]) -> list[tuple[str, bool]]:
    """The LPIPS of a full step evaluation: the final net in both input conventions
    (none when the final evaluation computes none)."""
    return [(final[0][0], True), (final[0][0], False)] if final else []


def _step_evaluation(step: int, ev: Evaluation, net: str, num_gaussians: int, seconds: float) -> StepEvaluation:
    return StepEvaluation(step, ev.psnr, ev.ssim, net if net else "", ev.lpips.get((net, True)),
                          ev.lpips.get((net, False)), num_gaussians, round(seconds, 3), ev.views)


def train(config: TrainConfig, *, progress: Callable[[StepStatus], None] | None = None,
          dataset=None, resume: str | Path | None = None, say: Callable[[str], None] | None = None) -> TrainResult:
    """Train 3DGS on ``config.dataset`` and return the measured `TrainResult`.

    Every input problem (config field, dataset, initialisation) is a one-line
    `InputError` raised before the first render. Writes under ``config.out``:
    ``config.toml`` (the resolved config), ``checkpoints/iteration_<step>.ply`` every
    ``checkpoint_every`` steps and when a stop signal ends training early (then
    `splatbench.interrupt.Interrupted` is raised, naming that checkpoint), each with the
    full state beside it (``iteration_<step>.pt``, `splatbench.train.checkpoint`),
    ``point_cloud.ply`` (the final model) and ``result.json``. ``progress`` is called
    after every step; ``dataset`` (a loaded `splatbench.data.Dataset`) replaces reading
    ``config.dataset``; ``resume`` (a ``.pt`` checkpoint of a run with the same config)
    continues that run exactly. ``say`` gets set-up lines as they happen, before the first
    step (init="sfm": ``SfM: running pycolmap ...`` / ``SfM: reusing ...``, then its result
    note, which is also among the result's notes).

    Example::

        result = train(TrainConfig(dataset="data/scenes/diffuse-128", iterations=2000))
        result.test_psnr, result.num_gaussians, result.ply_path
    """
    with torch_threads(config.torch_threads):
        return _train(config, progress, dataset, resume, say)


@contextmanager
def torch_threads(n: int):
    """Run with ``n`` torch intra-op threads (0: leave torch's setting), then restore it."""
    before = torch.get_num_threads()
    if n:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def checkpoint_path(out: str | Path, step: int) -> Path:
    """``<out>/checkpoints/iteration_<step>.ply``: the model after ``step`` steps (its full
    state, for ``resume``, is the ``.pt`` file beside it)."""
    return Path(out) / "checkpoints" / f"iteration_{step}.ply"


def _save_checkpoint(trainer: Trainer, out: Path, extra: dict) -> Path:
    """Write the model after the last finished step (PLY) and its full state (``.pt``),
    with stop signals held while they are written; return the PLY's path."""
    from splatbench.train.checkpoint import save_checkpoint

    path = checkpoint_path(out, trainer.step_index)
    with deferred():
        if not path.is_file():  # written already when the signal came right after a checkpoint
            trainer.save_ply(path)
            save_checkpoint(trainer, path.with_suffix(".pt"), extra=extra)
    return path


def _schedule_note(strategy, config: TrainConfig) -> str | None:
    """The strategy's `schedule_note` for this run (optional), with the protocol's advice
    where the method takes an ``advice`` (a named protocol: only its full length keeps it)."""
    note = getattr(strategy, "schedule_note", None)
    if note is None:
        return None
    advice = get_protocol(config.protocol).schedule_advice
    if advice is not None and "advice" in inspect.signature(note).parameters:
        return note(config.iterations, advice=advice)
    return note(config.iterations)


def _image_size(dataset) -> list[int]:
    """[width, height] of the dataset's test images (its training images where it has no test
    split): the size the run trained and was evaluated at."""
    split = dataset.test if len(dataset.test) else dataset.train
    height, width = split.image_size
    return [int(width), int(height)]


def _train(config: TrainConfig, progress, dataset, resume, say) -> TrainResult:
    from splatbench.metrics.load import Load, process_cpu_seconds
    from splatbench.metrics.machine import resolve_device
    from splatbench.metrics.memory import peak_rss_mb
    from splatbench.train.checkpoint import load_checkpoint, resume_line

    out = Path(config.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"out: {str(out)!r} is a file, not a folder; choose another output folder")
    try:
        trainer = Trainer(config, dataset=dataset, say=say, resuming=resume is not None)
    except Interrupted as exc:
        raise Interrupted(exc.signum, "nothing kept: training had not started (loading the dataset, "
                                      "initialising)") from None
    history: list[HistoryPoint] = []
    evaluations: list[EvalPoint] = []
    step_evaluations: list[StepEvaluation] = []
    loop_seconds = cpu_seconds = 0.0
    resumed: list[str] = []
    resumed_step = None
    if resume is not None:
        extra = load_checkpoint(trainer, resume)
        resumed_step = trainer.step_index
        resumed.append(resume_line(resume, trainer.step_index, config.iterations))
        history, evaluations = list(extra.get("history", [])), list(extra.get("evaluations", []))
        step_evaluations = list(extra.get("step_evaluations", []))
        loop_seconds = float(extra.get("loop_seconds", 0.0))
        cpu_seconds = float(extra.get("cpu_seconds", 0.0))
    save_config(config, out / "config.toml")
    final_lpips, curve_lpips, lpips_note = lpips_plan(config, trainer.dataset.test)
    full_steps = set(config.evaluation_steps)  # the protocol's 7K / 30K columns (splatbench.train.protocol)
    full_lpips = step_lpips(final_lpips) if full_steps else []
    net = final_lpips[0][0] if final_lpips else ""

    def state() -> dict:
        return {"history": history, "evaluations": evaluations, "loop_seconds": loop_seconds,
                "cpu_seconds": cpu_seconds, "step_evaluations": step_evaluations}

    config_warnings = config.warnings()
    if say is not None:
        for line in config_warnings:
            say(line)
    status = None
    load = Load.start()
    try:
        t0 = time.perf_counter()
        trainer.warm_up()  # outside every timed section (TrainResult.warmup_seconds); touches no state
        warmup_seconds = time.perf_counter() - t0
        first = config.eval.before_refine  # graphdeco's order: a due evaluation inside its step
        for _ in range(config.iterations - trainer.step_index):
            done = trainer.step_index + 1  # the completed steps once this one is
            full = done in full_steps and done < config.iterations  # the last step's is the final evaluation
            due = full or bool(config.eval.every and done % config.eval.every == 0 and done < config.iterations)
            lpips_now = list(dict.fromkeys(full_lpips + curve_lpips)) if full else curve_lpips
            early: dict[str, Any] = {}

            def evaluate_early() -> None:  # graphdeco's order: inside the step, before its refinement
                e0, ec0 = time.perf_counter(), process_cpu_seconds()
                early["ev"] = trainer.evaluate(lpips_now)
                early["seconds"], early["cpu"] = time.perf_counter() - e0, process_cpu_seconds() - ec0

            with deferred():  # a stop signal ends the run between steps, never inside one
                t0, c0 = time.perf_counter(), process_cpu_seconds()
                status = trainer.step(evaluate_early if first and due else None,
                                      refine=not (first and done == config.iterations))
                loop_seconds += time.perf_counter() - t0 - early.get("seconds", 0.0)
                cpu_seconds += process_cpu_seconds() - c0 - early.get("cpu", 0.0)
            if status.step % config.log_every == 0 or done == config.iterations:
                history.append(HistoryPoint(status.step, status.loss, status.psnr, status.num_gaussians))
            if progress is not None:
                progress(status)
            if due:
                ev = early["ev"] if "ev" in early else trainer.evaluate(lpips_now)
                if ev.psnr is not None:
                    evaluations.append(EvalPoint(done, ev.psnr, ev.ssim, ev.lpips.get(CURVE_LPIPS)))
                    if full:
                        step_evaluations.append(_step_evaluation(done, ev, net, trainer.num_gaussians, loop_seconds))
            if config.checkpoint_every and done % config.checkpoint_every == 0:
                _save_checkpoint(trainer, out, state())
        t0, c0 = time.perf_counter(), process_cpu_seconds()
        trainer.sh.finish(trainer.step_index, trainer.probe_band)
        loop_seconds += time.perf_counter() - t0
        cpu_seconds += process_cpu_seconds() - c0
        with deferred():
            ply = trainer.save_ply(out / "point_cloud.ply")
    except Interrupted as exc:
        path = _save_checkpoint(trainer, out, state())
        raise Interrupted(exc.signum, f"kept the last checkpoint {path} (the model after "
                                      f"{trainer.step_index} of {config.iterations} steps; resume with "
                                      f"--resume {path.with_suffix('.pt')})") from None
    try:
        ev = trainer.evaluate(list(dict.fromkeys(final_lpips + full_lpips + curve_lpips)))
    except Interrupted as exc:
        raise Interrupted(exc.signum, f"kept the final model {ply} (not evaluated)") from None
    notes = resumed + list(trainer.dataset.notes) \
        + ([trainer.init_note] if trainer.init_note and not trainer.init_warns else []) \
        + [trainer.background_note] + ([trainer.up_note] if trainer.up_note else []) \
        + ([lpips_note] if lpips_note else [])
    early_note = get_protocol(config.protocol).early_stop_note(config.iterations)
    if early_note:
        notes.append(early_note)
    # what the run warns of (TrainResult.warnings): the config's, the random start's region, the strategy's
    # schedule and outcome where they warn ("warning: ...", splatbench.strategies.base; an outcome without it,
    # e.g. the budget strategy's prune in its last refinement, is a note), an empty model
    warnings = config_warnings + ([trainer.init_note] if trainer.init_note and trainer.init_warns else [])
    outcome_note = getattr(trainer.strategy, "outcome_note", lambda _: None)(trainer.state)  # optional
    for said in (_schedule_note(trainer.strategy, config), outcome_note):
        if said:
            (warnings if said.startswith("warning:") else notes).append(said)
    if trainer.num_gaussians == 0:
        gone = next((h.step for h in history if h.num_gaussians == 0), trainer.step_index)
        warnings.append(f"warning: the model is empty: every Gaussian was pruned (none left from step {gone} on), so "
                        f"it renders the background only; start from more points (init=surface or random, or SfM "
                        f"with more registered views)")
    if ev.views == 0:
        notes.append("no test views: test metrics are None")
    else:
        evaluations.append(EvalPoint(trainer.step_index, ev.psnr, ev.ssim, ev.lpips.get(CURVE_LPIPS)))
        if full_steps:
            step_evaluations.append(_step_evaluation(trainer.step_index, ev, net, trainer.num_gaussians,
                                                     loop_seconds))
    result = TrainResult(
        test_psnr=ev.psnr, test_ssim=ev.ssim, test_lpips=ev.lpips.get(final_lpips[0]) if final_lpips else None,
        lpips_net=final_lpips[0][0] if final_lpips else "", lpips_scale_inputs=config.eval.lpips_scale_inputs,
        cpu_seconds=round(cpu_seconds, 3), load=load.stop().metrics(),
        num_gaussians=trainer.num_gaussians,
        train_seconds=round(loop_seconds, 3), iterations=trainer.step_index, sh_degree=trainer.sh.degree,
        sh_degree_reason=trainer.sh.reason, ply_path=str(ply), render_ms_per_view=ev.render_ms_per_view,
        peak_rss_mb=round(peak_rss_mb(), 1), strategy=trainer.strategy.name, scene_extent=trainer.extent,
        test_views=ev.views, history=history, evaluations=evaluations,
        sh_decisions=[d._asdict() for d in trainer.sh.decisions], notes=notes, warnings=warnings,
        init=trainer.init_summary,
        warmup_seconds=round(warmup_seconds, 3), resumed_step=resumed_step, protocol=config.protocol,
        raster=config.raster, device=resolve_device(config.device),
        step_evaluations=step_evaluations, topology=topology_counts(trainer.state),
        background=[round(c, 6) for c in trainer._background_rgb], background_source=trainer.background_source,
        train_views=len(trainer.dataset.train), image_size=_image_size(trainer.dataset),
        test_view_psnr=[round(float(p), 6) for p in ev.per_view_psnr])
    write_text(out / "result.json", result.to_json(indent=2) + "\n")  # whole or not at all
    return result


__all__ = ["train", "torch_threads", "resolve_background", "BACKGROUND_SOURCES", "Trainer", "StepStatus", "StepTimes", "Evaluation"]
