"""Tile binning: expand Gaussian-tile pairs, sort by (tile, depth), find tile ranges.

A pair every pixel of its tile would skip changes no output, so binning keeps only
pairs some pixel centre of the tile can accept, in two conservative steps:

1. Each Gaussian's **support**, the ellipse of pixels the compositing loop can accept:
   q = 2 sigma <= min(R^2, 2 ln(opacity / alpha_min)) (`support_radius_sq`, computed once
   per Gaussian and kept in `Bins.support_sq`), and the tight bounding box of that ellipse
   (`support_extents`): a faint Gaussian's box is far smaller than its cutoff box.
2. The tiles of that box that the ellipse meets (`ellipse_meets_rect`, tested at the
   tile's pixel-centre rectangle).

Both steps widen by a float32 slack derived below, so they can only keep a pair that
every pixel skips, never drop one a pixel accepts; and the support box holds every tile
the ellipse test keeps, so the pairs, their order, the images and the gradients are
exactly those of testing every tile of the cutoff box (tests/test_raster_binning.py).
This is not ``radius="opacity"``, which changes the cutoff R^2 itself (and so the image).

The sort is linear: the Gaussians are sorted by depth once (N keys, not P pairs), their
pairs are generated in that order, and one stable counting sort by tile
(`dr.detail.block_mkperm`; 8-bit radix passes on CUDA, where only small bucket counts
sort stably) puts the pairs in (tile, depth) order. No gradients flow
through binning.
"""

from __future__ import annotations

from dataclasses import dataclass

from splatbench.raster.device import dr
from splatbench.raster.options import RasterOptions
from splatbench.raster.projection import Projection, array_namespace

# Slack of the rectangle test, relative to the size of the quadratic form's terms
# (A dx^2 + 2|B dx dy| + C dy^2). The compositing loop and this test each evaluate
# q in float32 with about 8 roundings of relative error 2^-24 on those terms (dx = px - u,
# three products, two sums, the scale by 0.5); 2^-16 is 256 unit roundoffs, far above
# their sum, so the test never rejects a pixel the loop would accept.
Q_REL_SLACK = 2.0 ** -16
# Absolute slack on the alpha_min radius 2 ln(o / alpha_min): exp, the product o * G
# and log each round by about 2^-24 relative, i.e. about 2^-23 in ln; 2^-12 covers it.
LN_ABS_SLACK = 2.0 ** -12
# Largest relative widening `support_extents` applies (see there); a Gaussian whose
# conic is too ill-conditioned for it keeps its cutoff box.
MAX_WIDENING = 0.125


