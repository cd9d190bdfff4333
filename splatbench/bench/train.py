"""Training benchmark: iterations per second and where a step's time goes.

For each image size, a synthetic scene (random Gaussians in a ball, seen by an orbit
of cameras and rendered by splatbench itself) is trained with `splatbench.train.Trainer`
-- the same step as ``splatbench train`` -- from ``n`` Gaussians seeded on noisy copies
of the true centres, SH degree 3 active from the fourth step, no densification
(``strategy="none"``, so N stays fixed). After ``warmup`` untimed steps (Dr.Jit kernels
compile or load from the cache), ``iterations`` steps are timed. The trainer times each
phase of a step with wall clocks around it (`splatbench.train.loop.StepTimes`):

* rasterizer forward -- ``splatbench.rasterize`` (Dr.Jit forward; its outputs are
  copied to torch, which waits for Dr.Jit, so the wall time is the work);
* loss -- L1 + D-SSIM forward and its backward down to the rendered image (the
  trainer backpropagates in two calls, loss then rasterizer, so these split cleanly);
* rasterizer backward -- image cotangent to parameter gradients (Dr.Jit backward,
  copies to torch);
* optimizer -- six Adam steps; strategy and other -- hooks and bookkeeping.

Units: milliseconds per step (ms), shares in percent of the timed steps' wall time.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np

from splatbench import report_files
from splatbench.errors import InputError

#: The standard sizes (square images, pixels) reported by ``splatbench bench train``.
STANDARD_SIZES = (128, 256)


def check_train_settings(settings, counts: tuple[str, ...], *, min_size: int, size_reason: str = "") -> None:
    """The one-line checks of a training benchmark's settings (`TrainBenchSettings`, and
    ``bench ab-train``'s `AbTrainSettings`): each field in ``counts`` >= 1, ``warmup`` >= 0,
    each of ``sizes`` >= ``min_size`` pixels (``size_reason``: why, for the message)."""
    for name in counts:
        if getattr(settings, name) < 1:
            raise InputError(f"--{name}: expected a count >= 1, got {getattr(settings, name)}")
    if settings.warmup < 0:
        raise InputError(f"--warmup: expected a count >= 0, got {settings.warmup}")
    for s in settings.sizes:
        if s < min_size:
            raise InputError(f"--size: expected a side >= {min_size} pixels{size_reason}, got {s}")


@dataclass(frozen=True)
class TrainBenchSettings:
    """How each size is benchmarked."""

    sizes: tuple[int, ...] = STANDARD_SIZES  # square image sides (pixels)
    gaussians: int = 20_000                 # N trained (the scene has the same number of true Gaussians)
    views: int = 16                         # training views rendered per size
    iterations: int = 30                    # timed steps
    warmup: int = 5                         # untimed steps first (kernel compilation)
    seed: int = 0                           # scene and training seed
    device: str = "auto"                    # rasterizer backend: "cpu", "cuda" or "auto"
    torch_threads: int = 1                  # torch intra-op threads (as `TrainConfig.torch_threads`)

    def validate(self) -> None:
        check_train_settings(self, ("gaussians", "views", "iterations"), min_size=8)


@dataclass
class TrainBenchResult:
    """One size. Per-step times are means over the timed steps."""

    name: str                   # "synthetic-<W>x<H>"
    width: int                  # image width (pixels)
    height: int                 # image height (pixels)
    n: int                      # Gaussians trained
    sh_degree: int              # active SH degree during the timed steps
    device: str                 # "cpu" (Dr.Jit LLVM) or "cuda"
    iterations: int             # timed steps
    seconds: float              # wall time of the timed steps
    it_per_s: float             # iterations / seconds
    step_ms: float              # mean wall time of one step
    raster_forward_ms: float    # per step: splatbench.rasterize forward
    loss_ms: float              # per step: loss forward + backward to the image
    raster_backward_ms: float   # per step: rasterizer backward
    optimizer_ms: float         # per step: Adam steps (and zero_grad)
    other_ms: float             # per step: strategy hooks, schedules, bookkeeping
    raster_forward_pct: float   # share of the step time (%)
    raster_backward_pct: float
    loss_pct: float
    optimizer_pct: float
    other_pct: float
    peak_rss_mb: float          # peak RSS of the process so far (MB)
    step_runs_ms: list[float] = field(default_factory=list)  # every timed step


CSV_COLUMNS = tuple(f.name for f in fields(TrainBenchResult) if f.name != "step_runs_ms")


def synthetic_scene(size: int, n: int, views: int, seed: int):
    """(dataset, truth): ``n`` random Gaussians in a ball of radius ~1, SH degree 3,
    rendered from ``views`` orbit cameras at ``size`` x ``size``; the dataset's points
    are the true centres plus noise (sigma 0.03) with their DC colours."""
    from splatbench.cameras import Camera
    from splatbench.data.dataset import Dataset, PointCloud, Split
    from splatbench.gaussians import SH_C0, Gaussians
    from splatbench.raster import render
    from splatbench.workloads import random_unit_quats

    rng = np.random.default_rng(seed)
    means = rng.normal(size=(n, 3)) * 0.5
    sh = np.concatenate([rng.normal(size=(n, 1, 3)) * 0.6, rng.normal(size=(n, 15, 3)) * 0.1], axis=1)
    truth = Gaussians(means=means, log_scales=np.log(rng.uniform(0.01, 0.05, (n, 3))),
                      quats=random_unit_quats(rng, n), opacity_logits=rng.normal(1.0, 1.0, n), sh=sh)
    cams = []
    for i in range(views):
        a = 2 * np.pi * i / views
        eye = [3.0 * np.cos(a), -1.0 + 0.5 * (i % 3), 3.0 * np.sin(a)]
        cams.append(Camera.look_at(eye=eye, target=[0, 0, 0], up=[0, -1, 0], width=size, height=size,
                                   fov_x_deg=45))
    images = np.stack([np.clip(render(truth, c).rgb, 0, 1) for c in cams]).astype(np.float32)
    split = Split(images, cams, None, [f"view{i}.png" for i in range(views)])
    empty = Split(np.zeros((0, size, size, 3), np.float32), [], None, [])
    xyz = means + rng.normal(size=means.shape) * 0.03
    rgb = (np.clip(0.5 + SH_C0 * sh[:, 0], 0, 1) * 255).astype(np.uint8)
    return Dataset(f"synthetic-{size}x{size}", split, empty, PointCloud(xyz, rgb), Path("."), "blender"), truth


def run_size(size: int, settings: TrainBenchSettings) -> TrainBenchResult:
    """Benchmark training at ``size`` x ``size`` in this process."""
    from splatbench.metrics.memory import peak_rss_mb
    from splatbench.metrics.machine import resolve_device
    from splatbench.train.config import SHConfig, StrategyConfig, TrainConfig
    from splatbench.train.loop import StepTimes, Trainer, torch_threads

    dataset, _ = synthetic_scene(size, settings.gaussians, settings.views, settings.seed)
    cfg = TrainConfig(dataset="", out="", iterations=settings.warmup + settings.iterations,
                      strategy=StrategyConfig(name="none"), sh=SHConfig(degree=3, interval=1), schedule="absolute",
                      seed=settings.seed, device=settings.device, torch_threads=settings.torch_threads)
    with torch_threads(settings.torch_threads):
        trainer = Trainer(cfg, dataset=dataset)
        for _ in range(settings.warmup):
            trainer.step()
        trainer.times = StepTimes()
        runs = []
        for _ in range(settings.iterations):
            t0 = time.perf_counter()
            status = trainer.step()
            runs.append(time.perf_counter() - t0)
    t, total, k = trainer.times, sum(runs), settings.iterations
    other = t.strategy + t.other + max(total - t.total(), 0.0)
    parts = {"raster_forward": t.raster_forward, "loss": t.loss, "raster_backward": t.raster_backward,
             "optimizer": t.optimizer, "other": other}
    ms = {f"{name}_ms": round(1e3 * v / k, 3) for name, v in parts.items()}
    pct = {f"{name}_pct": round(100 * v / total, 1) for name, v in parts.items()}
    return TrainBenchResult(
        name=dataset.name, width=size, height=size, n=trainer.num_gaussians, sh_degree=status.sh_degree,
        device=resolve_device(settings.device), iterations=k, seconds=round(total, 3),
        it_per_s=round(k / total, 3), step_ms=round(1e3 * total / k, 3), **ms, **pct,
        peak_rss_mb=round(peak_rss_mb(), 1), step_runs_ms=[round(1e3 * r, 3) for r in runs])


def format_table(results: list[TrainBenchResult]) -> str:
    head = ("size", "N", "it/s", "step ms", "raster fwd", "raster bwd", "loss", "optimizer", "other")
    rows = [head] + [(f"{r.width}x{r.height}", str(r.n), f"{r.it_per_s:.2f}", f"{r.step_ms:.1f}",
                      f"{r.raster_forward_pct:.1f}%", f"{r.raster_backward_pct:.1f}%", f"{r.loss_pct:.1f}%",
                      f"{r.optimizer_pct:.1f}%", f"{r.other_pct:.1f}%") for r in results]
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in rows)


def write_csv(results: list[TrainBenchResult], path: Path) -> Path:
    """One CSV line per result under the header `CSV_COLUMNS`, atomically."""
    return report_files.write_csv(path, CSV_COLUMNS, ({c: row[c] for c in CSV_COLUMNS}
                                                      for row in (asdict(r) for r in results)))


def write_json(results: list[TrainBenchResult], machine, settings: TrainBenchSettings, path: Path) -> Path:
    """``{"machine": MachineInfo, "settings": TrainBenchSettings, "results": [TrainBenchResult]}``."""
    return report_files.write_json(path, {"machine": asdict(machine), "settings": asdict(settings),
                                         "results": [asdict(r) for r in results]}, indent=2)


__all__ = ["TrainBenchSettings", "TrainBenchResult", "STANDARD_SIZES", "synthetic_scene", "run_size",
           "format_table", "write_csv", "write_json"]
