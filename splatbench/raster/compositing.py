"""Front-to-back alpha compositing over tiles, with an analytic backward pass.

Mirrors `reference.composite`. Lanes are ordered tile by tile (with 4x4 blocks a SIMD
packet of 16 lanes with AVX-512 holds one 16x16 tile), and each lane shades a block of
B x B pixels (`RasterOptions.pixel_block`), walking its own list: the pairs of its tile whose
support meets the block (`blocks.block_lists`). One load of a Gaussian's packed
record serves the whole block, and in the backward pass the block's gradient
contributions are summed in registers before one scatter. A symbolic loop per lane
stops early once every pixel of the block would fall below the transmittance
threshold.

The backward pass is a `dr.CustomOp` that walks each lane's list back to front,
recovering transmittance by division (alpha <= alpha_max < 1 keeps it
invertible). Gradients are accumulated per (tile, Gaussian) pair, then reduced
per Gaussian in a fixed order, so results are bit-reproducible at every tile size. On
LLVM the lanes of one SIMD packet add into one slot per pair (`ReduceMode.Expand`:
per-thread copies, and a packet never spans two threads; a tile wider than a packet has
a slot per packet); that mode exists only on LLVM, so elsewhere (CUDA) each lane writes a
slot of its own; the reduction sums a pair's slots in order: no atomics, the same result
every run (see `reduction.lane_group`). Dr.Jit's own AD
through the forward loop (`composite_loop_ad`) is kept as a test-only
second backward that checks the hand-written one.

The loops carry a flat tuple of Dr.Jit arrays; `_FrontPixel` and `_BackPixel` name each
pixel's part of it. The backward pass runs in named steps (`_WalkPlan`, `_lane_cotangents`,
`reduction.PairBuffers`, `_walk_back`, `_adjoint_step` per pixel, `_publish`), each
beside the forward code it differentiates. The record layout (`records`), the lanes and
their lists (`blocks`), binning and the per-pair reduction live in modules of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from splatbench.raster.device import dr
from splatbench.raster.binning import Bins, TileGrid
from splatbench.raster.blocks import Lanes, lanes_for, pair_at
from splatbench.raster.options import DEFAULT_PIXEL_BLOCK, RasterOptions
from splatbench.raster.projection import Projection, array_namespace, next_power_of_two
from splatbench.raster.records import GeoRecord, Records, Splats, load_records, pack_records
from splatbench.raster.reduction import PairBuffers, reduce_pairs

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
    """What the compositing loops read of `RasterOptions` (its thresholds, as Python floats:
    constants of the traced kernels; the side of a lane's pixel block, `pixel_block`: the lane
    layout, never the image) and the RGB background; made from the options only, by
    `from_options` (`composite`, `composite_loop_ad`, `work.work_stats`)."""

    alpha_min: float
    alpha_max: float
    transmittance_min: float
    background: tuple[float, float, float]
    pixel_block: int = DEFAULT_PIXEL_BLOCK

    @classmethod
    def from_options(cls, options: RasterOptions, background=(0.0, 0.0, 0.0)) -> CompositeSettings:
        return cls(float(options.alpha_min), float(options.alpha_max), float(options.transmittance_min),
                   tuple(float(c) for c in background), options.pixel_block)


class Composite(NamedTuple):
    """Per-pixel outputs in row-major image order (width H*W):
    rgb [H*W, 3] (Array3f), alpha [H*W], depth_sum [H*W] = sum of T*alpha*z
    (divide by alpha for expected depth)."""

    rgb: object
    alpha: object
    depth_sum: object


def _half_mahalanobis(conic_a, conic_b, conic_c, dx, dy):
    """sigma = d^2 / 2 = 0.5 (A dx^2 + C dy^2) + B dx dy: the oracle's function of the same
    name (reference/composite.py), the same expression in the same order."""
    return 0.5 * (conic_a * dx * dx + conic_c * dy * dy) + conic_b * dx * dy


def _alpha_at(geo: GeoRecord, px, py, cfg: CompositeSettings, active):
    """Alpha of one Gaussian (geometry record ``geo``) at pixel centre (px, py), and
    the pieces its gradient needs."""
    dx = px - geo.u
    dy = py - geo.v
    sigma = _half_mahalanobis(geo.conic_a, geo.conic_b, geo.conic_c, dx, dy)
    gauss = dr.exp(-sigma)
    raw = geo.opacity * gauss
    alpha = dr.minimum(raw, cfg.alpha_max)
    contributes = active & (sigma <= 0.5 * geo.cutoff_sq) & (alpha >= cfg.alpha_min)
    return alpha, contributes, dx, dy, gauss, raw


class _Forward(NamedTuple):
    """Lane-order results, lists over the K pixels of a lane."""

    rgb: list
    T: list
    depth_sum: list
    stop: list  # exclusive end of each pixel's composited range


class _FrontPixel(NamedTuple):
    """One pixel's state in the forward walk (front to back). No Bool on purpose: Dr.Jit 1.5
    emits invalid LLVM IR (i8 vs i1) when reverse-mode AD through the loop has to record a
    Bool state variable; a pixel is live while ``stop`` still equals the lane's end."""

    T: object          # transmittance in front of the next Gaussian
    r: object          # colour composited so far
    g: object
    b: object
    depth_sum: object  # sum of T alpha z: the oracle's D (reference/composite.py)
    stop: object       # UInt32: where the pixel stopped; the lane's end while live (start if outside the image)


