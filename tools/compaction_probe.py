"""Would compacting the compositing lanes that are still running pay? A forward-pass probe (issue 30).

    python tools/compaction_probe.py guitar 400x300 16        # a bundled model, one view, K = 16
    python tools/compaction_probe.py syn100000 512x512 16      # synthetic N

The forward compositing loop runs a SIMD packet of 16 lanes (4x4-pixel blocks of one tile)
until its longest list ends. This probe runs it in two phases instead: every lane for at
most K entries, then only the lanes still running, gathered into dense packets (tiles mixed),
from the state phase 1 left; images and transmittances must come out bit-identical (checked),
and both are timed alternately (median of 10 after 2, wall clock, Dr.Jit's default threads).
Timing only: the backward pass would need the same (and a pair's gradient slot would be added
from several packets, which the deterministic reduction does not allow), so it is not in the
rasterizer. docs/history/benchmarks.md ("2026-12-06") has what it found.
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("workload", help="a bundled model (guitar, biker) or synN (N synthetic Gaussians)")
    ap.add_argument("size", help="WxH")
    ap.add_argument("k", type=int, nargs="?", default=32, help="entries every lane composites in phase one")
    args = ap.parse_args()

    from splatbench.raster import compositing as C
    from splatbench.raster.api import to_tensor
    from splatbench.raster.binning import bin_gaussians
    from splatbench.raster.blocks import lanes_for
    from splatbench.raster.device import dr, get_device
    from splatbench.raster.options import RasterOptions
    from splatbench.raster.projection import project
    from splatbench.workloads import model_workload, synthetic

    width, height = (int(v) for v in args.size.lower().split("x"))
    name = args.workload
    wl = synthetic(int(name[3:]), width, height, 0) if name.startswith("syn") else model_workload(name, 0, 1, width,
                                                                                                      height)
    m = get_device("cpu").t
    opts = RasterOptions(device="cpu")
    cfg = C.CompositeSettings.from_options(opts)
    with dr.suspend_grad():
        g = wl.gaussians
        proj = project(*(to_tensor(m, getattr(g, k)) for k in ("means", "log_scales", "quats", "opacity_logits")),
                       wl.camera, opts)
        bins = bin_gaussians(proj, wl.camera, opts)
        rec = C.splat_records(proj)
        lanes = lanes_for(m, rec, bins, opts.pixel_block)
        dr.eval(rec)
    ids = bins.gaussian_ids

    def one_phase():
        out = C._forward_loop(m, rec, ids, lanes, cfg)
        dr.eval(tuple(out))  # a NamedTuple: Dr.Jit does not traverse it
        return out, 0

    def two_phases():
        first = lanes._replace(end=dr.minimum(lanes.end, lanes.start + args.k))
        f1 = C._forward_loop(m, rec, ids, first, cfg)
        running = dr.zeros(m.Bool, dr.width(lanes.start))  # a pixel still live, more entries left
        for stop in f1.stop:
            running |= stop == first.end
        running &= first.end < lanes.end
        dr.eval(tuple(f1), running)
        idx = dr.compress(running)
        if dr.width(idx) == 0:
            return f1, 0

        def take(values):
            return [dr.gather(type(v), v, idx) for v in values]

        rest = lanes._replace(px=take(lanes.px), py=take(lanes.py), inside=take(lanes.inside),
                              image_index=take(lanes.image_index), start=take([first.end])[0],
                              end=take([lanes.end])[0])
        # phase one's state; a pixel still live had stop == first.end, which phase two calls rest.end
        resume = [C._FrontPixel(T, rgb.x, rgb.y, rgb.z, depth, dr.select(stop == rest.start, rest.end, stop))
                  for T, rgb, depth, stop in zip(take(f1.T), take(f1.rgb), take(f1.depth_sum), take(f1.stop))]
        f2 = C._forward_loop(m, rec, ids, rest, cfg, resume_from=resume)
        for k in range(len(lanes.px)):
            dr.scatter(f1.rgb[k], f2.rgb[k], idx)
            dr.scatter(f1.T[k], f2.T[k], idx)
            dr.scatter(f1.depth_sum[k], f2.depth_sum[k], idx)
            dr.scatter(f1.stop[k], f2.stop[k], idx)
        dr.eval(tuple(f1))
        return f1, dr.width(idx)

    (a, _), (b, running) = one_phase(), two_phases()
    for k in range(len(a.rgb)):
        assert np.array_equal(a.rgb[k].numpy(), b.rgb[k].numpy()) and np.array_equal(a.T[k].numpy(), b.T[k].numpy())
    print(f"{name} {args.size}: images bit-identical; {dr.width(lanes.start)} lanes, {running} still running after "
          f"{args.k} entries")
    times: dict = {one_phase: [], two_phases: []}
    for r in range(12):
        for f in (one_phase, two_phases) if r % 2 == 0 else (two_phases, one_phase):
            dr.sync_thread()
            t0 = time.perf_counter()
            f()
            dr.sync_thread()
            if r >= 2:
                times[f].append(time.perf_counter() - t0)
    print(f"  forward loop: one phase {1e3 * np.median(times[one_phase]):.2f} ms, two phases "
          f"{1e3 * np.median(times[two_phases]):.2f} ms")


if __name__ == "__main__":
    main()
