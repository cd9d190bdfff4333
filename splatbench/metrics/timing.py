"""Timing closures of the rasterizer benchmark (pytorch3d ``bm_rasterize_points`` style).

The factories `forward_with_init` and `forward_backward_with_init` build everything
outside the timed part and return a closure; `time_runs` times ``repeats`` calls of
one, `staged_runs` splits forward+backward into the rasterizer's stages
(`StageSplit`). Used by `splatbench.bench.raster.run_one` and by the raster run kind
(`splatbench.experiments.raster_kind`).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from typing import Callable, NamedTuple


@dataclass
class StageSplit:
    """Median milliseconds per rasterizer stage, from forward+backward runs with a
    `StageTimer` (which syncs Dr.Jit after each stage, so ``total_ms`` may exceed the
    untimed `RasterBenchResult.fwd_bwd_ms`). Each stage is the wall time since the
    previous mark: ``preprocess_ms`` includes input validation and the torch -> Dr.Jit
    copies; ``backward_compositing_ms`` starts at the end of the forward pass, so it
    also holds torch's backward up to the rasterizer and the cotangent copies."""

    preprocess_ms: float            # projection, covariances, SH colours
    binning_ms: float               # Gaussian-tile pairs: binning_cull_ms + binning_sort_ms
    compositing_ms: float           # forward alpha compositing (+ image-order gather, depth)
    backward_compositing_ms: float  # hand-written backward of compositing, per-Gaussian reduction
    backward_preprocess_ms: float   # Dr.Jit AD through SH, projection and activations
    other_ms: float                 # total minus the five stages (output/gradient copies to torch)
    total_ms: float                 # median wall time of these timed runs
    binning_cull_ms: float = 0.0    # support boxes, their tiles, the ellipse-tile test
    binning_sort_ms: float = 0.0    # counting sort by tile (depth order within), tile ranges



class RunStats(NamedTuple):
    """What a run reports besides its time (no reference to the Dr.Jit frame, so
    holding it keeps no rasterizer memory alive)."""

    num_pairs: int
    visible: object  # [N] bool torch tensor
    sh_degree: int


def torch_params(gaussians) -> tuple:
    """(means, log_scales, quats, opacity_logits, sh) as float32 torch tensors sharing
    the Gaussians' memory."""
    import numpy as np
    import torch

    return tuple(torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))
                 for a in (gaussians.means, gaussians.log_scales, gaussians.quats, gaussians.opacity_logits,
                           gaussians.sh))


def device_sync(device) -> Callable[[], None]:
    """A wait for the queued GPU work on ``device`` (a name such as "cuda", or a torch device):
    ``torch.cuda.synchronize`` on CUDA (the bridge waits for Dr.Jit, but torch's own kernels and
    copies run on its stream); on the CPU nothing, where outputs are ready on return."""
    if str(device).startswith("cuda"):
        import torch

        return torch.cuda.synchronize
    return _ready


def _ready() -> None:
    """Nothing to wait for (`device_sync` on the CPU)."""


def forward_with_init(params: tuple, camera, options, sh_degree: int | None = None) -> Callable[[], RunStats]:
    """Forward only: `splatbench.rasterize` under ``torch.no_grad()`` on inputs that
    need no gradient (so Dr.Jit records no AD graph, as in `splatbench.render`)."""
    import torch

    from splatbench.raster.torch_bridge import rasterize

    inputs = tuple(p.detach() for p in params)
    sync = device_sync(inputs[0].device)

    def forward() -> RunStats:
        with torch.no_grad():
            _, _, _, info = rasterize(*inputs, camera, sh_degree=sh_degree, options=options)
        sync()
        return RunStats(info.num_pairs, info.visible, info.sh_degree)

    return forward


def forward_backward_with_init(params: tuple, camera, options, sh_degree: int | None = None) -> Callable[..., RunStats]:
    """Forward and backward: loss = rgb.sum() through `splatbench.rasterize`, all five
    parameter groups requiring grad. The closure takes an optional `StageTimer`."""
    from splatbench.raster.hooks import Hooks
    from splatbench.raster.torch_bridge import rasterize_with_hooks

    leaves = tuple(p.detach().requires_grad_(True) for p in params)
    sync = device_sync(leaves[0].device)

    def forward_backward(timer=None) -> RunStats:
        if timer is not None:
            timer.start()
        rgb, _, _, info = rasterize_with_hooks(*leaves, camera, Hooks(timer=timer), sh_degree=sh_degree, options=options)
        if timer is not None:
            timer.mark("other")  # outputs copied to torch, RasterInfo
        rgb.sum().backward()
        sync()
        if timer is not None:
            timer.mark("other")  # gradients copied to torch
        for p in leaves:
            p.grad = None  # as an optimizer's zero_grad(set_to_none=True) would
        return RunStats(info.num_pairs, info.visible, info.sh_degree)

    return forward_backward


def time_runs(fn: Callable[[], RunStats], repeats: int) -> tuple[list[float], RunStats]:
    """Wall seconds of ``repeats`` calls of ``fn`` (each ends with a copy to torch, which
    waits for Dr.Jit), and the last call's stats."""
    seconds, stats = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        stats = fn()
        seconds.append(time.perf_counter() - t0)
    return seconds, stats


def staged_runs(fn: Callable[..., RunStats], repeats: int) -> StageSplit:
    """``repeats`` calls of ``fn(timer)`` with a fresh `StageTimer` each; median per stage."""
    from splatbench.raster.timing import STAGES, StageTimer

    totals, per_stage = [], {s: [] for s in STAGES}
    others = []
    for _ in range(repeats):
        timer = StageTimer()
        t0 = time.perf_counter()
        fn(timer)
        total = time.perf_counter() - t0
        totals.append(total)
        for s in STAGES:
            per_stage[s].append(timer.seconds.get(s, 0.0))
        others.append(total - sum(timer.seconds.get(s, 0.0) for s in STAGES))
    per_stage["binning"] = [c + s for c, s in zip(per_stage["binning_cull"], per_stage["binning_sort"])]
    ms = {f"{s}_ms": milliseconds(statistics.median(v)) for s, v in per_stage.items()}
    return StageSplit(**ms, other_ms=milliseconds(statistics.median(others)), total_ms=milliseconds(statistics.median(totals)))


def milliseconds(seconds: float) -> float:
    """Seconds as milliseconds rounded to 1 µs (the unit of every bench table)."""
    return round(seconds * 1e3, 3)
