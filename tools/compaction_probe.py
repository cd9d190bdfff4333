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
rasterizer. docs/benchmarks.md ("2026-12-06") has what it found.
"""
import sys, time, numpy as np
import splatbench
from splatbench.raster.device import dr, get_device
from splatbench.raster.api import to_tensor
from splatbench.raster.binning import bin_gaussians
from splatbench.raster.blocks import lanes_for
from splatbench.raster import compositing as C
from splatbench.raster.options import RasterOptions
from splatbench.raster.projection import project
from splatbench.workloads import model_workload, synthetic
name, size = sys.argv[1], sys.argv[2]; K = int(sys.argv[3]) if len(sys.argv) > 3 else 32
w, h = (int(v) for v in size.split("x"))
wl = model_workload(name, 0, 1, w, h) if not name.startswith("syn") else synthetic(int(name[3:]), w, h, 0)
m = get_device("cpu").t
g, cam = wl.gaussians, wl.camera
opts = RasterOptions(device="cpu")
cfg = C.CompositeSettings.from_options(opts)
with dr.suspend_grad():
    proj = project(*(to_tensor(m, getattr(g, k)) for k in ("means", "log_scales", "quats", "opacity_logits")), cam, opts)
    bins = bin_gaussians(proj, cam, opts)
    rec = C.splat_records(proj)
    lanes = lanes_for(m, rec, bins, 4)
    dr.eval(rec)

def base():
    f = C._forward_loop(m, rec, bins.gaussian_ids, lanes, cfg); dr.eval(tuple(f)); return f

LIVE = [0]
def compacted():
    # phase 1: at most K iterations per lane
    L1 = lanes._replace(end=dr.minimum(lanes.end, lanes.start + K))
    f1 = C._forward_loop(m, rec, bins.gaussian_ids, L1, cfg)
    # lanes still live: a pixel stopped at L1.end (live) and the lane has more entries
    live = dr.zeros(m.Bool, dr.width(lanes.start))
    for s in f1.stop:
        live |= (s == L1.end)
    live &= L1.end < lanes.end
    dr.eval(tuple(f1), live)
    idx = dr.compress(live)
    if dr.width(idx) == 0:
        return f1
    LIVE[0] = dr.width(idx)
    g_ = lambda T, v: dr.gather(T, v, idx)
    L2 = lanes._replace(px=[g_(m.Float, v) for v in lanes.px], py=[g_(m.Float, v) for v in lanes.py],
                        inside=[g_(m.Bool, v) for v in lanes.inside], image_index=[g_(m.UInt32, v) for v in lanes.image_index],
                        start=g_(m.UInt32, L1.end), end=g_(m.UInt32, lanes.end))
    # continue from phase 1's state: a custom loop start (copy of _forward_loop with a given start state)
    K2 = len(L2.px); width = len(C._FrontPixel._fields)
    def cond(*state):
        i, pixels = C._unpack(state, C._FrontPixel, width)
        lv = pixels[0].stop == L2.end
        for p in pixels[1:]:
            lv = lv | (p.stop == L2.end)
        return (i < L2.end) & lv
    def body(*state):
        i, pixels = C._unpack(state, C._FrontPixel, width)
        gid = dr.gather(m.UInt32, bins.gaussian_ids, dr.gather(m.UInt32, L2.pairs, i))
        geo, (cr, cg, cb) = C.load_records(m, rec, gid)
        after = []
        for k, p in enumerate(pixels):
            alpha, contributes, _, _, _, _ = C._alpha_at(geo, L2.px[k], L2.py[k], cfg, p.stop == L2.end)
            t_next = p.T * (1.0 - alpha)
            stop_now = contributes & (t_next < cfg.transmittance_min)
            take = contributes & ~stop_now
            wgt = dr.select(take, p.T * alpha, 0.0)
            after.append(C._FrontPixel(T=dr.select(take, t_next, p.T), r=p.r + wgt * cr, g=p.g + wgt * cg, b=p.b + wgt * cb,
                                       depth_sum=p.depth_sum + wgt * geo.depth, stop=dr.select(stop_now, i, p.stop)))
        return C._pack(i + 1, after)
    st = [C._FrontPixel(g_(m.Float, f1.T[k]), g_(m.Float, f1.rgb[k].x), g_(m.Float, f1.rgb[k].y), g_(m.Float, f1.rgb[k].z),
                        g_(m.Float, f1.depth_sum[k]), dr.select(g_(m.UInt32, f1.stop[k]) == L2.start, L2.end, g_(m.UInt32, f1.stop[k])))
          for k in range(K2)]
    final = dr.while_loop(C._pack(m.UInt32(L2.start), st), cond, body, mode="symbolic")
    _, pix = C._unpack(final, C._FrontPixel, width)
    out = C._Forward([m.Array3f(f1.rgb[k]) for k in range(K2)], [m.Float(f1.T[k]) for k in range(K2)],
                     [m.Float(f1.depth_sum[k]) for k in range(K2)], [m.UInt32(f1.stop[k]) for k in range(K2)])
    for k, p in enumerate(pix):
        dr.scatter(out.rgb[k], m.Array3f(p.r, p.g, p.b), idx); dr.scatter(out.T[k], p.T, idx)
        dr.scatter(out.depth_sum[k], p.depth_sum, idx)
        dr.scatter(out.stop[k], p.stop, idx)
    dr.eval(tuple(out))
    return out

a, b = base(), compacted()
for k in range(len(a.rgb)):
    assert np.array_equal(a.rgb[k].numpy(), b.rgb[k].numpy()), k
    assert np.array_equal(a.T[k].numpy(), b.T[k].numpy()), k
print(f"{name} {size}: images bit-identical; {dr.width(lanes.start)} lanes, {LIVE[0]} still running after {K} entries")
T = {"base": [], "compact": []}
for r in range(12):
    for nm, f in (("base", base), ("compact", compacted)) if r % 2 == 0 else (("compact", compacted), ("base", base)):
        dr.sync_thread(); t = time.perf_counter(); f(); dr.sync_thread()
        if r >= 2: T[nm].append(time.perf_counter() - t)
print(f"  forward loop: one phase {1e3 * np.median(T['base']):.2f} ms, two phases {1e3 * np.median(T['compact']):.2f} ms")
