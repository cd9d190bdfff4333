"""The binning as it was before the support boxes and the counting sort (9af4c7d), kept
here only as the tests' reference: every tile of each Gaussian's cutoff box (3 sigma)
that `ellipse_meets_rect` keeps, sorted by one (tile, depth) 64-bit key. The rasterizer's
`bin_gaussians` must give bit-identical images and gradients
(tests/test_raster_binning.py)."""

from __future__ import annotations

from splatbench.raster.binning import Bins, TileGrid, ellipse_meets_rect, support_radius_sq, tile_pixel_offsets
from splatbench.raster.device import dr
from splatbench.raster.options import RasterOptions
from splatbench.raster.projection import Projection, array_namespace


def argsort_key(key, bits: int, radix_bits: int = 11):
    """Stable LSD radix argsort of a UInt64 ``key`` whose values are below 2^bits."""
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


def bin_gaussians_3sigma(proj: Projection, camera, options: RasterOptions, timer=None) -> Bins:
    """Assign each visible Gaussian to the tiles of its cutoff box that its support
    ellipse (`support_radius_sq`) meets, sorted by (tile, depth)."""
    grid = TileGrid(camera.width, camera.height, options.tile_size)
    alpha_min = float(options.alpha_min)
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
                 UInt32(), dr.zeros(UInt32, n), dr.zeros(UInt32, n), box_pairs, UInt32(), r2, box_pairs)
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
    order = argsort_key(key, 32 + max(grid.num_tiles - 1, 1).bit_length())
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
    return Bins(grid, gaussian_ids, tile_start, tile_end, num_pairs, order, offsets, counts, box_pairs, sorted_tile, r2,
                box_pairs)
