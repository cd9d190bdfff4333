"""Tile binning: expand Gaussian-tile pairs, sort by (tile, depth), find tile ranges.

Only visible Gaussians produce pairs, so empty tiles have an empty range and cost
nothing in compositing. A tile of the Gaussian's bounding box gets a pair only when
some pixel centre of the tile can pass the compositing loop's per-pixel test
(`ellipse_meets_rect`): a pair every pixel would skip changes no output, so dropping
it only removes work. No gradients flow through binning.
"""

from __future__ import annotations

from dataclasses import dataclass

from splatbench.raster.device import dr
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
    ``order [P]``: sorted position -> Gaussian-major position (pairs of Gaussian g
    occupy ``offsets[g] .. offsets[g] + counts[g]`` there), used to reduce per-pair
    gradients per Gaussian in a fixed order."""

    grid: TileGrid
    gaussian_ids: object
    tile_start: object
    tile_end: object
    num_pairs: int
    order: object = None
    offsets: object = None
    counts: object = None
    box_pairs: int = 0  # pairs of the bounding boxes alone, before the ellipse-tile test
    tiles: object = None  # [P] the tile of each sorted pair

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


def argsort_bits(key, bits: int, radix_bits: int = 11):
    """``dr.argsort(key)`` for a UInt64 ``key`` [P] whose values are below 2^bits: the same
    stable LSD radix sort (`dr.detail.block_mkperm`, 11-bit digits as Dr.Jit's own sort uses
    on the CPU), but only over the digits that can be non-zero. The (tile, depth) keys need
    32 + log2(tiles) bits: 4 passes instead of the 6 a full 64-bit sort makes."""
    m = array_namespace(key)
    n = dr.width(key)
    index = dr.arange(m.UInt32, n)
    for shift in range(0, bits, radix_bits):
        digit = m.UInt32((key >> shift) & m.UInt64((1 << radix_bits) - 1))
        dr.eval(digit, key)
        perm = dr.detail.block_mkperm(digit, n, 1 << radix_bits)
        key = dr.gather(m.UInt64, key, perm)
        index = dr.gather(m.UInt32, index, perm)
    return index


def bin_gaussians(proj: Projection, grid: TileGrid, alpha_min: float) -> Bins:
    """Assign each visible Gaussian to the tiles of its cutoff box that its support
    ellipse (`support_radius_sq`) meets, sorted by (tile, depth)."""
    m = array_namespace(proj.depths)
    UInt32, UInt64, Float = m.UInt32, m.UInt64, m.Float
    ts = float(grid.tile_size)
    u, v = dr.detach(proj.means2d.x), dr.detach(proj.means2d.y)
    rx, ry = proj.extents.x, proj.extents.y
    # Tile rectangle [x0, x1) x [y0, y1), clipped in float before any integer conversion.
    x0 = UInt32(dr.floor(dr.clip((u - rx) / ts, 0.0, grid.tiles_x)))
    x1 = UInt32(dr.floor(dr.clip((u + rx) / ts + 1.0, 0.0, grid.tiles_x)))
    y0 = UInt32(dr.floor(dr.clip((v - ry) / ts, 0.0, grid.tiles_y)))
    y1 = UInt32(dr.floor(dr.clip((v + ry) / ts + 1.0, 0.0, grid.tiles_y)))
    span_x = dr.select(x1 > x0, x1 - x0, 0)
    span_y = dr.select(y1 > y0, y1 - y0, 0)
    box_counts = dr.select(proj.visible, span_x * span_y, 0)
    r2 = support_radius_sq(proj.cutoff_sq, proj.opacities, alpha_min)
    dr.eval(box_counts, x0, y0, span_x, r2)

    box_pairs = int(dr.sum(box_counts)[0]) if dr.width(box_counts) else 0
    n = dr.width(box_counts)
    empty = Bins(grid, UInt32(), dr.zeros(UInt32, grid.num_tiles), dr.zeros(UInt32, grid.num_tiles), 0,
                 UInt32(), dr.zeros(UInt32, n), dr.zeros(UInt32, n), box_pairs)
    if box_pairs == 0:
        return empty

    # Every tile of every bounding box (Gaussian-major), then the ones the ellipse meets.
    box_offsets = dr.prefix_sum(box_counts)  # exclusive
    # Gaussian of each box slot: its index marked where its run starts, then an inclusive
    # running maximum (what dr.repeat gives, without its log2(N)-step binary search).
    gid = dr.zeros(UInt32, box_pairs)
    dr.scatter(gid, dr.arange(UInt32, n), box_offsets, box_counts > 0, mode=dr.ReduceMode.Permute)
    gid = dr.block_prefix_reduce(dr.ReduceOp.Max, gid, box_pairs, exclusive=False)
    local = dr.arange(UInt32, box_pairs) - dr.gather(UInt32, box_offsets, gid)
    # Masked tail lanes of a SIMD packet read w = 0, and x86 integer division by
    # zero traps (SIGFPE): keep the divisor >= 1.
    w = dr.maximum(dr.gather(UInt32, span_x, gid), 1)
    row = local // w
    tx = dr.gather(UInt32, x0, gid) + (local - row * w)
    ty = dr.gather(UInt32, y0, gid) + row
    conic = proj.conics
    meets = ellipse_meets_rect(*tile_pixel_offsets(grid, tx, ty, dr.gather(Float, u, gid), dr.gather(Float, v, gid)),
                               dr.gather(Float, dr.detach(conic.x), gid), dr.gather(Float, dr.detach(conic.y), gid),
                               dr.gather(Float, dr.detach(conic.z), gid), dr.gather(Float, r2, gid))
    kept = dr.compress(meets)  # ascending: the kept pairs stay Gaussian-major
    num_pairs = dr.width(kept)
    if num_pairs == 0:
        return empty
    gid = dr.gather(UInt32, gid, kept)
    tile = dr.gather(UInt32, ty, kept) * grid.tiles_x + dr.gather(UInt32, tx, kept)
    dr.eval(gid, tile)
    del kept, meets, tx, ty, row, w, local, box_offsets  # box-sized buffers: free them before the sort
    counts = dr.zeros(UInt32, n)
    dr.scatter_add(counts, dr.full(UInt32, 1, num_pairs), gid)  # integer adds: order-free
    offsets = dr.prefix_sum(counts)
    dr.eval(gid, tile, counts, offsets)

    # Positive float32 depths sort like their bit patterns; the sort is stable, so
    # equal depths keep ascending Gaussian order (the reference's tie rule).
    depth_bits = dr.reinterpret_array(UInt32, dr.gather(Float, dr.detach(proj.depths), gid))
    key = (UInt64(tile) << 32) | UInt64(depth_bits)
    order = argsort_bits(key, 32 + max(grid.num_tiles - 1, 1).bit_length())
    gaussian_ids = dr.gather(UInt32, gid, order)
    sorted_tile = dr.gather(UInt32, tile, order)

    # Range of each tile: a pair starts a range where its tile differs from the previous one.
    # P enters the kernel as an opaque value: a literal would compile one kernel per pair count.
    idx, count = dr.arange(UInt32, num_pairs), dr.opaque(UInt32, num_pairs)
    prev = dr.gather(UInt32, sorted_tile, idx - 1, idx > 0)
    nxt = dr.gather(UInt32, sorted_tile, idx + 1, idx + 1 < count)
    first = (idx == 0) | (prev != sorted_tile)
    last = (idx + 1 == count) | (nxt != sorted_tile)
    tile_start = dr.zeros(UInt32, grid.num_tiles)
    tile_end = dr.zeros(UInt32, grid.num_tiles)
    dr.scatter(tile_start, idx, sorted_tile, first)
    dr.scatter(tile_end, idx + 1, sorted_tile, last)
    dr.eval(gaussian_ids, tile_start, tile_end)
    return Bins(grid, gaussian_ids, tile_start, tile_end, num_pairs, order, offsets, counts, box_pairs, sorted_tile)
