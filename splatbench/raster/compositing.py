"""Front-to-back alpha compositing over tiles, with an analytic backward pass.

Mirrors `reference.composite`. Lanes are ordered tile by tile (a SIMD packet of
16 lanes with AVX-512 holds one 16x16 tile), and each lane shades a block of
PIXEL_BLOCK x PIXEL_BLOCK pixels, walking its own list: the pairs of its tile whose
support meets the block (`blocks.block_lists`). One load of a Gaussian's packed
record serves the whole block, and in the backward pass the block's gradient
contributions are summed in registers before one scatter. A symbolic loop per lane
stops early once every pixel of the block would fall below the transmittance
threshold.

The backward pass is a `dr.CustomOp` that walks each lane's list back to front,
recovering transmittance by division (alpha <= alpha_max < 1 keeps it
invertible). Gradients are accumulated per (tile, Gaussian) pair, then reduced
per Gaussian in a fixed order, so results are bit-reproducible. On LLVM the lanes of
a tile add into one slot per pair (`ReduceMode.Expand`: per-thread copies, and a
tile never spans two threads); that mode exists only on LLVM, so elsewhere (CUDA)
each lane writes a slot of its own and the reduction sums a pair's lane slots in
lane order: no atomics, the same result every run (see `lane_slots`). Dr.Jit's own AD
through the forward loop (`composite(..., loop_ad=True)`) is kept as a test-only
second backward that checks the hand-written one.

Size (~490 lines, over the ~400 guideline on purpose): the forward loop and the
`dr.CustomOp` that walks it backwards share the record layout, the lane lists and
`_alpha_at`, and each line of the backward mirrors one of the forward; split across
modules, a change to one would no longer sit beside its adjoint. The lane/record
plumbing that does not need that (`blocks`, `binning`, `reduction`, `work`) lives
elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from splatbench.raster.device import dr
from splatbench.raster.binning import Bins, TileGrid, bin_gaussians
from splatbench.raster.projection import DEFAULTS, Projection, array_namespace, next_power_of_two
from splatbench.raster.reduction import PAIR_GROUPS, bucket, reduce_pairs, lane_slots

GEO = 8  # geometry record per Gaussian: u, v, conic A, B, C, opacity, depth, cutoff_sq
COL = 4  # colour record per Gaussian: r, g, b, (padding: packet loads need a power of two)
# Each lane shades a PIXEL_BLOCK x PIXEL_BLOCK block of pixels: one load of a record
# serves them all, and their gradient terms are summed in registers before a scatter.
# 4x4 measured best on AVX-512 (one 16-lane packet per 16x16 tile); see docs/benchmarks.md.
PIXEL_BLOCK = 4
GRAD_KEYS = ("mx", "my", "ca", "cb", "cc", "o", "r", "g", "b", "z", "ax", "ay")
#: The per-pair gradient terms each differentiable input of the op receives.
INPUT_KEYS = {"means2d": ("mx", "my"), "conics": ("ca", "cb", "cc"), "opacities": ("o",),
              "colors": ("r", "g", "b"), "depths": ("z",)}


def needed_keys(inputs: dict, absgrad: bool) -> tuple[str, ...]:
    """The `GRAD_KEYS` the compositing backward must accumulate: those of the inputs
    (``INPUT_KEYS`` name -> Dr.Jit array) with gradients enabled, plus the screen-space
    mean and its absolute value when AbsGS asks for them. Dr.Jit enables a screen-space
    quantity's gradient exactly when a trainable parameter reaches it (means2d and depths:
    the means; conics: means, log_scales, quats; opacities: opacity_logits, and with
    antialiasing the means, log_scales, quats; colors: sh and, through the view direction,
    the means), so a frozen group costs no per-pixel work here."""
    keys = {key for name, group in INPUT_KEYS.items() if dr.grad_enabled(inputs[name]) for key in group}
    if absgrad:
        keys |= {"mx", "my", "ax", "ay"}
    return tuple(key for key in GRAD_KEYS if key in keys)


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


class Records(NamedTuple):
    """Per-Gaussian data packed for packet loads: ``geo`` [N * GEO], ``col`` [N * COL].
    One packet gather of a record replaces a scalar gather per field in the loops."""

    geo: object
    col: object


def pack_records(m, s: Splats) -> Records:
    """Interleave the splat attributes into `Records` (differentiable scatters)."""
    n = dr.width(s.opacities)
    idx = dr.arange(m.UInt32, n)
    geo = dr.zeros(m.Float, GEO * n)
    col = dr.zeros(m.Float, COL * n)
    fields = (s.means2d.x, s.means2d.y, s.conics.x, s.conics.y, s.conics.z, s.opacities, s.depths, s.cutoff_sq)
    for k, value in enumerate(fields):
        dr.scatter(geo, value, idx * GEO + k, mode=dr.ReduceMode.Permute)
    for k, value in enumerate((s.colors.x, s.colors.y, s.colors.z)):
        dr.scatter(col, value, idx * COL + k, mode=dr.ReduceMode.Permute)
    return Records(geo, col)


class Lanes(NamedTuple):
    """Compositing lanes in tile order; each lane shades K = block^2 pixels.

    px, py, inside, image_index: lists of K arrays (pixel centres, whether the
    pixel exists, its row-major index); start, end: the lane's range in its list.
    lanes_per_tile: lanes that share one tile. pairs: None when each lane walks its
    tile's range of the sorted pairs; else the lanes' own lists (`blocks.block_lists`),
    each entry a sorted pair position.
    """

    px: list
    py: list
    inside: list
    image_index: list
    start: object
    end: object
    lanes_per_tile: int
    pairs: object = None


def pair_at(m, lanes: Lanes, i):
    """Sorted pair position of entry ``i`` of each lane's list."""
    return i if lanes.pairs is None else dr.gather(m.UInt32, lanes.pairs, i)


