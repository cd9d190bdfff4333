"""Binning's culling and sort (`splatbench.raster.binning`) against the binning it replaced.

The support boxes drop only pairs every pixel skips, and the counting sort gives the same
(tile, depth, index) order, so the images and the gradients must be bit-identical to
binning every tile of the cutoff box that the ellipse test keeps, sorted by one 64-bit key
(`tests/binning_3sigma.py`, the old path kept only here). And the backward pass must be
bit-reproducible at every tile size (issue 30 item 4: at tile_size 32 it was not).
"""

from __future__ import annotations

import numpy as np
import pytest

from splatbench import Camera, Gaussians
from splatbench.raster import pipeline
from splatbench.raster.api import to_tensor
from splatbench.raster.binning import MAX_WIDENING, bin_gaussians, support_extents
from splatbench.raster.device import dr, get_device
from splatbench.raster.options import RasterOptions
from splatbench.raster.projection import project
from splatbench.raster.work import work_stats
from splatbench.workloads import Workload, model_workload, synthetic
from tests.binning_3sigma import bin_gaussians_3sigma
from tests.gradcheck import GROUPS, Cotangents, fast_vjp


def culling_scene(n: int, seed: int, width: int = 88, height: int = 72) -> Workload:
    """What the culling must get right: faint Gaussians (opacity from 1e-4 to 0.98, so
    some below alpha_min = 1/255 and many whose support is far inside 3 sigma), needles
    thin enough that their conic is too ill-conditioned for the tight box (they keep the
    cutoff box), Gaussians past the image edges, and ties in depth (every 7th shares z = 3)."""
    rng = np.random.default_rng(seed)
    fx = float(width)
    z = rng.uniform(2.0, 6.0, n)
    z[::7] = 3.0
    u, v = rng.uniform(-0.1 * width, 1.1 * width, n), rng.uniform(-0.1 * height, 1.1 * height, n)
    means = np.stack([(u - width / 2) * z / fx, (v - height / 2) * z / fx, z], axis=1)
    sigma_px = np.exp(rng.uniform(np.log(0.4), np.log(8.0), n))
    log_scales = np.log(sigma_px * z / fx)[:, None] + np.zeros((n, 3))
    needle = rng.random(n) < 0.2
    # long and thin: up to ~160 px along, eps2d (0.3 px^2) across, so the conic's condition
    # tr^2 / det reaches past the 8192 = MAX_WIDENING / Q_REL_SLACK of the tight box
    log_scales[needle, 0] += 3.0
    log_scales[needle, 1:] -= 6.0
    log_scales[~needle] += 0.8 * rng.standard_normal((int((~needle).sum()), 3))
    angle = rng.uniform(0, np.pi, n)
    quats = np.c_[np.cos(angle / 2), 0.3 * rng.standard_normal((n, 2)), np.sin(angle / 2)]
    opacity = np.exp(rng.uniform(np.log(1e-4), np.log(0.98), n))
    sh = np.concatenate([0.6 * rng.standard_normal((n, 1, 3)), 0.1 * rng.standard_normal((n, 3, 3))], 1)
    g = Gaussians(means, log_scales, quats, np.log(opacity / (1 - opacity)), sh)
    return Workload(f"culling-{seed}", g, Camera(width, height, fx, fx, width / 2, height / 2, np.eye(4)))


def assert_same_vjp(new, old) -> None:
    for name in ("rgb", "alpha", "depth"):
        np.testing.assert_array_equal(getattr(new, name), getattr(old, name), err_msg=name)
    for k in GROUPS:
        assert np.abs(old.grads[k]).max() > 0, k  # a gradient that could differ
        np.testing.assert_array_equal(new.grads[k], old.grads[k], err_msg=k)


def vjp_both_ways(workload: Workload, monkeypatch, **options):
    """(culled binning, the old cutoff-box binning): outputs and gradients of one random cotangent."""
    c = workload.camera
    v = Cotangents.standard_normal(3, c.height, c.width)
    kwargs = dict(device="cpu", background=(0.1, 0.2, 0.3), **options)
    new = fast_vjp(workload, v, **kwargs)
    with monkeypatch.context() as patch:
        patch.setattr(pipeline, "bin_gaussians", bin_gaussians_3sigma)
        old = fast_vjp(workload, v, **kwargs)
    return new, old


