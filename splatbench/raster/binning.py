"""Tile binning: expand Gaussian-tile pairs, sort by (tile, depth), find tile ranges.

Only visible Gaussians produce pairs, so empty tiles have an empty range and cost
nothing in compositing. No gradients flow through binning.
"""

from __future__ import annotations

from dataclasses import dataclass

from splatbench.raster.backend import dr
from splatbench.raster.projection import Projection, array_namespace


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

    @property
    def num_lanes(self) -> int:
        return self.num_tiles * self.tile_size * self.tile_size


@dataclass
class Bins:
    """Result of binning. ``gaussian_ids [P]``: Gaussian of each sorted pair;
    ``tile_start, tile_end [num_tiles]``: each tile's range in that list (empty
    tiles have start == end); ``num_pairs`` P; ``max_list_length``: longest range.
    ``order [P]``: sorted position -> Gaussian-major position (pairs of Gaussian g
    occupy ``offsets[g] .. offsets[g] + counts[g]`` there), used to reduce per-pair
    gradients per Gaussian in a fixed order."""

    grid: TileGrid
    gaussian_ids: object
    tile_start: object
    tile_end: object
    num_pairs: int
    max_list_length: int
    order: object = None
    offsets: object = None
    counts: object = None


def bin_gaussians(proj: Projection, grid: TileGrid) -> Bins:
    """Assign each visible Gaussian to the tiles its cutoff box touches, sorted by depth."""
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
    counts = dr.select(proj.visible, span_x * span_y, 0)
    dr.eval(counts, x0, y0, span_x)

    num_pairs = int(dr.sum(counts)[0]) if dr.width(counts) else 0
    if num_pairs == 0:
        zeros = dr.zeros(UInt32, grid.num_tiles)
        return Bins(grid, UInt32(), zeros, zeros, 0, 0, UInt32(), dr.zeros(UInt32, dr.width(counts)), counts)

    offsets = dr.prefix_sum(counts)  # exclusive
    n = dr.width(counts)
    gid = dr.repeat(dr.arange(UInt32, n), counts)  # the Gaussian of each pair
    local = dr.arange(UInt32, num_pairs) - dr.gather(UInt32, offsets, gid)
    # Masked tail lanes of a SIMD packet read w = 0, and x86 integer division by
    # zero traps (SIGFPE): keep the divisor >= 1.
    w = dr.maximum(dr.gather(UInt32, span_x, gid), 1)
    row = local // w
    tile = ((dr.gather(UInt32, y0, gid) + row) * grid.tiles_x
            + dr.gather(UInt32, x0, gid) + (local - row * w))
    # Positive float32 depths sort like their bit patterns; the sort is stable, so
    # equal depths keep ascending Gaussian order (the reference's tie rule).
    depth_bits = dr.reinterpret_array(UInt32, dr.gather(Float, dr.detach(proj.depths), gid))
    key = (UInt64(tile) << 32) | UInt64(depth_bits)
    order = dr.argsort(key)
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
    max_len = int(dr.max(tile_end - tile_start)[0])
    return Bins(grid, gaussian_ids, tile_start, tile_end, num_pairs, max_len, order, offsets, counts)