@dataclass(frozen=True)
class TileGrid:
    """Pixels grouped into square tiles; compositing lanes are ordered tile by tile."""

    width: int
    height: int
    tile_size: int

    @property
    def tiles_x(self) -> int:
        return -(-self.width // self.tile_size)

    @property
    def tiles_y(self) -> int:
        return -(-self.height // self.tile_size)

    @property
    def num_tiles(self) -> int:
        return self.tiles_x * self.tiles_y


@dataclass
class Bins:
    """Result of binning. ``gaussian_ids [P]``: Gaussian of each sorted pair;
    ``tile_start, tile_end [num_tiles]``: each tile's range in that list (empty
    tiles have start == end); ``num_pairs`` P; `max_list_length` (computed on use): longest range.
    ``order [P]``: sorted position -> generation position; pairs are generated
    Gaussian by Gaussian (in depth order), those of Gaussian g at
    ``offsets[g] .. offsets[g] + counts[g]`` in ascending tile order, which is the fixed
    order the backward pass reduces per-pair gradients per Gaussian in.
    ``support_sq [N]``: each Gaussian's support radius^2 (`support_radius_sq`)."""

    grid: TileGrid
    gaussian_ids: object
    tile_start: object
    tile_end: object
    num_pairs: int
    order: object = None
    offsets: object = None
    counts: object = None
    box_pairs: int = 0  # tiles of the support boxes: the pairs the ellipse-tile test sees
    tiles: object = None  # [P] the tile of each sorted pair
    support_sq: object = None
    cutoff_box_pairs: int = 0  # tiles of the cutoff boxes (Projection.extents): before any culling

    @property
    def max_list_length(self) -> int:
        """The longest tile range (a host sync: only the test-only loop AD needs it)."""
        return int(dr.max(self.tile_end - self.tile_start)[0]) if self.num_pairs else 0


def support_radius_sq(cutoff_sq, opacities, alpha_min: float):
    """R^2 (Mahalanobis units, [N]) of the pixels the compositing loop can accept:
    q = 2 sigma <= cutoff_sq and opacity * exp(-sigma) >= alpha_min, i.e.
    q <= min(cutoff_sq, 2 ln(opacity / alpha_min)), widened by `LN_ABS_SLACK`."""
    o = dr.detach(opacities)
    level = 2.0 * dr.log(dr.maximum(o, 1e-38) / alpha_min) + LN_ABS_SLACK
    return dr.minimum(dr.detach(cutoff_sq), level)


def ellipse_meets_rect(dx0, dx1, dy0, dy1, conic_a, conic_b, conic_c, r2):
    """Whether q(dx, dy) = A dx^2 + 2B dx dy + C dy^2 <= r2 somewhere on the rectangle
    [dx0, dx1] x [dy0, dy1] (offsets of pixel centres from the mean; dx0 <= dx1, dy0 <= dy1).

    q is convex with its minimum 0 at the origin, so its minimum over the rectangle is 0
    when the rectangle holds the origin, and otherwise lies on an edge: on the edge
    dx = e, q(e, dy) is smallest at dy = -B e / C clamped to [dy0, dy1] (likewise for the
    edges dy = e). The minimum over the four edges is compared with r2 plus
    `Q_REL_SLACK` times the terms' magnitude, so float32 rounding can only keep a
    rectangle, never drop one the per-pixel test would accept. A, C > 0 (a conic of a
    positive definite covariance).
    """
    # Reciprocals: the same expression in every call, so one division per kernel. The
    # minimiser f is only ever off by rounding, which raises q by O(2^-48) relative
    # (q is quadratic around it), far inside the slack.
    inv_a, inv_c = 1.0 / conic_a, 1.0 / conic_c

    def edge_min(e, lo, hi, a_e, b, c_f, inv_c_f):  # min over f in [lo, hi] of a_e e^2 + 2 b e f + c_f f^2
        f = dr.clip(-b * e * inv_c_f, lo, hi)
        q = a_e * e * e + 2.0 * b * e * f + c_f * f * f
        scale = a_e * e * e + 2.0 * dr.abs(b * e * f) + c_f * f * f
        return q - Q_REL_SLACK * scale

    best = dr.minimum(
        dr.minimum(edge_min(dx0, dy0, dy1, conic_a, conic_b, conic_c, inv_c),
                   edge_min(dx1, dy0, dy1, conic_a, conic_b, conic_c, inv_c)),
        dr.minimum(edge_min(dy0, dx0, dx1, conic_c, conic_b, conic_a, inv_a),
                   edge_min(dy1, dx0, dx1, conic_c, conic_b, conic_a, inv_a)))
    holds_origin = (dx0 <= 0) & (dx1 >= 0) & (dy0 <= 0) & (dy1 >= 0)
    return holds_origin | (best <= r2)


def tile_pixel_offsets(grid: TileGrid, tx, ty, u, v, block: int | None = None, bx=0, by=0):
    """(dx0, dx1, dy0, dy1): offsets from the mean (u, v) of the first and last pixel
    centres of tile (tx, ty), or of its ``block`` x ``block`` sub-block (bx, by), clipped
    to the image (pixels past its edge do not exist)."""
    ts = grid.tile_size
    size = ts if block is None else block
    x_lo = tx * ts + bx * size
    y_lo = ty * ts + by * size
    x_hi = dr.minimum(x_lo + size, grid.width) - 1
    y_hi = dr.minimum(y_lo + size, grid.height) - 1
    Float = type(u)
    return (Float(x_lo) + 0.5 - u, Float(x_hi) + 0.5 - u, Float(y_lo) + 0.5 - v, Float(y_hi) + 0.5 - v)


def support_extents(conics, r2, cutoff_extents):
    """(rx, ry) [N]: half-extents in pixels of a box holding every pixel centre the
    compositing loop can accept.

    The support is q = (A dx^2 + 2B dx dy + C dy^2) <= r2 (``r2``: `support_radius_sq`);
    its exact bounding box has half-extents sqrt(r2 C / det), sqrt(r2 A / det) with
    det = AC - B^2 of the conic (A, B, C). Float32 rounding is bounded through the
    conic's conditioning, e = `Q_REL_SLACK` tr^2 / det (tr = A + C): the loop's sigma
    errs by at most Q_REL_SLACK s, s = 0.5 (A dx^2 + C dy^2) + |B dx dy|, and
    s <= 0.75 tr |d|^2 <= 1.5 sigma tr^2 / det (|B| <= tr / 2, sigma >= 0.5 (det / tr) |d|^2),
    so an accepted pixel (2 sigma_computed <= r2) has exact q <= r2 / (1 - 2e); det itself
    is off by less than e det. The box of r2 / (1 - 4e) holds both, and every tile that
    `ellipse_meets_rect` keeps (its slack stays below 1.5 e q). Where that widening is too
    large (e > `MAX_WIDENING`: an ill-conditioned conic) or det <= 0 in float32, the
    Gaussian keeps its cutoff box (``cutoff_extents``, `Projection.extents`) unchanged;
    the box never exceeds it.

    r2 < 0 (opacity below alpha_min) gives a box of zero size: the one tile holding the
    mean, which the ellipse test keeps when its pixel centres surround the mean. No pixel
    accepts such a Gaussian (sigma_computed >= sigma (1 - 2e) >= 0), so dropping that pair
    too would leave the image unchanged, but not the gradients' last bits: the lanes of a
    tile add into shared per-pair slots in (iteration, lane) order, and removing an entry
    from one lane's list shifts which of its adds come first.
    """
    a, b, c = dr.detach(conics.x), dr.detach(conics.y), dr.detach(conics.z)
    det = a * c - b * b
    tr = a + c
    well = det > 0
    e = dr.select(well, Q_REL_SLACK * tr * tr / dr.select(well, det, 1.0), 1.0)
    well &= e <= MAX_WIDENING
    r2_wide = dr.maximum(r2, 0.0) / (1.0 - 4.0 * dr.minimum(e, MAX_WIDENING))
    inv_det = 1.0 / dr.select(well, det, 1.0)
    rx_cut, ry_cut = dr.detach(cutoff_extents.x), dr.detach(cutoff_extents.y)
    rx = dr.select(well, dr.minimum(dr.sqrt(r2_wide * c * inv_det), rx_cut), rx_cut)
    ry = dr.select(well, dr.minimum(dr.sqrt(r2_wide * a * inv_det), ry_cut), ry_cut)
    return rx, ry


def tile_box(grid: TileGrid, u, v, rx, ry):
    """(x0, y0, span_x, span_y) [N] UInt32: the tiles [x0, x0 + span_x) x [y0, y0 + span_y)
    that the box [u - rx, u + rx] x [v - ry, v + ry] overlaps, clipped to the image
    (clipped in float before any integer conversion). A pixel centre lies 0.5 from every
    tile border, so the float rounding here never moves one out of the box."""
    m = array_namespace(u)
    UInt32 = m.UInt32
    ts = float(grid.tile_size)
    x0 = UInt32(dr.floor(dr.clip((u - rx) / ts, 0.0, grid.tiles_x)))
    x1 = UInt32(dr.floor(dr.clip((u + rx) / ts + 1.0, 0.0, grid.tiles_x)))
    y0 = UInt32(dr.floor(dr.clip((v - ry) / ts, 0.0, grid.tiles_y)))
    y1 = UInt32(dr.floor(dr.clip((v + ry) / ts + 1.0, 0.0, grid.tiles_y)))
    return x0, y0, dr.select(x1 > x0, x1 - x0, 0), dr.select(y1 > y0, y1 - y0, 0)


#: The widest single pass of `block_mkperm` over pair tiles on LLVM, where it is stable at
#: any bucket count (its histograms cost 4 bytes per bucket per block).
MAX_LLVM_TILE_PASS_BITS = 20


def radix_bits(m) -> int:
    """Digit width of a stable LSD radix pass, as Dr.Jit's own sort picks it: 11 bits on
    LLVM; 8 elsewhere, because on CUDA `dr.detail.block_mkperm` is stable only in its
    shared-memory "tiny" variant (up to 512 buckets), and an unstable pass would break
    the order the earlier passes made."""
    return 11 if m.__name__.startswith("drjit.llvm") else 8


def argsort_bits(key, bits: int, digit_bits: int | None = None):
    """``dr.argsort(key)`` for a UInt32 or UInt64 ``key`` [n] whose values are below 2^bits:
    the same stable LSD radix sort (`dr.detail.block_mkperm` over `radix_bits` digits, or
    ``digit_bits`` where the caller knows a wider pass is stable), but only over the digits
    that can be non-zero."""
    m = array_namespace(key)
    Key = type(key)
    n = dr.width(key)
    width = digit_bits or radix_bits(m)
    index = dr.arange(m.UInt32, n)
    shifts = list(range(0, max(bits, 1), width))
    for k, shift in enumerate(shifts):
        digit = m.UInt32((key >> shift) & Key((1 << width) - 1))
        dr.eval(digit, key)
        perm = dr.detail.block_mkperm(digit, n, 1 << width)
        if k + 1 < len(shifts):
            key = dr.gather(Key, key, perm)
        index = dr.gather(m.UInt32, index, perm) if k else perm
    return index


#: The most buckets `count_order` sorts by (a power of two): larger counts share the last one.
MAX_COUNT_BUCKETS = 1 << 16


def count_order(counts, block: int | None = None):
    """A permutation that puts ``counts`` [n] (UInt32) in ascending order within each run of
    ``block`` elements (None: the whole array), by one counting sort; counts past
    `MAX_COUNT_BUCKETS` - 1 count as that. Stable on LLVM; on CUDA `block_mkperm` is stable
    only up to 512 buckets (`radix_bits`). Used to give the lanes of a SIMD packet loops of
    about equal length: `reduction.reduce_pairs` (each lane's sum is its own, so any order
    gives the same sums) and `blocks.sort_lanes_by_length` (LLVM only, where the order of a
    tile's lanes is the order of their adds into a shared gradient slot: stable there)."""
    m = array_namespace(counts)
    n = dr.width(counts)
    if n == 0:
        return m.UInt32()
    buckets = min(1 << int(dr.max(counts)[0]).bit_length(), MAX_COUNT_BUCKETS)
    key = m.UInt32(dr.minimum(counts, buckets - 1))
    dr.eval(key)
    return dr.detail.block_mkperm(key, block or n, buckets)


def tile_order(m, tile, num_tiles: int):
    """Stable argsort of the pairs' tile ids [P] (< num_tiles): one counting sort on
    LLVM (one `block_mkperm` pass over every tile), 8-bit passes elsewhere."""
    bits = max(num_tiles - 1, 1).bit_length()
    llvm = m.__name__.startswith("drjit.llvm")
    return argsort_bits(tile, bits, bits if llvm and bits <= MAX_LLVM_TILE_PASS_BITS else None)


def _empty_bins(m, grid: TileGrid, n: int, r2, box_pairs: int, cutoff_box_pairs: int) -> Bins:
    zeros = dr.zeros(m.UInt32, grid.num_tiles)
    return Bins(grid, m.UInt32(), zeros, m.UInt32(zeros), 0, m.UInt32(), dr.zeros(m.UInt32, n),
                dr.zeros(m.UInt32, n), box_pairs, m.UInt32(), r2, cutoff_box_pairs)


def bin_gaussians(proj: Projection, camera, options: RasterOptions, timer=None) -> Bins:
    """Pair each visible Gaussian with the tiles of its support box (`support_extents`)
    that its support ellipse meets (`ellipse_meets_rect`), sorted by (tile, depth; ties by
    ascending Gaussian index, the reference's rule).

    ``proj``: the `Projection` of ``camera`` (a `splatbench.Camera`: its width and height
    make the `TileGrid`); ``options``: `RasterOptions`, of which binning reads tile_size and
    alpha_min. ``timer``: None, or a benchmark's `StageTimer`, marked "binning_cull" once the
    pairs are known (extents, expansion, ellipse test); the caller marks "binning_sort".
    """
    grid = TileGrid(camera.width, camera.height, options.tile_size)
    alpha_min = float(options.alpha_min)
    m = array_namespace(proj.depths)
    UInt32, Float = m.UInt32, m.Float
    u, v = dr.detach(proj.means2d.x), dr.detach(proj.means2d.y)
    n = dr.width(u)
    r2 = support_radius_sq(proj.cutoff_sq, proj.opacities, alpha_min)
    rx, ry = support_extents(proj.conics, r2, proj.extents)
    x0, y0, span_x, span_y = tile_box(grid, u, v, rx, ry)
    box_counts = dr.select(proj.visible, span_x * span_y, 0)
    _, _, cut_x, cut_y = tile_box(grid, u, v, dr.detach(proj.extents.x), dr.detach(proj.extents.y))
    cutoff_counts = dr.select(proj.visible, m.UInt64(cut_x * cut_y), 0)  # 64-bit: a count, never a size
    dr.eval(box_counts, x0, y0, span_x, r2, cutoff_counts)
    box_pairs = int(dr.sum(box_counts)[0]) if n else 0
    cutoff_box_pairs = int(dr.sum(cutoff_counts)[0]) if n else 0
    if box_pairs == 0:
        if timer is not None:
            timer.mark("binning_cull")
        return _empty_bins(m, grid, n, r2, 0, cutoff_box_pairs)

    # The Gaussians that get pairs, in depth order: positive float32 depths sort like their
    # bit patterns, and the stable sort keeps ascending index among equal depths. What the
    # expansion reads of them is laid out in that order, so its reads are sequential.
    active = dr.compress(box_counts > 0)
    depth_bits = dr.reinterpret_array(UInt32, dr.gather(Float, dr.detach(proj.depths), active))
    ranked = dr.gather(UInt32, active, argsort_bits(depth_bits, 32))  # Gaussian of each depth rank
    n_ranked = dr.width(ranked)
    # One record per Gaussian (F floats, integers by their bits), gathered in rank order
    # as one packet load each instead of F scattered reads.
    conic = proj.conics
    fields = (dr.reinterpret_array(Float, box_counts), dr.reinterpret_array(Float, x0),
              dr.reinterpret_array(Float, y0), dr.reinterpret_array(Float, span_x), u, v,
              dr.detach(conic.x), dr.detach(conic.y), dr.detach(conic.z), r2)
    F = len(fields)
    packed = dr.zeros(Float, F * n)
    for k, value in enumerate(fields):
        dr.scatter(packed, value, dr.arange(UInt32, n) * F + k, mode=dr.ReduceMode.Permute)
    dr.eval(packed)
    rec = dr.gather(m.ArrayXf, packed, ranked, shape=(F, n_ranked))
    r_counts, r_x0, r_y0, r_span_x = (dr.reinterpret_array(UInt32, rec[k]) for k in range(4))
    r_u, r_v, r_a, r_b, r_c, r_r2 = (rec[k] for k in range(4, F))
    rank_offsets = dr.prefix_sum(r_counts)  # exclusive
    dr.eval(ranked, rank_offsets, r_x0, r_y0, r_span_x, r_u, r_v, r_a, r_b, r_c, r_r2)
    del packed, rec

    # Every tile of every support box, rank by rank; then the ones the ellipse meets. The
    # rank of each box slot: its index marked where its run starts, then an inclusive
    # running maximum (what dr.repeat gives, without its log2(N)-step binary search).
    rank = dr.zeros(UInt32, box_pairs)
    dr.scatter(rank, dr.arange(UInt32, n_ranked), rank_offsets, mode=dr.ReduceMode.Permute)
    rank = dr.block_prefix_reduce(dr.ReduceOp.Max, rank, box_pairs, exclusive=False)
    local = dr.arange(UInt32, box_pairs) - dr.gather(UInt32, rank_offsets, rank)
    # Masked tail lanes of a SIMD packet read w = 0, and x86 integer division by
    # zero traps (SIGFPE): keep the divisor >= 1.
    w = dr.maximum(dr.gather(UInt32, r_span_x, rank), 1)
    row = local // w
    tx = dr.gather(UInt32, r_x0, rank) + (local - row * w)
    ty = dr.gather(UInt32, r_y0, rank) + row
    meets = ellipse_meets_rect(*tile_pixel_offsets(grid, tx, ty, dr.gather(Float, r_u, rank),
                                                   dr.gather(Float, r_v, rank)),
                               dr.gather(Float, r_a, rank), dr.gather(Float, r_b, rank), dr.gather(Float, r_c, rank),
                               dr.gather(Float, r_r2, rank))
    kept = dr.compress(meets)  # ascending: the kept pairs stay in depth-rank order
    num_pairs = dr.width(kept)
    if num_pairs == 0:
        if timer is not None:
            timer.mark("binning_cull")
        return _empty_bins(m, grid, n, r2, box_pairs, cutoff_box_pairs)
    rank = dr.gather(UInt32, rank, kept)
    tile = dr.gather(UInt32, ty, kept) * grid.tiles_x + dr.gather(UInt32, tx, kept)
    dr.eval(rank, tile)
    del kept, meets, tx, ty, row, w, local  # box-sized buffers: free them before the sort
    if timer is not None:
        timer.mark("binning_cull")

    # Per-Gaussian runs of the generated (depth-rank-major) order, for the reduction: the
    # ranks ascend along it, so a run starts where the rank changes (no atomics).
    idx, count = dr.arange(UInt32, num_pairs), dr.opaque(UInt32, num_pairs)
    gid = dr.gather(UInt32, ranked, rank)
    prev = dr.gather(UInt32, rank, idx - 1, idx > 0)
    nxt = dr.gather(UInt32, rank, idx + 1, idx + 1 < count)
    offsets = dr.zeros(UInt32, n)
    run_end = dr.zeros(UInt32, n)
    dr.scatter(offsets, idx, gid, (idx == 0) | (prev != rank))
    dr.scatter(run_end, idx + 1, gid, (idx + 1 == count) | (nxt != rank))
    counts = run_end - offsets
    dr.eval(gid, offsets, counts)
    # A stable sort by tile (one counting sort on LLVM): within a tile the pairs keep the
    # depth order they were generated in.
    order = tile_order(m, tile, grid.num_tiles)
    gaussian_ids = dr.gather(UInt32, gid, order)
    sorted_tile = dr.gather(UInt32, tile, order)
    dr.eval(order, gaussian_ids, sorted_tile)

    # Range of each tile: a pair starts a range where its tile differs from the previous one.
    # P enters the kernels as an opaque value: a literal would compile one kernel per pair count.
    prev = dr.gather(UInt32, sorted_tile, idx - 1, idx > 0)
    nxt = dr.gather(UInt32, sorted_tile, idx + 1, idx + 1 < count)
    first = (idx == 0) | (prev != sorted_tile)
    last = (idx + 1 == count) | (nxt != sorted_tile)
    tile_start = dr.zeros(UInt32, grid.num_tiles)
    tile_end = dr.zeros(UInt32, grid.num_tiles)
    dr.scatter(tile_start, idx, sorted_tile, first)
    dr.scatter(tile_end, idx + 1, sorted_tile, last)
    dr.eval(tile_start, tile_end)
    return Bins(grid, gaussian_ids, tile_start, tile_end, num_pairs, order, offsets, counts, box_pairs, sorted_tile,
                r2, cutoff_box_pairs)