@pytest.mark.parametrize("tile_size", [8, 16, 32])
def test_culled_binning_is_bit_identical_to_the_cutoff_box(tile_size, monkeypatch):
    workload = culling_scene(500, seed=tile_size)
    new, old = vjp_both_ways(workload, monkeypatch, tile_size=tile_size)
    assert_same_vjp(new, old)
    stats = work_stats(workload.gaussians, workload.camera, RasterOptions(device="cpu", tile_size=tile_size))
    assert stats.pairs <= stats.box_pairs < stats.cutoff_box_pairs  # the support boxes culled some


@pytest.mark.parametrize("radius, antialiased", [("opacity", False), ("3sigma", True)])
def test_culled_binning_is_bit_identical_with_other_options(radius, antialiased, monkeypatch):
    new, old = vjp_both_ways(culling_scene(300, seed=5), monkeypatch, radius=radius, antialiased=antialiased)
    assert_same_vjp(new, old)


def test_culled_binning_is_bit_identical_on_a_real_model(monkeypatch):
    """A real trained model (PlayCanvas guitar, MIT), small: its opacities are what the
    support boxes are for."""
    new, old = vjp_both_ways(model_workload("guitar", 0, 3, 120, 90), monkeypatch)
    assert_same_vjp(new, old)


def bins_of(workload: Workload, binner, tile_size: int = 16):
    m = get_device("cpu").t
    g, cam = workload.gaussians, workload.camera
    opts = RasterOptions(device="cpu", tile_size=tile_size)
    with dr.suspend_grad():
        proj = project(*(to_tensor(m, getattr(g, k)) for k in ("means", "log_scales", "quats", "opacity_logits")),
                       cam, opts)
        bins = binner(proj, cam, opts)
        return bins, proj


def test_pairs_are_the_old_pairs_in_the_old_order():
    """The kept pairs are exactly the old ones, in the same (tile, depth, index) order: every
    tile the ellipse test keeps lies inside the support box (its slack is below the box's
    widening, `support_extents`), so the boxes only save candidates. And the per-Gaussian
    runs for the reduction hold each Gaussian's pairs in ascending tile order."""
    workload = culling_scene(400, seed=2)
    new, _ = bins_of(workload, bin_gaussians)
    old, _ = bins_of(workload, bin_gaussians_3sigma)
    assert new.box_pairs < old.box_pairs == new.cutoff_box_pairs
    for name in ("gaussian_ids", "tiles", "tile_start", "tile_end"):
        a, b = getattr(new, name).numpy(), getattr(old, name).numpy()
        if name == "tile_start":  # an empty tile's range may sit anywhere
            a, b = a[new.tile_end.numpy() > a], b[old.tile_end.numpy() > b]
        np.testing.assert_array_equal(a, b, err_msg=name)
    # Gaussian g's pairs at generation positions offsets[g] .. + counts[g], ascending tiles.
    # order: sorted position -> generation position
    order, tiles, gids = new.order.numpy(), new.tiles.numpy(), new.gaussian_ids.numpy()
    offsets, counts = new.offsets.numpy(), new.counts.numpy()
    assert sorted(order) == list(range(new.num_pairs))
    tile_at = np.empty(new.num_pairs, dtype=np.int64)
    tile_at[order] = tiles
    gid_at = np.empty(new.num_pairs, dtype=np.int64)
    gid_at[order] = gids
    np.testing.assert_array_equal(counts, np.bincount(gids, minlength=len(counts)))
    for g in np.flatnonzero(counts):
        run = slice(offsets[g], offsets[g] + counts[g])
        assert (gid_at[run] == g).all()
        assert (np.diff(tile_at[run]) > 0).all()


