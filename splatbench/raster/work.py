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
from splatbench.raster.backend import dr, get_backend
from splatbench.raster.binning import TileGrid, bin_gaussians, ellipse_meets_rect, support_radius_sq
# The compositing loop's own per-pixel test and record loads, so that the counts are
# of exactly the decisions it makes.
from splatbench.raster.compositing import CompositeSettings, Splats, _alpha_at, _load, make_lanes, pack_records
from splatbench.raster.options import RasterOptions
from splatbench.raster.pipeline import project_view


@dataclass(frozen=True)
class WorkStats:
    """Work of one compositing pass over one view (counts; early termination ignored).

    box_pairs: Gaussian-tile pairs of the cutoff bounding boxes (the binning before the
    ellipse-tile test); pairs: the pairs compositing walks; performed: pixel-Gaussian
    evaluations, pairs x tile_size^2 (the lanes of a tile walk its list in lock-step, so
    every pixel of the tile evaluates every pair; pixels stopped by transmittance still
    occupy their SIMD lane); block_evaluations: 16 x the (4x4 block, Gaussian) pairs
    whose block meets the support, the work a per-block skip would leave;
    inside_cutoff: (pixel, Gaussian) evaluations with the pixel centre inside the cutoff
    ellipse, q = 2 sigma <= R^2; useful: those that also pass alpha >= alpha_min, i.e.
    the Gaussian's support, where it can change the pixel.
    """

    box_pairs: int
    pairs: int
    performed: int
    block_evaluations: int
    inside_cutoff: int
    useful: int

    @property
    def useful_share(self) -> float:
        """useful / performed (0 when nothing is performed)."""
        return self.useful / self.performed if self.performed else 0.0


def work_stats(gaussians, camera, **options) -> WorkStats:
    """Count the compositing work of rendering ``gaussians`` from ``camera``.

    Args:
        gaussians: `splatbench.Gaussians` [N]. camera: `splatbench.Camera` (W x H).
        **options: `RasterOptions` fields, as for `splatbench.render`.

    Returns:
        `WorkStats` (integers).
    """
    opts = RasterOptions.from_kwargs(**options)
    m = get_backend(opts.device).t
    if len(gaussians) == 0:
        return WorkStats(0, 0, 0, 0, 0, 0)
    with dr.suspend_grad():
        proj = project_view(to_tensor(m, gaussians.means), to_tensor(m, gaussians.log_scales),
                            to_tensor(m, gaussians.quats), to_tensor(m, gaussians.opacity_logits), camera, opts)
        grid = TileGrid(camera.width, camera.height, opts.tile_size)
        bins = bin_gaussians(proj, grid, opts.alpha_min)
        if bins.num_pairs == 0:
            return WorkStats(bins.box_pairs, 0, 0, 0, 0, 0)
        zero = dr.zeros(m.Array3f, dr.width(proj.depths))
        records = pack_records(m, Splats(proj.means2d, proj.conics, proj.opacities, zero, proj.depths,
                                         proj.cutoff_sq))
        counts = _count(m, records, bins, grid, CompositeSettings(opts.alpha_min, opts.alpha_max,
                                                                   opts.transmittance_min, (0.0, 0.0, 0.0)))
    return WorkStats(bins.box_pairs, bins.num_pairs, bins.num_pairs * opts.tile_size ** 2, *counts)


def _count(m, records, bins, grid: TileGrid, cfg: CompositeSettings) -> tuple[int, int, int]:
    """(block_evaluations, inside_cutoff, useful) over every lane's tile list."""
    UInt32 = m.UInt32
    lanes = make_lanes(m, grid, bins)
    K = len(lanes.px)
    block = int(round(K ** 0.5))
    # Block rectangle of pixel centres, clipped to the image (lanes past it have no pixels).
    bx0, by0 = lanes.px[0], lanes.py[0]
    bx1 = dr.minimum(lanes.px[block - 1], grid.width - 0.5)
    by1 = dr.minimum(lanes.py[K - 1], grid.height - 0.5)

    def body(i, blocks, inside, useful):
        geo, _ = _load(m, records, dr.gather(UInt32, bins.gaussian_ids, i))
        u, v, ca, cb, cc, opacity, _, cutoff = geo
        r2 = support_radius_sq(cutoff, opacity, cfg.alpha_min)
        meets = ellipse_meets_rect(bx0 - u, bx1 - u, by0 - v, by1 - v, ca, cb, cc, r2)
        blocks = blocks + dr.select(meets, K, 0)
        for k in range(K):
            _, contributes, dx, dy, _, _ = _alpha_at(geo, lanes.px[k], lanes.py[k], cfg, lanes.inside[k])
            sigma = 0.5 * (ca * dx * dx + cc * dy * dy) + cb * dx * dy
            inside = inside + dr.select(lanes.inside[k] & (sigma <= 0.5 * cutoff), 1, 0)
            useful = useful + dr.select(contributes, 1, 0)
        return i + 1, blocks, inside, useful

    zero = dr.zeros(UInt32, dr.width(lanes.start))
    _, *totals = dr.while_loop((UInt32(lanes.start), zero, UInt32(zero), UInt32(zero)),
                               lambda i, *_: i < lanes.end, body, mode="symbolic")
    return tuple(int(np.sum(t.numpy(), dtype=np.int64)) for t in totals)