def make_lanes(m, grid: TileGrid, bins: Bins) -> Lanes:
    ts = grid.tile_size
    block = min(PIXEL_BLOCK, ts)
    side = ts // block                      # lanes per tile side
    lanes_per_tile = side * side
    lane = dr.arange(m.UInt32, grid.num_tiles * lanes_per_tile)
    tile = lane // lanes_per_tile           # powers of two: shifts
    local = lane % lanes_per_tile
    x0 = (tile % grid.tiles_x) * ts + (local % side) * block
    y0 = (tile // grid.tiles_x) * ts + (local // side) * block
    px, py, inside, image_index = [], [], [], []
    for ky in range(block):
        for kx in range(block):
            x, y = x0 + kx, y0 + ky
            ok = (x < grid.width) & (y < grid.height)
            px.append(m.Float(x) + 0.5)
            py.append(m.Float(y) + 0.5)
            inside.append(ok)
            image_index.append(dr.select(ok, y * grid.width + x, 0))
    start = dr.gather(m.UInt32, bins.tile_start, tile)
    any_inside = inside[0]
    for ok in inside[1:]:
        any_inside |= ok
    end = dr.select(any_inside, dr.gather(m.UInt32, bins.tile_end, tile), start)
    return Lanes(px, py, inside, image_index, start, end, lanes_per_tile)


def lanes_for(m, rec: Records, bins: Bins, cfg: CompositeSettings) -> Lanes:
    """The compositing lanes with their per-block lists (`blocks.block_lists`)."""
    from splatbench.raster.blocks import block_lists

    lanes = make_lanes(m, bins.grid, bins)
    if bins.num_pairs == 0:
        return lanes
    return block_lists(m, rec, bins, lanes, cfg.alpha_min, lambda r, gid: _load(m, r, gid))


def _half_mahalanobis(conic_a, conic_b, conic_c, dx, dy):
    """sigma = d^2 / 2 = 0.5 (A dx^2 + C dy^2) + B dx dy: the oracle's function of the same
    name (reference/composite.py), the same expression in the same order."""
    return 0.5 * (conic_a * dx * dx + conic_c * dy * dy) + conic_b * dx * dy


def _alpha_at(rec, px, py, cfg: CompositeSettings, active):
    """Alpha of one Gaussian (geometry record ``rec``) at pixel centre (px, py), and
    the pieces its gradient needs."""
    mean_x, mean_y, conic_a, conic_b, conic_c, opacity, depth, cutoff = rec
    dx = px - mean_x
    dy = py - mean_y
    sigma = _half_mahalanobis(conic_a, conic_b, conic_c, dx, dy)
    gauss = dr.exp(-sigma)
    raw = opacity * gauss
    alpha = dr.minimum(raw, cfg.alpha_max)
    contributes = active & (sigma <= 0.5 * cutoff) & (alpha >= cfg.alpha_min)
    return alpha, contributes, dx, dy, gauss, raw


def _load(m, rec: Records, gid, active=True):
    """(geometry fields, colour fields) of Gaussians ``gid`` as lists of Float."""
    n = dr.width(gid)
    geo = dr.gather(m.ArrayXf, rec.geo, gid, active, shape=(GEO, n))
    col = dr.gather(m.ArrayXf, rec.col, gid, active, shape=(COL, n))
    return [geo[k] for k in range(GEO)], [col[k] for k in range(3)]


class _Forward(NamedTuple):
    """Lane-order results, lists over the K pixels of a lane."""

    rgb: list
    T: list
    depth_sum: list
    stop: list  # exclusive end of each pixel's composited range


def _forward_loop(m, rec: Records, ids, lanes: Lanes, cfg: CompositeSettings, max_iterations=None) -> _Forward:
    Float, UInt32 = m.Float, m.UInt32
    K = len(lanes.px)
    n = dr.width(lanes.start)
    zero = dr.zeros(Float, n)
    one = dr.full(Float, 1.0, n)
    if dr.width(ids) == 0:  # nothing visible: every pixel shows the background
        return _Forward([m.Array3f(zero, zero, zero)] * K, [one] * K, [zero] * K, [UInt32(lanes.start)] * K)

    # state: i, then per pixel (T, r, g, b, depth_sum, stop); depth_sum = sum of T alpha z, the
    # oracle's D (reference/composite.py). A pixel is live while its stop
    # index still equals the lane's end (pixels outside the image start at `start`).
    # No Bool in the state on purpose: Dr.Jit 1.5 emits invalid LLVM IR (i8 vs i1)
    # when reverse-mode AD through the loop has to record a Bool state variable.
    def unpack(state):
        return state[0], [state[1 + 6 * k: 7 + 6 * k] for k in range(K)]

    def cond(*state):
        i, pix = unpack(state)
        live = pix[0][5] == lanes.end
        for p in pix[1:]:
            live = live | (p[5] == lanes.end)
        return (i < lanes.end) & live

    def body(*state):
        i, pix = unpack(state)
        gid = dr.gather(UInt32, ids, pair_at(m, lanes, i))
        geo, (cr, cg, cb) = _load(m, rec, gid)
        out = [i + 1]
        for k, (T, r, g, b, depth_sum, stop) in enumerate(pix):
            alpha, contributes, _, _, _, _ = _alpha_at(geo, lanes.px[k], lanes.py[k], cfg, stop == lanes.end)
            t_next = T * (1.0 - alpha)
            stop_now = contributes & (t_next < cfg.transmittance_min)
            take = contributes & ~stop_now
            w = dr.select(take, T * alpha, 0.0)
            out += [dr.select(take, t_next, T), r + w * cr, g + w * cg, b + w * cb, depth_sum + w * geo[6],
                    dr.select(stop_now, i, stop)]
        return tuple(out)

    state = [UInt32(lanes.start)]
    for k in range(K):
        state += [Float(one), Float(zero), Float(zero), Float(zero), Float(zero),
                  dr.select(lanes.inside[k], lanes.end, lanes.start)]
    kwargs = {} if max_iterations is None else {"max_iterations": max_iterations}
    final = dr.while_loop(tuple(state), cond, body, mode="symbolic", **kwargs)
    _, pix = unpack(final)
    return _Forward([m.Array3f(p[1], p[2], p[3]) for p in pix], [p[0] for p in pix], [p[4] for p in pix],
                    [p[5] for p in pix])


def _to_image(m, grid: TileGrid, lanes: Lanes, fwd: _Forward, bg) -> Composite:
    """Lane order -> row-major image order; adds the background behind the splats."""
    size = grid.width * grid.height
    rgb, T, depth_sum = dr.zeros(m.Array3f, size), dr.zeros(m.Float, size), dr.zeros(m.Float, size)
    for k in range(len(lanes.px)):
        idx, ok = lanes.image_index[k], lanes.inside[k]
        dr.scatter(rgb, fwd.rgb[k], idx, ok, mode=dr.ReduceMode.Permute)
        dr.scatter(T, fwd.T[k], idx, ok, mode=dr.ReduceMode.Permute)
        dr.scatter(depth_sum, fwd.depth_sum[k], idx, ok, mode=dr.ReduceMode.Permute)
    return Composite(rgb + T * m.Array3f(*bg), 1.0 - T, depth_sum)


class _CompositeOp(dr.CustomOp):
    """Forward: `_forward_loop`. Backward: back-to-front walk, per-pair accumulation."""

    def eval(self, means2d, conics, opacities, colors, depths, cutoff_sq, state, cfg):
        m = array_namespace(opacities)
        # The op keeps `state` (to publish its screen-space gradients there), but the
        # state never references the op: the op's arguments live on Dr.Jit's C++
        # side, so a cycle through them would never be collected (a leak per call).
        self.state = state
        self.m, self.bins, self.cfg = m, state.bins, cfg
        self.want_absgrad, self.timer = state.want_absgrad, state.timer
        self.n = dr.width(opacities)
        self.records = pack_records(m, Splats(means2d, conics, opacities, colors, depths, cutoff_sq))
        dr.eval(self.records)
        self.lanes = lanes_for(m, self.records, self.bins, cfg)
        fwd = _forward_loop(m, self.records, self.bins.gaussian_ids, self.lanes, cfg)
        dr.eval(fwd)
        self.fwd = fwd
        # A plain tuple: Dr.Jit does not traverse NamedTuples, so a `Composite` here
        # would silently disconnect the outputs from the AD graph.
        return tuple(_to_image(m, self.bins.grid, self.lanes, fwd, cfg.background))

    def backward(self):
        m, rec, lanes, cfg, bins = self.m, self.records, self.lanes, self.cfg, self.bins
        Float, UInt32 = m.Float, m.UInt32
        keys = self.state.grad_keys  # only what a trainable input needs (`needed_keys`)
        want_means2d = "mx" in keys
        if bins.num_pairs == 0 or not keys:  # nothing composited, or nothing to differentiate
            zero = dr.zeros(Float, self.n)
            self.state.grad_means2d = m.Array2f(zero, zero) if want_means2d else None
            self.state.abs_grad_means2d = m.Array2f(zero, zero) if self.want_absgrad else None
            self.records = self.lanes = self.fwd = None
            return
        # What the walk computes: alpha's cotangent (and the sum S of what lies behind it)
        # only for the geometry and opacity; the weight T alpha only for colours and depth.
        want_sigma = any(k in keys for k in ("mx", "my", "ca", "cb", "cc"))
        want_va = want_sigma or "o" in keys
        want_w = any(k in keys for k in ("r", "g", "b", "z"))
        # Per pixel state: T and, for alpha's cotangent, S = v . (what lies behind): the
        # cotangent-weighted colour and depth composited behind this Gaussian (background
        # included), v_rgb . rgb_behind + v_depth . depth_behind. One scalar instead of the
        # four channels: the walk is bound by the values it keeps live, not by arithmetic.
        width = 2 if want_va else 1
        v_rgb_img, v_alpha_img, v_d_img = self.grad_out()
        K = len(lanes.px)
        # Image order -> lane order (pixels outside the image get zero cotangents).
        v_rgb = [dr.gather(m.Array3f, v_rgb_img, lanes.image_index[k], lanes.inside[k]) for k in range(K)]
        v_alpha = [dr.gather(Float, v_alpha_img, lanes.image_index[k], lanes.inside[k]) for k in range(K)]
        v_d = [dr.gather(Float, v_d_img, lanes.image_index[k], lanes.inside[k]) for k in range(K)]
        T_final, stop = self.fwd.T, self.fwd.stop
        bg = cfg.background
        ids = bins.gaussian_ids
        # Per-pair accumulators: slot p belongs to one (tile, Gaussian) pair, so only the
        # lanes of one tile ever add into it.
        cap = bucket(bins.num_pairs)  # slots past num_pairs stay zero and are never read
        per_lane = lane_slots(m)
        L = lanes.lanes_per_tile if per_lane else 1
        pair = {name: dr.zeros(Float, size * cap * L) for name, (size, group) in PAIR_GROUPS.items()
                if any(key in keys for key in group)}
        # Expand (LLVM): per-thread copies, non-atomic updates. Still deterministic: a slot
        # is only written by the lanes of one tile, and a tile never spans two threads.
        # Per-lane slots (CUDA): each slot is written once, by one lane, without atomics.
        sub_slot = dr.arange(UInt32, dr.width(lanes.start)) % L if per_lane else None
        # Each lane walks its own list back from the largest stop index of its pixels.
        start_i = stop[0]
        for s in stop[1:]:
            start_i = dr.maximum(start_i, s)

        def unpack(state):  # i, then per pixel (T, S) or (T,)
            return state[0], [state[1 + width * k: 1 + width * (k + 1)] for k in range(K)]

        def cond(*state):
            return state[0] > lanes.start

        def body(*state):
            i, pix = unpack(state)
            i = i - 1
            p = pair_at(m, lanes, i)
            gid = dr.gather(UInt32, ids, p)
            geo, (cr, cg, cb) = _load(m, rec, gid)
            ca, cbk, cc, depth = geo[2], geo[3], geo[4], geo[6]
            sums = {key: 0.0 for key in keys}
            out = [i]
            any_on = None
            for k, px_state in enumerate(pix):
                T = px_state[0]
                alpha, on, dx, dy, gauss, raw = _alpha_at(geo, lanes.px[k], lanes.py[k], cfg, i < stop[k])
                inv_1ma = 1.0 / (1.0 - alpha)
                T_i = T * inv_1ma  # transmittance in front of this Gaussian
                w = T_i * alpha
                vr, vg, vb = v_rgb[k].x, v_rgb[k].y, v_rgb[k].z
                terms = {}
                if want_va:
                    behind = px_state[1]
                    v_here = vr * cr + vg * cg + vb * cb + v_d[k] * depth  # v . (colour, depth) of this one
                    v_a = T_i * v_here - behind * inv_1ma + v_alpha[k] * T_final[k] * inv_1ma
                    v_raw = dr.select(on & (raw < cfg.alpha_max), v_a, 0.0)
                    terms["o"] = v_raw * gauss
                if want_sigma:
                    v_sigma = -v_raw * raw
                    v_mx = v_sigma * -(ca * dx + cbk * dy)
                    v_my = v_sigma * -(cbk * dx + cc * dy)
                    terms.update({"mx": v_mx, "my": v_my, "ca": v_sigma * 0.5 * dx * dx, "cb": v_sigma * dx * dy,
                                  "cc": v_sigma * 0.5 * dy * dy, "ax": dr.abs(v_mx), "ay": dr.abs(v_my)})
                if want_w:
                    w_on = dr.select(on, w, 0.0)
                    terms.update({"r": vr * w_on, "g": vg * w_on, "b": vb * w_on, "z": v_d[k] * w_on})
                for key in keys:
                    sums[key] = sums[key] + terms[key]
                any_on = on if any_on is None else any_on | on
                out.append(dr.select(on, T_i, T))
                if want_va:
                    out.append(dr.select(on, behind + w * v_here, behind))
            for name, buffer in pair.items():
                values = m.ArrayXf([sums[key] if key in keys else 0.0 for key in PAIR_GROUPS[name][1]])
                if per_lane:
                    dr.scatter(buffer, values, p * L + sub_slot, any_on)
                else:
                    dr.scatter_add(buffer, values, p, any_on, mode=dr.ReduceMode.Expand)
            return tuple(out)

        state = [UInt32(start_i)]
        for k in range(K):
            T = T_final[k]
            v = v_rgb[k]
            state += [Float(T), T * (v.x * bg[0] + v.y * bg[1] + v.z * bg[2])][:width]
        dr.while_loop(tuple(state), cond, body, mode="symbolic")
        dr.eval(pair)
        # The walk was the last reader of the records, lane lists and forward state:
        # release them before the reduction allocates (the op runs its backward once).
        del state, v_rgb, v_alpha, v_d, T_final, stop, start_i, rec, lanes
        self.records = self.lanes = self.fwd = None
        buf = reduce_pairs(m, bins, pair, self.n, L)
        if want_means2d:
            self.state.grad_means2d = m.Array2f(buf["mx"], buf["my"])
        if self.want_absgrad:
            self.state.abs_grad_means2d = m.Array2f(buf["ax"], buf["ay"])
        for name, group in INPUT_KEYS.items():
            if group[0] in keys:  # a group is computed whole or not at all (`needed_keys`)
                values = [buf[key] for key in group]
                self.set_grad_in(name, values[0] if len(values) == 1 else getattr(m, f"Array{len(values)}f")(*values))
        if self.timer is not None:
            self.timer.mark("backward_compositing")

    def name(self):
        return "splatbench.composite"


class CompositeState:
    """What densification and benchmarks need from one compositing call.

    A plain class on purpose: Dr.Jit traverses dataclass arguments of `dr.custom`
    as PyTrees (and may copy them); this one must reach the op by reference.
    After a backward pass the op sets ``grad_means2d`` [N, 2] (None when the means are
    frozen and AbsGS is off: then it is not computed) and, when asked,
    ``abs_grad_means2d`` [N, 2] (per-pixel |d loss / d mean2d| summed, for AbsGS).
    ``grad_keys``: the per-pair gradient terms the backward pass accumulates
    (`needed_keys`; a frozen group's are left out, and with them their per-pixel work).
    It holds no reference to the op (see `_CompositeOp.eval`).
    """

    __slots__ = ("bins", "want_absgrad", "timer", "grad_means2d", "abs_grad_means2d", "grad_keys")

    def __init__(self, bins: Bins, want_absgrad: bool = False, timer=None, grad_keys: tuple[str, ...] = ()) -> None:
        self.bins = bins
        self.want_absgrad = want_absgrad
        self.timer = timer
        self.grad_keys = grad_keys  # the `GRAD_KEYS` the backward pass accumulates (`needed_keys`)
        self.grad_means2d = None
        self.abs_grad_means2d = None


def composite(means2d, conics, opacities, colors, depths, cutoff_sq, visible, width: int, height: int,
              *, background=(0.0, 0.0, 0.0), alpha_min: float = DEFAULTS.alpha_min,
              alpha_max: float = DEFAULTS.alpha_max, transmittance_min: float = DEFAULTS.transmittance_min,
              tile_size: int = DEFAULTS.tile_size, extents=None,
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
    grid = TileGrid(width, height, tile_size)
    bins = bin_gaussians(proj, grid, float(alpha_min))
    if timer is not None:
        timer.mark("binning")
    cfg = CompositeSettings(float(alpha_min), float(alpha_max), float(transmittance_min),
                            tuple(float(c) for c in background))
    if loop_ad:
        records = pack_records(m, Splats(means2d, conics, opacities, colors, depths, cutoff_sq))
        lanes = lanes_for(m, records, bins, cfg)
        # Reverse-mode AD through a symbolic loop needs a true upper bound on the trip
        # count (the longest tile list, rounded up to a power of two); -1 is wrong here.
        bound = next_power_of_two(max(bins.max_list_length, 1))
        fwd = _forward_loop(m, records, bins.gaussian_ids, lanes, cfg, max_iterations=bound)
        return _to_image(m, grid, lanes, fwd, cfg.background), CompositeState(bins)
    keys = needed_keys({"means2d": means2d, "conics": conics, "opacities": opacities, "colors": colors,
                        "depths": depths}, absgrad)
    state = CompositeState(bins, absgrad, timer, keys)
    out = dr.custom(_CompositeOp, means2d, conics, opacities, colors, depths, cutoff_sq, state, cfg)
    return Composite(*out), state