def test_support_boxes_shrink_faint_gaussians_and_keep_needles():
    workload = culling_scene(400, seed=3)
    bins, proj = bins_of(workload, bin_gaussians)
    with dr.suspend_grad():
        rx, ry = support_extents(proj.conics, bins.support_sq, proj.extents)
    rx, ry = rx.numpy(), ry.numpy()
    cut_x, cut_y = proj.extents.x.numpy(), proj.extents.y.numpy()
    a, b, c = (x.numpy().astype(np.float64) for x in (proj.conics.x, proj.conics.y, proj.conics.z))
    opacity, visible = proj.opacities.numpy(), proj.visible.numpy()
    e = 2.0 ** -16 * (a + c) ** 2 / (a * c - b * b)
    well = e <= MAX_WIDENING
    assert (rx <= cut_x).all() and (ry <= cut_y).all()
    assert not well.all() and well.any()  # the scene has both kinds
    assert (rx[~well] == cut_x[~well]).all() and (ry[~well] == cut_y[~well]).all()  # needles: cutoff box
    faint = well & visible & (opacity < 0.5 / 255)
    assert faint.any() and (rx[faint] == 0).all() and (ry[faint] == 0).all()  # below alpha_min: the mean's tile
    assert (bins.counts.numpy()[faint] <= 1).all()
    # a faint, well-conditioned Gaussian's box: the ellipse 2 ln(o / alpha_min), far inside 3 sigma
    dim = well & visible & (opacity > 2 / 255) & (opacity < 0.05)
    assert dim.any() and (rx[dim] < 0.9 * cut_x[dim]).all()


@pytest.mark.parametrize("tile_size, pixel_block", [(8, 4), (16, 4), (32, 4), (16, 2)])
def test_backward_is_bit_reproducible(tile_size, pixel_block):
    """Several backward passes give the same bits. 96 x 96 at tile_size 32 is 9 tiles of
    4 SIMD packets each (16-lane AVX-512): with two threads Dr.Jit splits the launch into
    two blocks of 18 packets, so a tile straddles them, and a per-pair slot shared by the
    whole tile rounded differently from run to run (issue 30: 3 of 14 runs). 32 x 32 is a
    single such tile; 2 x 2 pixel blocks make a 16-pixel tile 4 packets too. Needs more
    than one Dr.Jit thread, or any order is fixed."""
    threads = dr.thread_count()
    if threads < 2:
        dr.set_thread_count(2)
    try:
        for size in (96, 32):
            workload = synthetic(1500, size, size, seed=size)
            c = workload.camera
            v = Cotangents.standard_normal(1, c.height, c.width)
            first = fast_vjp(workload, v, device="cpu", tile_size=tile_size, pixel_block=pixel_block)
            for _ in range(6):
                again = fast_vjp(workload, v, device="cpu", tile_size=tile_size, pixel_block=pixel_block)
                np.testing.assert_array_equal(again.rgb, first.rgb)
                for k in GROUPS:
                    np.testing.assert_array_equal(again.grads[k], first.grads[k], err_msg=f"{k} at {size}")
    finally:
        dr.set_thread_count(threads)


@pytest.mark.parametrize("digit_bits", [None, 8, 13])
def test_argsort_bits_is_a_stable_argsort(digit_bits):
    """Every digit width binning sorts with (11 bits on LLVM, 8 as on CUDA, a wider single
    pass) gives numpy's stable argsort, ties included."""
    from splatbench.raster.binning import argsort_bits

    m = get_device("cpu").t
    rng = np.random.default_rng(digit_bits or 0)
    keys = rng.integers(0, 1 << 26, 20_000, dtype=np.uint32)
    keys[::3] = keys[1::3][: len(keys[::3])]  # ties
    np.testing.assert_array_equal(argsort_bits(m.UInt32(keys), 26, digit_bits).numpy(),
                                  np.argsort(keys, kind="stable"))


@pytest.mark.parametrize("num_tiles", [1, 475, 1 << 21])
def test_tile_order_is_stable(num_tiles):
    from splatbench.raster.binning import tile_order

    m = get_device("cpu").t
    tiles = np.random.default_rng(num_tiles).integers(0, num_tiles, 50_000, dtype=np.uint32)
    np.testing.assert_array_equal(tile_order(m, m.UInt32(tiles), num_tiles).numpy(),
                                  np.argsort(tiles, kind="stable"))
