"""Work counting and the ellipse-tile test of binning.

The tile test may only drop pairs whose every pixel the compositing loop would skip.
It is checked against a dense evaluation of the loop's own per-pixel test
(`compositing._alpha_at`, the same float32 expression) at every pixel of the image
for every Gaussian: the useful evaluations counted through the binned lists must
equal the dense count exactly, with no tolerance (a dropped tile that holds one
accepted pixel makes them differ).
"""

from __future__ import annotations

import numpy as np
import pytest

import splatbench
from splatbench import Camera, Gaussians
from splatbench.raster.api import to_tensor
from splatbench.raster.device import dr, get_device
from splatbench.raster.compositing import CompositeSettings, _alpha_at
from splatbench.raster.options import RasterOptions
from splatbench.raster.records import GeoRecord
from splatbench.raster.projection import project
from splatbench.raster.work import work_stats
from splatbench.workloads import synthetic


def elongated_scene(n: int, seed: int) -> tuple[Gaussians, Camera]:
    """Thin, rotated Gaussians of mixed opacity: bounding boxes much larger than the ellipses."""
    rng = np.random.default_rng(seed)
    means = np.c_[rng.uniform(-1.2, 1.2, (n, 2)), rng.uniform(3.0, 5.0, n)]
    log_scales = np.c_[np.log(rng.uniform(0.2, 0.6, n)), np.log(rng.uniform(0.005, 0.03, n)),
                       np.log(rng.uniform(0.005, 0.03, n))]
    angle = rng.uniform(0, np.pi, n)  # rotation about the optical axis
    quats = np.c_[np.cos(angle / 2), np.zeros(n), np.zeros(n), np.sin(angle / 2)]
    g = Gaussians(means, log_scales, quats, rng.normal(0.0, 2.0, n), rng.normal(0.5, 0.2, (n, 1, 3)))
    cam = Camera(72, 56, 60.0, 60.0, 36.0, 28.0, np.eye(4))
    return g, cam


def dense_useful(gaussians, camera, opts: RasterOptions) -> int:
    """(pixel, Gaussian) pairs the compositing loop's per-pixel test accepts, over the
    whole image, ignoring tiles entirely."""
    m = get_device("cpu").t
    with dr.suspend_grad():
        proj = project(*(to_tensor(m, getattr(gaussians, k)) for k in
                         ("means", "log_scales", "quats", "opacity_logits")), camera, opts)
        n, size = len(gaussians), camera.width * camera.height
        idx = dr.arange(m.UInt32, n * size)
        g, pix = idx // size, idx % size
        fields = GeoRecord(u=proj.means2d.x, v=proj.means2d.y, conic_a=proj.conics.x, conic_b=proj.conics.y,
                           conic_c=proj.conics.z, opacity=proj.opacities, depth=proj.depths, cutoff_sq=proj.cutoff_sq)
        geo = GeoRecord(*(dr.gather(m.Float, f, g) for f in fields))
        px = m.Float(pix % camera.width) + 0.5
        py = m.Float(pix // camera.width) + 0.5
        cfg = CompositeSettings.from_options(opts)
        _, contributes, *_ = _alpha_at(geo, px, py, cfg, dr.gather(m.Bool, proj.visible, g))
        return int(dr.count(contributes)[0])


@pytest.mark.parametrize("tile_size", [4, 16, 32])
@pytest.mark.parametrize("radius, antialiased", [("3sigma", False), ("opacity", False), ("3sigma", True)])
def test_tile_test_keeps_every_accepted_pixel(tile_size, radius, antialiased):
    g, cam = elongated_scene(400, seed=tile_size)
    opts = dict(device="cpu", tile_size=tile_size, radius=radius, antialiased=antialiased)
    stats = work_stats(g, cam, RasterOptions(**opts))
    assert stats.useful == dense_useful(g, cam, RasterOptions.from_kwargs(**opts))
    # The tests do drop work here (thin diagonal ellipses in square boxes): pairs at
    # the tile level (32-pixel tiles are too coarse for much of it) ...
    if tile_size <= 16:
        assert stats.pairs < 0.8 * stats.box_pairs
    # ... and list entries at the block level (a 4-pixel tile is one block).
    if tile_size > 4:
        assert stats.performed < 0.5 * stats.tile_evaluations
    # ... and the counts are consistent with each other.
    assert stats.useful <= stats.inside_cutoff <= stats.block_evaluations <= stats.performed
    assert stats.performed <= stats.tile_evaluations == stats.pairs * tile_size ** 2
    assert splatbench.render(g, cam, options=RasterOptions(**opts)).num_pairs == stats.pairs


def test_work_stats_standard_workload_matches_dense_count():
    w = synthetic(2000, 96, 80, seed=5)
    stats = work_stats(w.gaussians, w.camera, RasterOptions(device="cpu"))
    assert stats.useful == dense_useful(w.gaussians, w.camera, RasterOptions(device="cpu"))
    assert 0 < stats.useful_share < 1


def test_work_stats_of_nothing_is_zero():
    cam = Camera(16, 12, 16.0, 16.0, 8.0, 6.0, np.eye(4))
    g = Gaussians(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0), np.zeros((0, 1, 3)))
    assert work_stats(g, cam, RasterOptions(device="cpu")).performed == 0


def test_dropped_pairs_change_no_output_or_gradient(monkeypatch):
    """Box-only binning (every tile of the bounding box) against the ellipse-tile test:
    the images are bit-identical and so are the gradients (a dropped pair only ever
    contributed exact zeros to its Gaussian's sums)."""
    import torch

    from splatbench.raster import binning

    g, cam = elongated_scene(300, seed=1)
    names = ("means", "log_scales", "quats", "opacity_logits", "sh")

    def run():
        leaves = [torch.tensor(getattr(g, k), requires_grad=True) for k in names]
        rgb, alpha, depth, info = splatbench.rasterize(*leaves, cam, options=RasterOptions(device="cpu"), background=(0.1, 0.2, 0.3))
        (rgb.square().sum() + alpha.sum() + 0.1 * depth.sum()).backward()
        return [rgb.detach(), alpha.detach(), depth.detach()] + [p.grad for p in leaves], info.num_pairs

    tested, pairs = run()
    monkeypatch.setattr(binning, "ellipse_meets_rect", lambda dx0, *rest: dx0 == dx0)  # keep every tile
    boxed, box_pairs = run()
    assert pairs < box_pairs
    for a, b in zip(tested, boxed):
        assert torch.equal(a, b)
