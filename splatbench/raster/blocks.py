"""Per-block lists: each compositing lane walks only the pairs of its tile whose
support ellipse meets the lane's PIXEL_BLOCK x PIXEL_BLOCK block of pixels.

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

from splatbench.raster.device import dr
from splatbench.raster.binning import Bins, ellipse_meets_rect, support_radius_sq, tile_pixel_offsets


def block_masks(m, rec, bins: Bins, block: int, alpha_min: float, load) -> list:
    """Words of [P] UInt32: bit b % 32 of word b // 32 is set when pair p's ellipse
    meets block b of its tile (blocks row-major, as `compositing.make_lanes` orders a
    tile's lanes); blocks wholly outside the image never get a bit."""
    grid = bins.grid
    side = grid.tile_size // block
    geo, _ = load(rec, bins.gaussian_ids)
    u, v, ca, cb, cc, opacity, _, cutoff = geo
    r2 = support_radius_sq(cutoff, opacity, alpha_min)
    tx, ty = bins.tiles % grid.tiles_x, bins.tiles // grid.tiles_x
    words = [dr.zeros(m.UInt32, bins.num_pairs) for _ in range(-(-side * side // 32))]
    for b in range(side * side):
        bx, by = b % side, b // side
        x_lo = tx * grid.tile_size + bx * block
        y_lo = ty * grid.tile_size + by * block
        exists = (x_lo < grid.width) & (y_lo < grid.height)
        hit = exists & ellipse_meets_rect(*tile_pixel_offsets(grid, tx, ty, u, v, block, bx, by), ca, cb, cc, r2)
        words[b // 32] |= dr.select(hit, m.UInt32(1 << (b % 32)), m.UInt32(0))
    return words


def block_lists(m, rec, bins: Bins, lanes, alpha_min: float, load):
    """`Lanes` whose [start, end) index their own list ``pairs`` (UInt32 sorted pair
    positions, depth order) instead of the tile's range.

    ``rec``: packed `Records`; ``load(rec, gid)``: the compositing loop's record load.
    """
    UInt32 = m.UInt32
    L = lanes.lanes_per_tile
    block = bins.grid.tile_size // int(round(L ** 0.5))
    words = block_masks(m, rec, bins, block, alpha_min, load)
    dr.eval(words)
    # Which bit of which word each lane reads (lane = tile * L + b).
    b = dr.arange(UInt32, dr.width(lanes.start)) % L
    word_of, shift = b // 32, b % 32

    def hit(i):
        word = dr.gather(UInt32, words[0], i)
        for k in range(1, len(words)):
            word = dr.select(word_of == k, dr.gather(UInt32, words[k], i), word)
        return ((word >> shift) & 1) == 1

    # Pass 1: each lane walks its tile's range and counts its entries (lanes with no
    # pixel in the image have an empty range, make_lanes' rule, so they count none).
    def count_body(i, n):
        return i + 1, n + dr.select(hit(i), 1, 0)

    zero = dr.zeros(UInt32, dr.width(lanes.start))
    _, counts = dr.while_loop((UInt32(lanes.start), zero), lambda i, n: i < lanes.end, count_body,
                              mode="symbolic")
    dr.eval(counts)
    starts = dr.prefix_sum(counts)  # exclusive
    total = int(dr.sum(counts)[0])
    pairs = dr.zeros(UInt32, max(total, 1))

    # Pass 2: the same walk writes each entry in depth order.
    def fill_body(i, pos):
        h = hit(i)
        dr.scatter(pairs, i, pos, h)
        return i + 1, pos + dr.select(h, 1, 0)

    dr.while_loop((UInt32(lanes.start), UInt32(starts)), lambda i, pos: i < lanes.end, fill_body, mode="symbolic")
    end = starts + counts
    dr.eval(pairs, end)
    return lanes._replace(start=starts, end=end, pairs=pairs)