class _BackPixel(NamedTuple):
    """One pixel's state in the backward walk (back to front).

    T: the transmittance in front of the Gaussians walked so far (T_final at the start).
    behind: only when alpha's cotangent is wanted (else None, and not carried), S =
    v . (what lies behind): the cotangent-weighted colour and depth composited behind the
    current Gaussian (background included), v_rgb . rgb_behind + v_depth . depth_behind.
    One scalar instead of the four channels: the walk is bound by the values it keeps
    live, not by arithmetic.
    """

    T: object
    behind: object = None

    def step(self, on, T_i, w, v_here) -> _BackPixel:
        """The state once the walk has passed a Gaussian (``on``: it contributed, with
        weight ``w`` = T_i alpha and cotangent-weighted value ``v_here``)."""
        T = dr.select(on, T_i, self.T)
        if self.behind is None:
            return _BackPixel(T)
        return _BackPixel(T, dr.select(on, self.behind + w * v_here, self.behind))


def _pack(i, pixels) -> tuple:
    """The flat state a compositing loop carries: the list index ``i``, then each pixel's
    fields in order (a field that is None is not carried)."""
    return (i, *(value for pixel in pixels for value in pixel if value is not None))


def _unpack(state, pixel_type, width: int):
    """(index, [pixel_type of each pixel]) from a flat loop state of ``width`` fields per pixel."""
    return state[0], [pixel_type(*state[1 + width * k: 1 + width * (k + 1)]) for k in range((len(state) - 1) // width)]


def _forward_loop(m, rec: Records, ids, lanes: Lanes, cfg: CompositeSettings, max_iterations=None) -> _Forward:
    """Composite each lane's list front to back, from nothing composited yet."""
    Float, UInt32 = m.Float, m.UInt32
    K = len(lanes.px)
    n = dr.width(lanes.start)
    zero = dr.zeros(Float, n)
    one = dr.full(Float, 1.0, n)
    if dr.width(ids) == 0:  # nothing visible: every pixel shows the background
        return _Forward([m.Array3f(zero, zero, zero)] * K, [one] * K, [zero] * K, [UInt32(lanes.start)] * K)
    width = len(_FrontPixel._fields)

    def cond(*state):
        i, pixels = _unpack(state, _FrontPixel, width)
        live = pixels[0].stop == lanes.end
        for p in pixels[1:]:
            live = live | (p.stop == lanes.end)
        return (i < lanes.end) & live

    def body(*state):
        i, pixels = _unpack(state, _FrontPixel, width)
        gid = dr.gather(UInt32, ids, pair_at(m, lanes, i))
        geo, (cr, cg, cb) = load_records(m, rec, gid)
        i_next = i + 1
        after = []
        for k, p in enumerate(pixels):
            alpha, contributes, _, _, _, _ = _alpha_at(geo, lanes.px[k], lanes.py[k], cfg, p.stop == lanes.end)
            t_next = p.T * (1.0 - alpha)
            stop_now = contributes & (t_next < cfg.transmittance_min)
            take = contributes & ~stop_now
            w = dr.select(take, p.T * alpha, 0.0)
            after.append(_FrontPixel(T=dr.select(take, t_next, p.T), r=p.r + w * cr, g=p.g + w * cg, b=p.b + w * cb,
                                     depth_sum=p.depth_sum + w * geo.depth, stop=dr.select(stop_now, i, p.stop)))
        return _pack(i_next, after)

    start = _pack(UInt32(lanes.start), [_FrontPixel(Float(one), Float(zero), Float(zero), Float(zero), Float(zero),
                                                    dr.select(lanes.inside[k], lanes.end, lanes.start))
                                        for k in range(K)])
    kwargs = {} if max_iterations is None else {"max_iterations": max_iterations}
    final = dr.while_loop(start, cond, body, mode="symbolic", **kwargs)
    _, pixels = _unpack(final, _FrontPixel, width)
    return _Forward([m.Array3f(p.r, p.g, p.b) for p in pixels], [p.T for p in pixels], [p.depth_sum for p in pixels],
                    [p.stop for p in pixels])


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


@dataclass(frozen=True)
class _WalkPlan:
    """What the backward walk computes for the gradient ``keys`` it accumulates: alpha's
    cotangent (and the sum S behind it) only for the geometry and opacity; the weight
    T alpha only for colours and depth."""

    keys: tuple[str, ...]
    want_sigma: bool  # the 2D mean and conic terms
    want_va: bool     # alpha's cotangent (carries S per pixel)
    want_w: bool      # the colour and depth terms

    @classmethod
    def of(cls, keys: tuple[str, ...]) -> _WalkPlan:
        want_sigma = any(k in keys for k in ("mx", "my", "ca", "cb", "cc"))
        return cls(keys, want_sigma, want_sigma or "o" in keys, any(k in keys for k in ("r", "g", "b", "z")))

    @property
    def width(self) -> int:
        """Loop-state fields per pixel: (T, S), or (T,) without alpha's cotangent."""
        return 2 if self.want_va else 1


class _PixelCotangent(NamedTuple):
    """What the backward walk reads of one pixel of each lane (lane order)."""

    v_rgb: object    # Array3f, d loss / d rgb (zero for pixels outside the image)
    v_alpha: object  # d loss / d alpha
    v_depth: object  # d loss / d depth_sum
    T_final: object  # transmittance after the forward walk
    stop: object     # exclusive end of the forward walk's range


def _lane_cotangents(m, lanes: Lanes, fwd: _Forward, v_rgb_img, v_alpha_img, v_d_img) -> list[_PixelCotangent]:
    """The outputs' cotangents, image order -> lane order, with the forward walk's end state."""
    K = len(lanes.px)
    v_rgb = [dr.gather(m.Array3f, v_rgb_img, lanes.image_index[k], lanes.inside[k]) for k in range(K)]
    v_alpha = [dr.gather(m.Float, v_alpha_img, lanes.image_index[k], lanes.inside[k]) for k in range(K)]
    v_d = [dr.gather(m.Float, v_d_img, lanes.image_index[k], lanes.inside[k]) for k in range(K)]
    return [_PixelCotangent(v_rgb[k], v_alpha[k], v_d[k], fwd.T[k], fwd.stop[k]) for k in range(K)]


def _adjoint_step(geo: GeoRecord, colour, px, py, cfg: CompositeSettings, plan: _WalkPlan, pix: _PixelCotangent,
                  state: _BackPixel, active, sums: dict):
    """The adjoint of one forward step at one pixel: adds the pixel's gradient terms for the
    Gaussian (``geo``, ``colour``) into ``sums``; returns (on, T_i, w, v_here) for `_BackPixel.step`."""
    cr, cg, cb = colour
    alpha, on, dx, dy, gauss, raw = _alpha_at(geo, px, py, cfg, active)
    inv_1ma = 1.0 / (1.0 - alpha)
    T_i = state.T * inv_1ma  # transmittance in front of this Gaussian
    w = T_i * alpha
    vr, vg, vb = pix.v_rgb.x, pix.v_rgb.y, pix.v_rgb.z
    terms, v_here = {}, None
    if plan.want_va:
        v_here = vr * cr + vg * cg + vb * cb + pix.v_depth * geo.depth  # v . (colour, depth) of this one
        v_a = T_i * v_here - state.behind * inv_1ma + pix.v_alpha * pix.T_final * inv_1ma
        v_raw = dr.select(on & (raw < cfg.alpha_max), v_a, 0.0)
        terms["o"] = v_raw * gauss
    if plan.want_sigma:
        ca, cb_, cc = geo.conic_a, geo.conic_b, geo.conic_c
        v_sigma = -v_raw * raw
        v_mx = v_sigma * -(ca * dx + cb_ * dy)
        v_my = v_sigma * -(cb_ * dx + cc * dy)
        terms.update({"mx": v_mx, "my": v_my, "ca": v_sigma * 0.5 * dx * dx, "cb": v_sigma * dx * dy,
                      "cc": v_sigma * 0.5 * dy * dy, "ax": dr.abs(v_mx), "ay": dr.abs(v_my)})
    if plan.want_w:
        w_on = dr.select(on, w, 0.0)
        terms.update({"r": vr * w_on, "g": vg * w_on, "b": vb * w_on, "z": pix.v_depth * w_on})
    for key in plan.keys:
        sums[key] = sums[key] + terms[key]
    return on, T_i, w, v_here


def _walk_back(m, rec: Records, ids, lanes: Lanes, cfg: CompositeSettings, plan: _WalkPlan,
               cotangents: list[_PixelCotangent], buffers: PairBuffers) -> None:
    """Walk each lane's list back to front from the largest stop index of its pixels,
    recovering transmittance by division, and add each step's terms into ``buffers``."""
    UInt32 = m.UInt32
    start_i = cotangents[0].stop
    for c in cotangents[1:]:
        start_i = dr.maximum(start_i, c.stop)

    def cond(*state):
        return state[0] > lanes.start

    def body(*state):
        i, pixels = _unpack(state, _BackPixel, plan.width)
        i = i - 1
        p = pair_at(m, lanes, i)
        geo, colour = load_records(m, rec, dr.gather(UInt32, ids, p))
        sums = {key: 0.0 for key in plan.keys}
        after, any_on = [], None
        for k, (pix, pixel) in enumerate(zip(cotangents, pixels)):
            on, T_i, w, v_here = _adjoint_step(geo, colour, lanes.px[k], lanes.py[k], cfg, plan, pix, pixel,
                                               i < pix.stop, sums)
            any_on = on if any_on is None else any_on | on
            after.append(pixel.step(on, T_i, w, v_here))
        buffers.add(m, p, sums, any_on)
        return _pack(i, after)

    bg = cfg.background
    start = _pack(UInt32(start_i), [
        _BackPixel(m.Float(c.T_final),
                   c.T_final * (c.v_rgb.x * bg[0] + c.v_rgb.y * bg[1] + c.v_rgb.z * bg[2]) if plan.want_va else None)
        for c in cotangents])
    dr.while_loop(start, cond, body, mode="symbolic")
    dr.eval(buffers.groups)


class _CompositeOp(dr.CustomOp):
    """Forward: `_forward_loop`. Backward: back-to-front walk, per-pair accumulation."""

    def eval(self, means2d, conics, opacities, colors, depths, cutoff_sq, state, cfg):
        m = array_namespace(opacities)
        # The op keeps `state` (to publish its screen-space gradients there), but the
        # state never references the op: the op's arguments live on Dr.Jit's C++
        # side, so a cycle through them would never be collected (a leak per call).
        self.state = state
        self.m, self.bins, self.cfg = m, state.bins, cfg
        self.want_absgrad = state.want_absgrad
        self.n = dr.width(opacities)
        self.records = pack_records(m, Splats(means2d, conics, opacities, colors, depths, cutoff_sq))
        dr.eval(self.records)
        self.lanes = lanes_for(m, self.records, self.bins, cfg.pixel_block)
        fwd = _forward_loop(m, self.records, self.bins.gaussian_ids, self.lanes, cfg)
        dr.eval(fwd)
        self.fwd = fwd
        # A plain tuple: Dr.Jit does not traverse NamedTuples, so a `Composite` here
        # would silently disconnect the outputs from the AD graph.
        return tuple(_to_image(m, self.bins.grid, self.lanes, fwd, cfg.background))

    def backward(self):
        keys = self.state.grad_keys  # only what a trainable input needs (`needed_keys`)
        if self.bins.num_pairs == 0 or not keys:  # nothing composited, or nothing to differentiate
            self._publish_zeros(keys)
            return
        m, lanes = self.m, self.lanes
        cotangents = _lane_cotangents(m, lanes, self.fwd, *self.grad_out())
        buffers = PairBuffers.allocate(m, self.bins, lanes, keys)
        _walk_back(m, self.records, self.bins.gaussian_ids, lanes, self.cfg, _WalkPlan.of(keys), cotangents, buffers)
        # The walk was the last reader of the records, lane lists and forward state:
        # release them before the reduction allocates (the op runs its backward once).
        del cotangents, lanes
        self.records = self.lanes = self.fwd = None
        self._publish(reduce_pairs(m, self.bins, buffers.groups, self.n, buffers.slots_per_pair), keys)
        if self.state.timer is not None:
            self.state.timer.mark("backward_compositing")

    def _publish_zeros(self, keys) -> None:
        """Nothing to walk: zero screen-space gradients where they are asked for (the inputs get none)."""
        m = self.m
        zero = dr.zeros(m.Float, self.n)
        self.state.grad_means2d = m.Array2f(zero, zero) if "mx" in keys else None
        self.state.abs_grad_means2d = m.Array2f(zero, zero) if self.want_absgrad else None
        self.records = self.lanes = self.fwd = None

    def _publish(self, sums: dict, keys) -> None:
        """Hand the per-Gaussian sums on: the screen-space mean's to the state (densification,
        AbsGS), each differentiable input's to Dr.Jit."""
        m = self.m
        if "mx" in keys:
            self.state.grad_means2d = m.Array2f(sums["mx"], sums["my"])
        if self.want_absgrad:
            self.state.abs_grad_means2d = m.Array2f(sums["ax"], sums["ay"])
        for name, group in INPUT_KEYS.items():
            if group[0] in keys:  # a group is computed whole or not at all (`needed_keys`)
                values = [sums[key] for key in group]
                self.set_grad_in(name, values[0] if len(values) == 1 else getattr(m, f"Array{len(values)}f")(*values))

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
    ``timer``: None, or a benchmark's `StageTimer` that the caller attaches after
    `composite` returns; the backward pass marks "backward_compositing" on it.
    It holds no reference to the op (see `_CompositeOp.eval`).
    """

    __slots__ = ("bins", "want_absgrad", "timer", "grad_means2d", "abs_grad_means2d", "grad_keys")

    def __init__(self, bins: Bins, want_absgrad: bool = False, grad_keys: tuple[str, ...] = ()) -> None:
        self.bins = bins
        self.want_absgrad = want_absgrad
        self.timer = None
        self.grad_keys = grad_keys  # the `GRAD_KEYS` the backward pass accumulates (`needed_keys`)
        self.grad_means2d = None
        self.abs_grad_means2d = None


def splat_records(proj: Projection, colors=None) -> Records:
    """``proj``'s Gaussians packed as the compositing loop reads them (`records.pack_records`);
    ``colors``: [N, 3] Array3f, None for black (the work counts and lane studies read only the
    geometry)."""
    m = array_namespace(proj.opacities)
    colors = dr.zeros(m.Array3f, dr.width(proj.depths)) if colors is None else colors
    return pack_records(m, Splats(proj.means2d, proj.conics, proj.opacities, colors, proj.depths, proj.cutoff_sq))


def composite(proj: Projection, colors, bins: Bins, options: RasterOptions, background=(0.0, 0.0, 0.0), *,
              absgrad: bool = False) -> tuple[Composite, CompositeState]:
    """Alpha-composite screen-space Gaussians (mirrors `reference.composite`, matched mode):
    the last stage of `project` -> `bin_gaussians` -> `composite`.

    Args:
        proj: `Projection` of N Gaussians (means2d [N, 2], conics [N, 3], opacities [N],
            depths [N], cutoff_sq [N]; gradients flow to the first four).
        colors: [N, 3] Array3f, the Gaussians' colours.
        bins: `Bins` of ``proj`` from `bin_gaussians` with the same ``options``.
        options: `RasterOptions`; compositing reads alpha_min, alpha_max and transmittance_min.
        background: RGB behind the splats, 3 floats (checked by the caller).
        absgrad: also accumulate per-pixel |d loss / d mean2d| (AbsGS) in backward.

    Returns:
        (`Composite` in row-major image order, `CompositeState`).
    """
    keys = needed_keys({"means2d": proj.means2d, "conics": proj.conics, "opacities": proj.opacities,
                        "colors": colors, "depths": proj.depths}, absgrad)
    state = CompositeState(bins, absgrad, grad_keys=keys)
    out = dr.custom(_CompositeOp, proj.means2d, proj.conics, proj.opacities, colors, proj.depths, proj.cutoff_sq,
                    state, CompositeSettings.from_options(options, background))
    return Composite(*out), state


def composite_loop_ad(proj: Projection, colors, bins: Bins, options: RasterOptions,
                      background=(0.0, 0.0, 0.0)) -> tuple[Composite, CompositeState]:
    """`composite` differentiated by Dr.Jit's AD through the forward loop instead of the
    hand-written backward (test-only: slower; checks `_CompositeOp`)."""
    settings = CompositeSettings.from_options(options, background)
    m = array_namespace(proj.opacities)
    records = splat_records(proj, colors)
    lanes = lanes_for(m, records, bins, settings.pixel_block)
    # Reverse-mode AD through a symbolic loop needs a true upper bound on the trip
    # count (the longest tile list, rounded up to a power of two); -1 is wrong here.
    bound = next_power_of_two(max(bins.max_list_length, 1))
    fwd = _forward_loop(m, records, bins.gaussian_ids, lanes, settings, max_iterations=bound)
    return _to_image(m, bins.grid, lanes, fwd, settings.background), CompositeState(bins)
