"""Front-to-back alpha compositing over tiles, with an analytic backward pass.

Mirrors `reference.composite`. One lane per pixel, lanes ordered tile by tile so
that a SIMD packet (16 lanes with AVX-512) walks the same tile list; a symbolic
loop per lane stops early once transmittance would fall below its threshold.

The backward pass is a `dr.CustomOp` that walks each pixel's list back to front,
recovering transmittance by division (alpha <= alpha_max < 1 keeps it
invertible) and scatter-adding into per-Gaussian gradient buffers. Dr.Jit's own
AD through the loop (`composite(..., loop_ad=True)`) is kept as a test-only
second backward that checks the hand-written one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from splatbench.raster.backend import dr
from splatbench.raster.binning import Bins, TileGrid, bin_gaussians
from splatbench.raster.project import Projection, array_namespace, next_power_of_two


@dataclass(frozen=True)
class CompositeSettings:
    alpha_min: float
    alpha_max: float
    transmittance_min: float
    background: tuple[float, float, float]


class Composite(NamedTuple):
    """Per-pixel outputs in row-major image order (width H*W):
    rgb [H*W, 3] (Array3f), alpha [H*W], depth_sum [H*W] = sum of T*alpha*z
    (divide by alpha for expected depth)."""

    rgb: object
    alpha: object
    depth_sum: object


@dataclass(frozen=True)
class Splats:
    """Per-Gaussian screen-space attributes read by the compositing loop."""

    means2d: object    # Array2f [N]
    conics: object     # Array3f [N]
    opacities: object  # Float [N]
    colors: object     # Array3f [N]
    depths: object     # Float [N]
    cutoff_sq: object  # Float [N], detached


class Lanes(NamedTuple):
    """Pixel lanes in tile order: centre coordinates, tile range, validity."""

    px: object
    py: object
    start: object
    end: object
    inside: object
    image_index: object  # row-major pixel index of each lane (0 for padding lanes)
    lane_of_pixel: object  # lane of each row-major pixel


def make_lanes(m, bins: Bins) -> Lanes:
    g: TileGrid = bins.grid
    ts = g.tile_size
    shift = ts.bit_length() - 1
    lane = dr.arange(m.UInt32, g.num_lanes)
    tile = lane >> (2 * shift)
    local = lane & (ts * ts - 1)
    tx = tile % g.tiles_x
    ty = tile // g.tiles_x
    ix = (tx << shift) + (local & (ts - 1))
    iy = (ty << shift) + (local >> shift)
    inside = (ix < g.width) & (iy < g.height)
    start = dr.gather(m.UInt32, bins.tile_start, tile)
    end = dr.select(inside, dr.gather(m.UInt32, bins.tile_end, tile), start)
    pix = dr.arange(m.UInt32, g.width * g.height)
    pix_x = pix % g.width
    pix_y = pix // g.width
    lane_of_pixel = (((pix_y >> shift) * g.tiles_x + (pix_x >> shift)) << (2 * shift)) \
        + ((pix_y & (ts - 1)) << shift) + (pix_x & (ts - 1))
    return Lanes(m.Float(ix) + 0.5, m.Float(iy) + 0.5, start, end, inside,
                 dr.select(inside, iy * g.width + ix, 0), lane_of_pixel)


def _gaussian_alpha(m, s: Splats, g, px, py, cfg: CompositeSettings, active):
    """Alpha of Gaussian ``g`` at pixel centre (px, py), and the pieces its gradient needs."""
    mean = dr.gather(m.Array2f, s.means2d, g, active)
    conic = dr.gather(m.Array3f, s.conics, g, active)
    opacity = dr.gather(m.Float, s.opacities, g, active)
    cutoff = dr.gather(m.Float, s.cutoff_sq, g, active)
    dx = px - mean.x
    dy = py - mean.y
    sigma = 0.5 * (conic.x * dx * dx + conic.z * dy * dy) + conic.y * dx * dy
    gauss = dr.exp(-sigma)
    raw = opacity * gauss
    alpha = dr.minimum(raw, cfg.alpha_max)
    contributes = active & (sigma <= 0.5 * cutoff) & (alpha >= cfg.alpha_min)
    return alpha, contributes, (dx, dy, conic, opacity, gauss, raw)


def _forward_loop(m, s: Splats, ids, lanes: Lanes, cfg: CompositeSettings, max_iterations=None):
    """Composite every lane; returns (rgb, T_final, depth_sum, stop_index) in lane order."""
    Float, UInt32 = m.Float, m.UInt32
    px, py = lanes.px, lanes.py

    def cond(i, T, r, g_, b, d, done):
        return (i < lanes.end) & ~done

    def body(i, T, r, g_, b, d, done):
        gid = dr.gather(UInt32, ids, i)
        alpha, contributes, _ = _gaussian_alpha(m, s, gid, px, py, cfg, True)
        t_next = T * (1.0 - alpha)
        stop = contributes & (t_next < cfg.transmittance_min)
        take = contributes & ~stop
        color = dr.gather(m.Array3f, s.colors, gid)
        depth = dr.gather(Float, s.depths, gid)
        w = dr.select(take, T * alpha, 0.0)
        r, g_, b, d = r + w * color.x, g_ + w * color.y, b + w * color.z, d + w * depth
        T = dr.select(take, t_next, T)
        i = dr.select(stop, i, i + 1)
        return i, T, r, g_, b, d, done | stop

    n = dr.width(px)
    zero = dr.zeros(Float, n)
    if dr.width(ids) == 0:  # nothing visible: every pixel shows the background
        return m.Array3f(zero, zero, zero), dr.full(Float, 1.0, n), zero, UInt32(lanes.start)
    state = (UInt32(lanes.start), dr.full(Float, 1.0, n), zero, Float(zero), Float(zero), Float(zero),
             dr.zeros(m.Bool, n))
    kwargs = {} if max_iterations is None else {"max_iterations": max_iterations}
    i, T, r, g_, b, d, _ = dr.while_loop(state, cond, body, labels=("i", "T", "r", "g", "b", "d", "done"),
                                         mode="symbolic", **kwargs)
    return m.Array3f(r, g_, b), T, d, i


def _to_image(m, lanes: Lanes, rgb, T, d, bg):
    """Lane order -> row-major image order; adds the background behind the splats."""
    idx = lanes.lane_of_pixel
    mode = dr.ReduceMode.Permute
    T_img = dr.gather(m.Float, T, idx, mode=mode)
    rgb_img = dr.gather(m.Array3f, rgb, idx, mode=mode) + T_img * m.Array3f(*bg)
    return Composite(rgb_img, 1.0 - T_img, dr.gather(m.Float, d, idx, mode=mode))


GRAD_KEYS = ("mx", "my", "ca", "cb", "cc", "o", "r", "g", "b", "z", "ax", "ay")


def _reduce_pairs(m, bins: Bins, pair: dict, n: int) -> dict:
    """Sum per-pair values per Gaussian, deterministically.

    The pairs are permuted back to Gaussian-major order (a permutation: no
    conflicts), then each Gaussian lane sums its own run in ascending order, so the
    result does not depend on thread scheduling.
    """
    Float, UInt32 = m.Float, m.UInt32
    major = {}
    for k, v in pair.items():
        major[k] = dr.zeros(Float, bins.num_pairs)
        dr.scatter(major[k], v, bins.order, mode=dr.ReduceMode.Permute)
    dr.eval(major)
    end = bins.offsets + bins.counts
    zero = dr.zeros(Float, n)

    def cond(j, *acc):
        return j < end

    def body(j, *acc):
        return (j + 1, *(a + dr.gather(Float, major[k], j) for a, k in zip(acc, major)))

    out = dr.while_loop((UInt32(bins.offsets), *(Float(zero) for _ in major)), cond, body, mode="symbolic")
    return dict(zip(major, out[1:]))


class _CompositeOp(dr.CustomOp):
    """Forward: `_forward_loop`. Backward: back-to-front walk with scatter-adds."""

    def eval(self, means2d, conics, opacities, colors, depths, cutoff_sq, state, cfg):
        m = array_namespace(opacities)
        state.op = self
        self.want_absgrad = state.want_absgrad
        self.timer = state.timer
        bins = state.bins
        self.m, self.bins, self.cfg = m, bins, cfg
        self.splats = Splats(means2d, conics, opacities, colors, depths, cutoff_sq)
        self.lanes = make_lanes(m, bins)
        rgb, T, d, stop = _forward_loop(m, self.splats, bins.gaussian_ids, self.lanes, cfg)
        dr.eval(rgb, T, d, stop)
        self.T_final, self.stop = T, stop
        self.grad_means2d = self.abs_grad_means2d = None
        # A plain tuple: Dr.Jit does not traverse NamedTuples, so a `Composite` here
        # would silently disconnect the outputs from the AD graph.
        return tuple(_to_image(m, self.lanes, rgb, T, d, cfg.background))

    def backward(self):
        m, s, lanes, cfg = self.m, self.splats, self.lanes, self.cfg
        Float, UInt32 = m.Float, m.UInt32
        v_rgb_img, v_alpha_img, v_d_img = self.grad_out()
        # Image order -> lane order (padding lanes get zero cotangents).
        v_rgb = dr.gather(m.Array3f, v_rgb_img, lanes.image_index, lanes.inside)
        v_alpha_out = dr.gather(Float, v_alpha_img, lanes.image_index, lanes.inside)
        v_d = dr.gather(Float, v_d_img, lanes.image_index, lanes.inside)
        keys = GRAD_KEYS if self.want_absgrad else GRAD_KEYS[:-2]
        n = dr.width(s.opacities)
        if self.bins.num_pairs == 0:  # nothing was composited: all gradients are zero
            zero = dr.zeros(Float, n)
            self.grad_means2d = m.Array2f(zero, zero)
            self.abs_grad_means2d = m.Array2f(zero, zero) if self.want_absgrad else None
            return
        # Per-pair accumulators: slot i belongs to one (tile, Gaussian) pair, so only the
        # lanes of one tile (one thread, fixed order) ever add into it.
        pair = {k: dr.zeros(Float, self.bins.num_pairs) for k in keys}
        T_final = self.T_final
        bg = cfg.background
        ids = self.bins.gaussian_ids
        px, py = lanes.px, lanes.py
        mode = dr.ReduceMode.Local  # the lanes of a packet share one slot: reduce them first

        # Lock-step walk: every lane of a tile starts at the tile's largest stop index,
        # so a SIMD packet always reads one Gaussian and the scatter-adds below reduce
        # within the packet to one memory update (lanes past their own stop are idle).
        tile_pixels = self.bins.grid.tile_size ** 2
        own_stop = self.stop
        tile_stop = dr.block_reduce(dr.ReduceOp.Max, own_stop, tile_pixels)
        start_i = dr.repeat(tile_stop, tile_pixels)

        def cond(i, T, ar, ag, ab, ad):
            return i > lanes.start

        def body(i, T, ar, ag, ab, ad):
            i = i - 1
            gid = dr.gather(UInt32, ids, i)
            alpha, on, (dx, dy, conic, opacity, gauss, raw) = _gaussian_alpha(
                m, s, gid, px, py, cfg, i < own_stop)
            color = dr.gather(m.Array3f, s.colors, gid, on)
            depth = dr.gather(Float, s.depths, gid, on)
            inv_1ma = 1.0 / (1.0 - alpha)
            T_i = T * inv_1ma  # transmittance in front of this Gaussian
            w = T_i * alpha
            v_alpha = (v_rgb.x * (T_i * color.x - ar * inv_1ma) + v_rgb.y * (T_i * color.y - ag * inv_1ma)
                       + v_rgb.z * (T_i * color.z - ab * inv_1ma) + v_d * (T_i * depth - ad * inv_1ma)
                       + v_alpha_out * T_final * inv_1ma)
            unclamped = on & (raw < cfg.alpha_max)
            v_raw = dr.select(unclamped, v_alpha, 0.0)
            v_sigma = -v_raw * raw
            v_mx = v_sigma * -(conic.x * dx + conic.y * dy)
            v_my = v_sigma * -(conic.y * dx + conic.z * dy)
            for key, val in (("mx", v_mx), ("my", v_my), ("ca", v_sigma * 0.5 * dx * dx),
                             ("cb", v_sigma * dx * dy), ("cc", v_sigma * 0.5 * dy * dy),
                             ("o", v_raw * gauss), ("r", v_rgb.x * w), ("g", v_rgb.y * w),
                             ("b", v_rgb.z * w), ("z", v_d * w), ("ax", dr.abs(v_mx)), ("ay", dr.abs(v_my))):
                if key in pair:
                    dr.scatter_add(pair[key], val, i, on, mode=mode)
            ar = dr.select(on, ar + w * color.x, ar)
            ag = dr.select(on, ag + w * color.y, ag)
            ab = dr.select(on, ab + w * color.z, ab)
            ad = dr.select(on, ad + w * depth, ad)
            T = dr.select(on, T_i, T)
            return i, T, ar, ag, ab, ad

        state = (UInt32(start_i), Float(T_final), T_final * bg[0], T_final * bg[1], T_final * bg[2],
                 dr.zeros(Float, dr.width(T_final)))
        dr.while_loop(state, cond, body, labels=("i", "T", "ar", "ag", "ab", "ad"), mode="symbolic")
        dr.eval(pair)
        buf = _reduce_pairs(m, self.bins, pair, n)
        self.grad_means2d = m.Array2f(buf["mx"], buf["my"])
        if self.want_absgrad:
            self.abs_grad_means2d = m.Array2f(buf["ax"], buf["ay"])
        self.set_grad_in("means2d", m.Array2f(buf["mx"], buf["my"]))
        self.set_grad_in("conics", m.Array3f(buf["ca"], buf["cb"], buf["cc"]))
        self.set_grad_in("opacities", buf["o"])
        self.set_grad_in("colors", m.Array3f(buf["r"], buf["g"], buf["b"]))
        self.set_grad_in("depths", buf["z"])
        if self.timer is not None:
            self.timer.mark("backward_compositing")

    def name(self):
        return "splatbench.composite"


class CompositeState:
    """What densification and benchmarks need from one compositing call.

    A plain class on purpose: Dr.Jit traverses dataclass arguments of `dr.custom`
    as PyTrees (and may copy them); this one must reach the op by reference.
    After a backward pass, ``op.grad_means2d`` [N, 2] and ``op.abs_grad_means2d``
    [N, 2] (per-pixel |d loss / d mean2d| summed, for AbsGS) are set.
    """

    __slots__ = ("bins", "op", "want_absgrad", "timer")

    def __init__(self, bins: Bins, want_absgrad: bool = False, timer=None) -> None:
        self.bins = bins
        self.op: _CompositeOp | None = None
        self.want_absgrad = want_absgrad
        self.timer = timer


def composite(means2d, conics, opacities, colors, depths, cutoff_sq, visible, width: int, height: int,
              *, background=(0.0, 0.0, 0.0), alpha_min: float = 1.0 / 255.0, alpha_max: float = 0.99,
              transmittance_min: float = 1e-4, tile_size: int = 16, extents=None,
              loop_ad: bool = False, absgrad: bool = False, timer=None) -> tuple[Composite, CompositeState]:
    """Alpha-composite screen-space Gaussians (mirrors `reference.composite`, matched mode).

    Args:
        means2d: [N, 2] Array2f. conics: [N, 3] Array3f. opacities, depths,
        cutoff_sq: [N] Float. colors: [N, 3] Array3f. visible: [N] Bool.
        extents: [N, 2] cutoff bounding-box half sizes (from `project`).
        loop_ad: differentiate the loop with Dr.Jit's AD instead of the
            hand-written backward (test-only: slower, checks the CustomOp).
        absgrad: also accumulate per-pixel |d loss / d mean2d| (AbsGS) in backward.
        timer: optional `StageTimer` (benchmarks): marks "binning" and, in backward,
            "backward_compositing".

    Returns:
        (`Composite` in row-major image order, `CompositeState`).
    """
    m = array_namespace(opacities)
    proj = Projection(means2d, conics, depths, opacities, cutoff_sq, extents, None, visible)
    bins = bin_gaussians(proj, TileGrid(width, height, tile_size))
    if timer is not None:
        timer.mark("binning")
    cfg = CompositeSettings(float(alpha_min), float(alpha_max), float(transmittance_min),
                            tuple(float(c) for c in background))
    if loop_ad:
        splats = Splats(means2d, conics, opacities, colors, depths, cutoff_sq)
        lanes = make_lanes(m, bins)
        # Reverse-mode AD through a symbolic loop needs a true upper bound on the trip
        # count (the longest tile list, rounded up to a power of two); -1 is wrong here.
        bound = next_power_of_two(max(bins.max_list_length, 1))
        rgb, T, d, _ = _forward_loop(m, splats, bins.gaussian_ids, lanes, cfg, max_iterations=bound)
        return _to_image(m, lanes, rgb, T, d, cfg.background), CompositeState(bins)
    state = CompositeState(bins, absgrad, timer)
    out = dr.custom(_CompositeOp, means2d, conics, opacities, colors, depths, cutoff_sq, state, cfg)
    return Composite(*out), state
