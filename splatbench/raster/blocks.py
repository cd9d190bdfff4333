"""Compositing lanes (`Lanes`, in tile order) and their per-block lists: each lane walks
only the pairs of its tile whose support ellipse meets the lane's B x B block of pixels
(B: `RasterOptions.pixel_block`, at most the tile size).

A tile's list holds every Gaussian whose ellipse meets some pixel of the tile, but a
small ellipse meets only a few of the tile's blocks. `block_lists` tests every
(pair, block) once with `binning.ellipse_meets_rect` (conservative: a dropped entry
is one every pixel of the block would skip) into a bit mask per pair; each lane then
walks its tile's range twice, counting and then writing the pairs with its bit set,
in depth order, so images and gradients are unchanged. Lane lists hold positions in the tile-sorted pair list
(``Lanes.pairs``): the Gaussian is ``gaussian_ids[p]`` and the backward pass
accumulates into pair slot ``p`` as before.
"""

from __future__ import annotations

from typing import NamedTuple

from splatbench.raster.device import dr, packet_width
from splatbench.raster.binning import Bins, TileGrid, count_order, ellipse_meets_rect, tile_pixel_offsets
from splatbench.raster.records import Records, load_records


class Lanes(NamedTuple):
    """Compositing lanes in tile order (within a tile wider than a SIMD packet, by list
    length: `sort_lanes_by_length`); each lane shades K = block^2 pixels.

    px, py, inside, image_index: lists of K arrays (pixel centres, whether the
    pixel exists, its row-major index); start, end: the lane's range in its list.
    lanes_per_tile: lanes that share one tile. pairs: None when each lane walks its
    tile's range of the sorted pairs; else the lanes' own lists (`block_lists`),
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


def make_lanes(m, grid: TileGrid, bins: Bins, pixel_block: int) -> Lanes:
    """The lanes in tile order, each a ``pixel_block`` x ``pixel_block`` block (at most
    the tile: `RasterOptions` refuses a larger one), walking its tile's whole range of the
    sorted pairs."""
    ts = grid.tile_size
    block = pixel_block
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


def lanes_for(m, rec: Records, bins: Bins, pixel_block: int) -> Lanes:
    """The compositing lanes with their per-block lists (`block_lists`); ``pixel_block``:
    the side of a lane's block (`RasterOptions.pixel_block`, a power of two, at most the
    tile size). Each lane shades its block's pixels: one load of a record serves
    them all, and their gradient terms are summed in registers before a scatter (4x4:
    one 16-lane AVX-512 packet per 16x16 tile; docs/benchmarks.md measures the others)."""
    lanes = make_lanes(m, bins.grid, bins, pixel_block)
    if bins.num_pairs == 0:
        return lanes
    return block_lists(m, rec, bins, lanes)


def block_masks(m, rec: Records, bins: Bins, block: int) -> list:
    """Words of [P] UInt32: bit b % 32 of word b // 32 is set when pair p's ellipse
    meets block b of its tile (blocks row-major, as `make_lanes` orders a
    tile's lanes); blocks wholly outside the image never get a bit."""
    grid = bins.grid
    side = grid.tile_size // block
    geo, _ = load_records(m, rec, bins.gaussian_ids)
    r2 = dr.gather(m.Float, bins.support_sq, bins.gaussian_ids)  # binning's, computed once
    tx, ty = bins.tiles % grid.tiles_x, bins.tiles // grid.tiles_x
    words = [dr.zeros(m.UInt32, bins.num_pairs) for _ in range(-(-side * side // 32))]
    for b in range(side * side):
        bx, by = b % side, b // side
        x_lo = tx * grid.tile_size + bx * block
        y_lo = ty * grid.tile_size + by * block
        exists = (x_lo < grid.width) & (y_lo < grid.height)
        hit = exists & ellipse_meets_rect(*tile_pixel_offsets(grid, tx, ty, geo.u, geo.v, block, bx, by),
                                         geo.conic_a, geo.conic_b, geo.conic_c, r2)
        words[b // 32] |= dr.select(hit, m.UInt32(1 << (b % 32)), m.UInt32(0))
    return words


def block_lists(m, rec: Records, bins: Bins, lanes):
    """`Lanes` whose [start, end) index their own list ``pairs`` (UInt32 sorted pair
    positions, depth order) instead of the tile's range.

    Where a tile has more lanes than a SIMD packet (LLVM, e.g. tile_size 32 or 2x2 blocks:
    64 lanes in four 16-lane packets), a tile's lanes are sorted by the length of their lists
    (`sort_lanes_by_length`) first, so each packet holds lanes of similar lengths and
    waits less for its longest one. Lanes never leave their tile's packets, which the
    deterministic gradient reduction needs (`reduction.lane_group`); a tile of one packet
    keeps make_lanes' order.

    ``rec``: the packed `Records` of the Gaussians.
    """
    UInt32 = m.UInt32
    L = lanes.lanes_per_tile
    block = bins.grid.tile_size // int(round(L ** 0.5))
    words = block_masks(m, rec, bins, block)
    dr.eval(words)
    lane_block = dr.arange(UInt32, dr.width(lanes.start)) % L  # lane = tile * L + block, make_lanes' order

    def hit(i, lane_block):
        """Whether entry i of the tile's range has the bit of the lane's block."""
        word_of, shift = lane_block // 32, lane_block % 32
        word = dr.gather(UInt32, words[0], i)
        for k in range(1, len(words)):
            word = dr.select(word_of == k, dr.gather(UInt32, words[k], i), word)
        return ((word >> shift) & 1) == 1

    # Pass 1: each lane walks its tile's range and counts its entries (lanes with no
    # pixel in the image have an empty range, make_lanes' rule, so they count none).
    def count_body(i, n):
        return i + 1, n + dr.select(hit(i, lane_block), 1, 0)

    zero = dr.zeros(UInt32, dr.width(lanes.start))
    _, counts = dr.while_loop((UInt32(lanes.start), zero), lambda i, n: i < lanes.end, count_body,
                              mode="symbolic")
    dr.eval(counts)
    if 1 < packet_width(m) < L:
        lanes, counts, lane_block = sort_lanes_by_length(m, lanes, counts, lane_block)
    starts = dr.prefix_sum(counts)  # exclusive
    total = int(dr.sum(counts)[0])
    pairs = dr.zeros(UInt32, max(total, 1))

    # Pass 2: the same walk writes each entry in depth order.
    def fill_body(i, pos):
        h = hit(i, lane_block)
        dr.scatter(pairs, i, pos, h)
        return i + 1, pos + dr.select(h, 1, 0)

    dr.while_loop((UInt32(lanes.start), UInt32(starts)), lambda i, pos: i < lanes.end, fill_body, mode="symbolic")
    end = starts + counts
    dr.eval(pairs, end)
    return lanes._replace(start=starts, end=end, pairs=pairs)


def sort_lanes_by_length(m, lanes: Lanes, counts, lane_block):
    """(lanes, counts, lane_block) with each tile's lanes in ascending order of their list
    length (stable, `binning.count_order`): a permutation within each tile's run of lanes,
    carrying every per-lane array with it."""
    UInt32 = m.UInt32
    perm = count_order(counts, lanes.lanes_per_tile)

    def permuted(values):
        return [dr.gather(type(v), v, perm) for v in values]

    moved = lanes._replace(px=permuted(lanes.px), py=permuted(lanes.py), inside=permuted(lanes.inside),
                           image_index=permuted(lanes.image_index), start=dr.gather(UInt32, lanes.start, perm),
                           end=dr.gather(UInt32, lanes.end, perm))
    counts, lane_block = dr.gather(UInt32, counts, perm), dr.gather(UInt32, lane_block, perm)
    dr.eval(moved.px, moved.py, moved.inside, moved.image_index, moved.start, moved.end, counts, lane_block)
    return moved, counts, lane_block
