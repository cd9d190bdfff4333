"""Where the CUDA time goes that `bench raster` books to "other" and `bench train` to "loss".

Two questions from reports/cuda/README.md, answered by measurement on a GPU machine:

1. At 1M Gaussians / 800x800, 174 of the 274 ms of a forward+backward were "other" (outside
   the five named stages). This times the same forward+backward with the parameters as
   `bench raster` holds them (CPU torch tensors, as `splatbench.train` holds them too) and
   with the parameters on the GPU, each with the stage split; the bare host<->device copies
   of that many floats; a cProfile of one call of each (host functions, by own time); and
   Dr.Jit's kernel history of one call (GPU execution time by kernel type and the largest
   kernels).
2. At 256x256 the loss (L1 + D-SSIM, forward and backward to the image) was 24 ms of a
   44 ms training step. This times `photometric_loss` with its backward on CPU tensors (where
   the trainer's rendered image lives) and on CUDA tensors, and the image copies between.

Usage: python tools/cuda_profile.py OUTDIR [--repeats 7] [--n 1000000] [--size 800] [--device cuda]
Writes OUTDIR/profile.json and OUTDIR/profile.txt; prints the text. Every time is the
median of --repeats runs after two untimed warm-up calls (kernels compiled or loaded from
Dr.Jit's cache before anything is timed).
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import io
import json
import platform
import pstats
import statistics
import time
from collections import defaultdict
from pathlib import Path


def _median_ms(fn, repeats: int, sync) -> float:
    times = []
    for _ in range(repeats):
        sync()
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    return round(statistics.median(times) * 1e3, 3)


def _host_profile(fn, top: int = 18) -> str:
    prof = cProfile.Profile()
    prof.enable()
    fn()
    prof.disable()
    text = io.StringIO()
    pstats.Stats(prof, stream=text).strip_dirs().sort_stats("tottime").print_stats(top)
    return text.getvalue()


def _kernels(fn, dr) -> dict:
    dr.kernel_history()  # clears what came before
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    t0 = time.perf_counter()
    fn()
    dr.sync_thread()
    wall = time.perf_counter() - t0
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    hist = dr.kernel_history()
    by_type: dict[str, float] = defaultdict(float)
    count: dict[str, int] = defaultdict(int)
    for k in hist:
        by_type[str(k["type"])] += k["execution_time"]
        count[str(k["type"])] += 1
    largest = sorted(hist, key=lambda k: -k["execution_time"])[:12]
    return {
        "wall_ms": round(wall * 1e3, 3),
        "kernels": len(hist),
        "gpu_ms": round(sum(k["execution_time"] for k in hist), 3),
        "gpu_ms_by_type": {t: round(v, 3) for t, v in by_type.items()},
        "count_by_type": dict(count),
        "largest": [{"type": str(k["type"]), "size": k.get("size"), "ops": k.get("operation_count"),
                     "ms": round(k["execution_time"], 3), "cache_hit": bool(k.get("cache_hit"))} for k in largest],
    }


def raster_other(n: int, size: int, repeats: int, device: str) -> tuple[dict, str]:
    import drjit as dr
    import torch

    from splatbench.metrics.timing import forward_backward_with_init, staged_runs, torch_params
    from splatbench.workloads import parse_synthetic

    workload = parse_synthetic(str(n), f"{size}x{size}").build()
    camera, options = workload.camera, {"device": device}
    host = torch_params(workload.gaussians)
    floats = sum(p.numel() for p in host)
    cuda = device == "cuda"
    variants = [("cpu_params", host)] + ([("cuda_params", tuple(p.cuda() for p in host))] if cuda else [])

    def sync():
        dr.sync_thread()
        if cuda:
            torch.cuda.synchronize()

    out, text = {"workload": f"{n} Gaussians at {size}x{size}", "param_floats": floats}, []
    for where, params in variants:
        fb = forward_backward_with_init(params, camera, options)
        fb(), fb()
        total = _median_ms(fb, repeats, sync)
        split = staged_runs(fb, repeats)
        out[where] = {"fwd_bwd_ms": total, "stages_ms": dataclasses.asdict(split)}
        out[where]["kernel_history"] = _kernels(fb, dr)
        text.append(f"--- {where}: fwd+bwd {total} ms; stages {split}\n")
        text.append(f"kernel history: {json.dumps(out[where]['kernel_history'], indent=1)}\n")
        text.append(f"host profile (one call, by own time):\n{_host_profile(fb)}\n")
    if not cuda:
        return out, "".join(text)

    dev = torch.empty(floats, device="cuda")
    cpu = torch.empty(floats)
    pinned = torch.empty(floats, pin_memory=True)
    out["copies_ms"] = {
        "d2h_pageable": _median_ms(lambda: cpu.copy_(dev), repeats, sync),
        "h2d_pageable": _median_ms(lambda: dev.copy_(cpu), repeats, sync),
        "d2h_pinned": _median_ms(lambda: pinned.copy_(dev), repeats, sync),
        "cpu_to_cuda_new_tensor": _median_ms(lambda: cpu.cuda(), repeats, sync),
        "cuda_to_cpu_new_tensor": _median_ms(lambda: dev.cpu(), repeats, sync),
    }
    text.append(f"copies of {floats} float32 (the parameters' size), ms: {out['copies_ms']}\n")
    return out, "".join(text)


def loss_256(repeats: int, device: str) -> tuple[dict, str]:
    import torch

    from splatbench.train.losses import photometric_loss

    g = torch.Generator().manual_seed(0)
    target = torch.rand(256, 256, 3, generator=g)
    pred0 = torch.rand(256, 256, 3, generator=g)
    out = {"torch_threads": torch.get_num_threads()}

    def step(device):
        pred = pred0.to(device).requires_grad_(True)
        tgt = target.to(device)

        def run():
            photometric_loss(pred, tgt).backward()
        return run

    cuda = device == "cuda"

    def sync():
        if cuda:
            torch.cuda.synchronize()

    for where in ("cpu", "cuda") if cuda else ("cpu",):
        fn = step(where)
        fn(), fn()
        out[f"loss_fwd_bwd_{where}_ms"] = _median_ms(fn, max(repeats, 20), sync)
    if cuda:
        img = torch.rand(256, 256, 3, device="cuda")
        out["image_d2h_ms"] = _median_ms(lambda: img.cpu(), max(repeats, 20), sync)
    fn = step("cpu")
    text = (f"--- loss at 256x256: {json.dumps(out)}\n"
            f"host profile of one CPU loss step:\n{_host_profile(fn)}\n")
    return out, text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--size", type=int, default=800)
    ap.add_argument("--device", default="cuda", help="cuda; cpu only to try this script without a GPU")
    args = ap.parse_args()
    import drjit
    import torch

    args.out.mkdir(parents=True, exist_ok=True)
    result = {"python": platform.python_version(), "drjit": drjit.__version__, "torch": torch.__version__,
              "gpu": torch.cuda.get_device_name(0) if args.device == "cuda" else "no GPU (cpu)"}
    raster, t1 = raster_other(args.n, args.size, args.repeats, args.device)
    loss, t2 = loss_256(args.repeats, args.device)
    result.update(raster=raster, loss=loss)
    (args.out / "profile.json").write_text(json.dumps(result, indent=1, default=str))
    text = f"{result['gpu']}, drjit {result['drjit']}, torch {result['torch']}\n{t1}{t2}"
    (args.out / "profile.txt").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
