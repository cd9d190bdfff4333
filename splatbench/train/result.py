"""`TrainResult`: what a training run measured, as a typed record and as JSON."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import NamedTuple

from splatbench.raster.options import RasterOptions
from splatbench.strategies.base import TopologyCounts


class HistoryPoint(NamedTuple):
    """Training progress at one logged step."""

    step: int            # 0-based step index
    loss: float          # training loss of that step
    psnr: float          # PSNR (dB) of that step's training view
    num_gaussians: int   # N after that step


class EvalPoint(NamedTuple):
    """Test-split metrics at one step (``eval.every``, and the final evaluation)."""

    step: int            # steps completed when evaluated
    psnr: float          # mean test PSNR (dB)
    ssim: float          # mean test SSIM
    lpips: float | None = None  # mean test LPIPS v0.1, AlexNet, inputs scaled (None: not computed)


class StepEvaluation(NamedTuple):
    """The full test evaluation at one step of `TrainConfig.evaluation_steps` (a protocol's
    7K / 30K columns): every metric a report sets beside a published one."""

    step: int                     # steps completed when evaluated
    psnr: float                   # mean test PSNR (dB)
    ssim: float                   # mean test SSIM (kornia's, window loss.ssim_window)
    lpips_net: str                # LPIPS v0.1 backbone of the two values below ("" when LPIPS was not computed)
    lpips_scaled: float | None    # mean LPIPS, inputs scaled to [-1, 1] (the lpips package, gsplat, NerfBaselines)
    lpips_unscaled: float | None  # mean LPIPS, [0, 1] inputs unscaled (graphdeco's metrics.py, the 3DGS paper)
    num_gaussians: int            # N at that step
    train_seconds: float          # optimisation-loop wall time up to that step (as TrainResult.train_seconds)
    views: int                    # test views evaluated


@dataclass
class TrainResult:
    """One run. Metrics are means over the test views; None where there are no test views."""

    test_psnr: float | None             # mean PSNR (dB) of the final model on the test views
    test_ssim: float | None             # mean SSIM (kornia's, window 11)
    test_lpips: float | None            # mean LPIPS v0.1 (`lpips_net`); None when not computed (see `notes`)
    num_gaussians: int                  # N at the end
    train_seconds: float                # wall time of the optimisation loop over all `iterations` steps, a resumed
                                        # run's earlier ones included (no evaluation, no I/O, no compilation)
    iterations: int                     # steps run
    sh_degree: int                      # SH degree in use at the end (the PLY holds this many bands)
    sh_degree_reason: str               # why (fixed schedule, or the automatic schedule's measurement)
    ply_path: str                       # the final 3DGS PLY
    render_ms_per_view: float | None    # mean forward render time of a test view (ms)
    peak_rss_mb: float                  # peak resident memory of the process (MB, 10^6 bytes)
    strategy: str = ""                  # densification strategy used
    scene_extent: float = 0.0           # 1.1 x camera-centre radius (scales the position learning rate)
    test_views: int = 0                 # views evaluated
    history: list[HistoryPoint] = field(default_factory=list)      # every `log_every` steps, and the last
    evaluations: list[EvalPoint] = field(default_factory=list)     # every `eval.every` steps, and the end
    sh_decisions: list[dict] = field(default_factory=list)         # auto SH: each band measured (ShDecision)
    notes: list[str] = field(default_factory=list)                 # e.g. why LPIPS was skipped
    warnings: list[str] = field(default_factory=list)  # what the run warns of, one line each ("warning: ..."):
                                        # the config's (`TrainConfig.warnings`), the strategy's schedule and outcome
                                        # notes, a random start's region known not to hold the scene, an empty model
    init: dict = field(default_factory=dict)   # how the initial Gaussians were made: method, points (and for
                                               # init="sfm": registered, total, center_rmse_rel, cached, ...)
    warmup_seconds: float = 0.0         # kernel compilation / cache loading before the loop (not in train_seconds)
    lpips_net: str = ""                 # test_lpips's backbone: "alex", "vgg" ("" when not computed)
    lpips_scale_inputs: bool = True     # test_lpips's inputs: scaled to [-1, 1] (True) or [0, 1] unscaled
    cpu_seconds: float = 0.0            # CPU seconds of the process (all threads) over the loop train_seconds times
    load: dict = field(default_factory=dict)  # the machine's load from warm-up to the final evaluation
                                        # (`splatbench.metrics.load.Load.metrics`: load_before, load_after,
                                        # own_cpu, own_before, load_other, cores, loaded)
    resumed_step: int | None = None     # --resume: the checkpoint's step (its earlier steps' loop time, timed by the
                                        # run that wrote it, is in train_seconds); None: not resumed
    protocol: str = "quick"             # TrainConfig.protocol (splatbench.train.protocol)
    raster: RasterOptions | None = None  # the rasterizer options of every render of the run (TrainConfig.raster:
                                        # its device as set, "auto" by default; the device that ran is `device`;
                                        # None: a result written before training took raster options; in JSON
                                        # the table of `RasterOptions.to_dict`, {} for None)
    step_evaluations: list[StepEvaluation] = field(default_factory=list)  # at TrainConfig.evaluation_steps
                                        # (graphdeco-30k: 7,000 and 30,000), the last one the final model's
    topology: TopologyCounts | None = None  # what the strategy did besides its settings' names: refinements,
                                        # opacity resets, cloned / split / pruned, MCMC relocated / added
                                        # (None: a result written before they were recorded)
    device: str = ""                    # where the rasterizer ran: "cpu" (Dr.Jit's LLVM backend) or "cuda", what
                                        # TrainConfig.device ("auto" by default, as `raster` records it) resolved
                                        # to on this machine ("": a result written before it was recorded)
    background: list[float] = field(default_factory=list)  # RGB in [0, 1] behind the splats in every test
                                        # render, and under the targets where the dataset has alphas or masks
                                        # (what background = "auto" resolved to, to 6 decimals; a random_background
                                        # run's evaluation background; []: a result written before it was recorded)
    background_source: str = ""         # where it came from (`splatbench.train.loop.BACKGROUND_SOURCES`): "config",
                                        # "masks" (a masked capture: white), "alpha" / "depth" (the mean of the
                                        # pixels the dataset marks empty), "none" (black: it marks none); "": not recorded
    train_views: int = 0                # views trained on (0: a result written before it was recorded)
    test_view_psnr: list[float] = field(default_factory=list)  # the final evaluation's PSNR of each test view
                                        # (dB, test-split order; their mean is test_psnr): one view far below the
                                        # others is a floater in front of its camera ([]: not recorded)
    image_size: list[int] = field(default_factory=list)  # [width, height] of the test images in pixels, as
                                        # trained and evaluated (after downscale; []: not recorded)

    def to_dict(self) -> dict:
        """JSON-ready dict; NaN / inf become None; history rows become objects."""
        data = asdict(self)
        data["raster"] = self.raster.to_dict() if self.raster is not None else {}
        data["history"] = [p._asdict() for p in self.history]
        data["evaluations"] = [p._asdict() for p in self.evaluations]
        data["step_evaluations"] = [p._asdict() for p in self.step_evaluations]
        return _finite(data)

    def to_json(self, *, indent: int | None = None) -> str:
        """One line by default (``splatbench train --json``)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, data: dict) -> TrainResult:
        topology, raster = data.get("topology"), data.get("raster")
        return cls(**{**data, "raster": RasterOptions.from_dict(raster) if raster else None, "history": [HistoryPoint(**p) for p in data.get("history", [])],
                      "evaluations": [EvalPoint(**p) for p in data.get("evaluations", [])],
                      "step_evaluations": [StepEvaluation(**p) for p in data.get("step_evaluations", [])],
                      "topology": TopologyCounts(**topology) if isinstance(topology, dict) else None})

    def at_step(self, step: int) -> StepEvaluation | None:
        """The full test evaluation after ``step`` steps (None when the run made none there)."""
        return next((e for e in self.step_evaluations if e.step == step), None)


def _finite(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


__all__ = ["TrainResult", "HistoryPoint", "EvalPoint", "StepEvaluation"]
