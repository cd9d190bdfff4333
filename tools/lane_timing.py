"""Forward+backward time of compositing lane layouts (tile_size, pixel_block), timed in
alternation in one process, so that every layout sees the same load.

    python tools/lane_timing.py guitar,biker 400x300 16/4 16/2 32/2 8/2 [--rounds 20] [--threads 1]
    python tools/lane_timing.py synthetic:10000 256x256 16/4 8/2
    python tools/lane_timing.py garden - 16/4 8/2
    python tools/lane_timing.py guitar 400x300 16/4 16/2 --rounds 10 --kernels 6
    python tools/lane_timing.py guitar 400x300 16/4 16/4x --kernels 4   # x: packets mix tiles

A layout TILE/BLOCK followed by ``x`` is a prototype, for timing only: every lane of the
image sorted by the length of its list (`dr.detail.block_mkperm`), so packets mix tiles
and wait less for their longest lane. The backward pass then adds into a pair's gradient
slot from several packets and threads, which the deterministic reduction does not allow
(`reduction.lane_group`): its gradients may differ in the last bits from run to run.

Workloads: a bundled model (view 0 of 1 at WxH, as `bench raster --model NAME
--model-views 1 --model-size WxH`), ``synthetic:N`` at WxH, or ``garden`` (its own size;
WxH ignored). Each layout is built and run twice first (kernels compile or load from
Dr.Jit's cache, outside the timed part); then ``--rounds`` rounds, each running every
layout once (`splatbench.metrics.timing.forward_backward_with_init`: loss = rgb.sum(),
all five groups), the first layout of a round rotating. Per layout: the median CPU
seconds of the process (all threads) and wall seconds per run, and the median over
rounds of the first layout's time / this layout's (> 1: faster than the first), with
its interquartile range; the 1-minute load average over the rounds.

With ``--threads 1`` (the default) the CPU time is the work done, which a loaded machine
disturbs least (a descheduled process accrues none), so ratios of it can choose between
layouts on a busy machine; they are not the wall-time speed-ups of a quiet one
(`splatbench bench ab` gives those). The counts of each layout (evaluations performed,
useful share) are `work_stats`' and tools/lane_packing.py's.

``--kernels K``: then, per layout, 6 more runs with Dr.Jit's kernel history on, and the K
kernels of the largest least time over them (launch order, kind, width, traced
operations, least milliseconds): where the layout's time goes. Indicative only: a kernel's
recorded time includes waiting for the cores.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time

import numpy as np


def build(name: str, size: str):
    from splatbench.workloads import build_workload, model_workload, synthetic

    if name == "garden":
        return build_workload("garden", 0)
    width, height = (int(v) for v in size.lower().split("x"))
    if name.startswith("synthetic:"):
        return synthetic(int(name.split(":", 1)[1]), width, height, 0)
    return model_workload(name, 0, 1, width, height)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("workloads", help="comma-separated: a bundled model, synthetic:N, or garden")
    parser.add_argument("size", help="WxH (ignored for garden)")
    parser.add_argument("layouts", nargs="+", help="TILE/BLOCK, e.g. 16/4 (the first is the baseline)")
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--threads", type=int, default=1, help="Dr.Jit threads (torch uses 1)")
    parser.add_argument("--kernels", type=int, default=0, help="list each layout's K costliest kernels")
    args = parser.parse_args(argv)

    import torch

    from splatbench.metrics.timing import forward_backward_with_init, torch_params
    from splatbench.raster.device import dr
    from splatbench.raster.options import RasterOptions

    dr.set_thread_count(args.threads)
    torch.set_num_threads(1)
    layouts = [(*(int(v) for v in text.rstrip("x").split("/")), text.endswith("x")) for text in args.layouts]
    for ts, pb, _ in layouts:
        RasterOptions(tile_size=ts, pixel_block=pb)  # one-line error for a bad layout
    for name in args.workloads.split(","):
        w = build(name, args.size)
        params = torch_params(w.gaussians)
        runs = {k: mixed(forward_backward_with_init(params, w.camera, {"tile_size": k[0], "pixel_block": k[1],
                                                                        "device": "cpu"}), k[2]) for k in layouts}
        for k in layouts:  # warm-up: compile or load the kernels
            runs[k]()
            runs[k]()
        cpu = {k: [] for k in layouts}
        wall = {k: [] for k in layouts}
        loads = [os.getloadavg()[0]]
        for r in range(args.rounds):
            for k in layouts[r % len(layouts):] + layouts[:r % len(layouts)]:
                c0, t0 = time.process_time(), time.perf_counter()
                runs[k]()
                cpu[k].append(time.process_time() - c0)
                wall[k].append(time.perf_counter() - t0)
            loads.append(os.getloadavg()[0])
        base = layouts[0]
        label = {k: f"{k[0]}/{k[1]}{'x' if k[2] else ''}" for k in layouts}
        print(f"{name} {w.camera.width}x{w.camera.height}: {args.rounds} rounds, Dr.Jit threads {args.threads}, "
              f"1-min load average {min(loads):.1f}-{max(loads):.1f} (median {np.median(loads):.1f}) on "
              f"{os.cpu_count()} CPUs")
        for k in layouts:
            c, t = np.array(cpu[k]), np.array(wall[k])
            rc, rt = np.array(cpu[base]) / c, np.array(wall[base]) / t
            print(f"  {label[k]}: CPU {1e3 * np.median(c):.1f} ms, wall {1e3 * np.median(t):.1f} ms; "
                  f"{label[base]} / this: CPU {np.median(rc):.3f} [{np.percentile(rc, 25):.3f}, "
                  f"{np.percentile(rc, 75):.3f}], wall {np.median(rt):.3f} [{np.percentile(rt, 25):.3f}, "
                  f"{np.percentile(rt, 75):.3f}]", flush=True)
        if args.kernels:
            for k in layouts:
                print(f"  {label[k]} kernels (least ms of 6 runs): "
                      + "; ".join(f"{kind} {size:,}x{ops} ops {ms:.1f}"
                                  for ms, (_, kind, size, ops) in costliest(runs[k], dr, args.kernels)), flush=True)
    return 0


def mixed(run, mix: bool):
    """``run`` as it is, or (``mix``) with every lane of the image sorted by list length."""
    if not mix:
        return run
    from splatbench.raster import blocks, compositing

    def sorted_run(*args):
        compositing.lanes_for = functools.partial(_lanes_sorted_overall, blocks.lanes_for)
        try:
            return run(*args)
        finally:
            compositing.lanes_for = blocks.lanes_for

    return sorted_run


def _lanes_sorted_overall(lanes_for, m, records, bins, pixel_block):
    from splatbench.raster.binning import count_order
    from splatbench.raster.device import dr

    lanes = lanes_for(m, records, bins, pixel_block)
    if lanes.pairs is None:
        return lanes
    counts = lanes.end - lanes.start
    dr.eval(counts)
    perm = count_order(counts)

    def permuted(values):
        return [dr.gather(type(v), v, perm) for v in values]

    moved = lanes._replace(px=permuted(lanes.px), py=permuted(lanes.py), inside=permuted(lanes.inside),
                           image_index=permuted(lanes.image_index), start=dr.gather(m.UInt32, lanes.start, perm),
                           end=dr.gather(m.UInt32, lanes.end, perm))
    dr.eval(moved.px, moved.py, moved.inside, moved.image_index, moved.start, moved.end)
    return moved


def costliest(run, dr, count: int, repeats: int = 6) -> list:
    """[(least ms, (launch index, kind, width, operations))] of the ``count`` costliest kernels."""
    least: dict = {}
    for _ in range(repeats):
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # clear
        run()
        history = dr.kernel_history()
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        for i, h in enumerate(history):
            key = (i, str(h.get("type", "")).split(".")[-1], h.get("size", 0), h.get("operation_count", 0))
            least[key] = min(least.get(key, float("inf")), h.get("execution_time", 0.0))
    return sorted(((ms, key) for key, ms in least.items()), reverse=True)[:count]


if __name__ == "__main__":
    from splatbench.errors import InputError

    try:
        sys.exit(main(sys.argv[1:]))
    except InputError as exc:
        sys.exit(f"lane_timing: {exc}")
