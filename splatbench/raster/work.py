"""How much work compositing does, and how much of it can change a pixel.

`work_stats` counts, for one view, the pixel-Gaussian evaluations of one
compositing pass and the ones inside each Gaussian's support. The counts are
deterministic (no timing), so they are evidence on any machine; docs/benchmarks.md
explains how `splatbench bench raster` turns them into a share of the FP32 peak.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from splatbench.raster.api import to_tensor
from splatbench.raster.device import dr, get_device, packet_width
# The rasterizer's own stages, lanes, lists, per-pixel test and record loads, so that
# the counts are of exactly the decisions compositing makes.
from splatbench.raster.binning import bin_gaussians
from splatbench.raster.blocks import lanes_for, pair_at
from splatbench.raster.compositing import CompositeSettings, _alpha_at, _half_mahalanobis, splat_records
from splatbench.raster.options import RasterOptions
from splatbench.raster.pipeline import check_options
from splatbench.raster.projection import project
from splatbench.raster.records import load_records


@dataclass(frozen=True)
class WorkStats:
    """Work of one compositing pass over one view (counts; early termination ignored).

    cutoff_box_pairs: Gaussian-tile pairs of the cutoff bounding boxes (`Projection.extents`),
    i.e. before any culling; cutoff_evaluations: cutoff_box_pairs x tile_size^2, what
    compositing would evaluate without culling; box_pairs: pairs of the support boxes
    (`binning.support_extents`), what binning's ellipse-tile test sees; pairs: the
    Gaussian-tile pairs kept; tile_evaluations: pairs x tile_size^2, what compositing would
    evaluate if every lane walked its whole tile list; block_evaluations: the sum over lanes
    of B^2 x the length of the lane's own list (`blocks.block_lists`; B x B: the lane's pixel
    block, `RasterOptions.pixel_block`, at most the tile), i.e. (block, Gaussian) pairs whose
    block meets the support, x B^2; performed: pixel-Gaussian evaluations compositing does, per
    SIMD packet its lanes x B^2 x the longest of their lists (a packet runs until its longest list ends; on LLVM a packet is
    min(lanes per tile, packet width) lanes of one tile, elsewhere counted as a whole tile);
    inside_cutoff: (pixel, Gaussian) evaluations with the pixel centre inside the cutoff
    ellipse, q = 2 sigma <= R^2; useful: those that also pass alpha >= alpha_min, i.e. the
    Gaussian's support, where it can change the pixel.
    """

    cutoff_box_pairs: int
    cutoff_evaluations: int
    box_pairs: int
    pairs: int
    tile_evaluations: int
    block_evaluations: int
    performed: int
    inside_cutoff: int
    useful: int

    @property
    def useful_share(self) -> float:
        """useful / performed (0 when nothing is performed)."""
        return self.useful / self.performed if self.performed else 0.0


def work_stats(gaussians, camera, options: RasterOptions | None = None) -> WorkStats:
    """Count the compositing work of rendering ``gaussians`` from ``camera``.

    Args:
        gaussians: `splatbench.Gaussians` [N]. camera: `splatbench.Camera` (W x H).
        options: the rasterizer's `RasterOptions`, as for `splatbench.render` (None: the defaults).

    Returns:
        `WorkStats` (integers).
    """
    opts = check_options(options)
    m = get_device(opts.device).t
    if len(gaussians) == 0:
        return WorkStats(0, 0, 0, 0, 0, 0, 0, 0, 0)
    with dr.suspend_grad():
        proj = project(to_tensor(m, gaussians.means), to_tensor(m, gaussians.log_scales),
                       to_tensor(m, gaussians.quats), to_tensor(m, gaussians.opacity_logits), camera, opts)
        bins = bin_gaussians(proj, camera, opts)
        area = opts.tile_size ** 2
        if bins.num_pairs == 0:
            return WorkStats(bins.cutoff_box_pairs, bins.cutoff_box_pairs * area, bins.box_pairs, 0, 0, 0, 0, 0, 0)
        counts = _count(m, splat_records(proj), bins, CompositeSettings.from_options(opts))
    return WorkStats(bins.cutoff_box_pairs, bins.cutoff_box_pairs * area, bins.box_pairs, bins.num_pairs,
                     bins.num_pairs * area, *counts)


def _count(m, records, bins, cfg: CompositeSettings) -> tuple[int, int, int, int]:
    """(block_evaluations, performed, inside_cutoff, useful), walking the lanes' own lists."""
    UInt32 = m.UInt32
    lanes = lanes_for(m, records, bins, cfg.pixel_block)
    K = len(lanes.px)
    # The lanes that run together: a SIMD packet of one tile on LLVM, else a whole tile.
    width = packet_width(m)
    packet = min(lanes.lanes_per_tile, width) if width > 1 else lanes.lanes_per_tile

    def body(i, inside, useful):
        geo, _ = load_records(m, records, dr.gather(UInt32, bins.gaussian_ids, pair_at(m, lanes, i)))
        for k in range(K):
            _, contributes, dx, dy, _, _ = _alpha_at(geo, lanes.px[k], lanes.py[k], cfg, lanes.inside[k])
            sigma = _half_mahalanobis(geo.conic_a, geo.conic_b, geo.conic_c, dx, dy)
            inside = inside + dr.select(lanes.inside[k] & (sigma <= 0.5 * geo.cutoff_sq), 1, 0)
            useful = useful + dr.select(contributes, 1, 0)
        return i + 1, inside, useful

    zero = dr.zeros(UInt32, dr.width(lanes.start))
    _, inside, useful = dr.while_loop((UInt32(lanes.start), zero, UInt32(zero)), lambda i, *_: i < lanes.end, body,
                                      mode="symbolic")
    length = lanes.end - lanes.start
    longest = dr.block_reduce(dr.ReduceOp.Max, length, packet)  # per SIMD packet

    def total(x, scale: int) -> int:
        return int(np.sum(x.numpy(), dtype=np.int64)) * scale

    return (total(length, K), total(longest, packet * K), total(inside, 1), total(useful, 1))
