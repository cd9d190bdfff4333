"""The compositing lanes' pixel block (`RasterOptions.pixel_block`) is an acceleration only.

A lane shades a B x B block and walks the pairs whose support meets it; every pixel
composites the same Gaussians in the same depth order whatever B is, and its backward
walk recovers the same transmittances by the same divisions (the walk only steps a
pixel's state where that pixel contributed). So the images are bit-identical at every B,
and so is each pixel's gradient term; only the grouping of the per-Gaussian sums changes
(B^2 pixels summed in registers per lane, then a packet's lanes into one per-pair slot,
then the slots in order), which float32 rounds differently.
"""

from __future__ import annotations

import numpy as np
import pytest

from splatbench.errors import InputError
from splatbench.raster.options import DEFAULT_PIXEL_BLOCK, RasterOptions
from splatbench.raster.work import work_stats
from splatbench.workloads import model_workload
from tests.compare import assert_grads_agree
from tests.gradcheck import GROUPS, Cotangents, fast_vjp
from tests.scenes import parity_scene

# Band for a change of summation order (as tests/test_raster_reduction.py derives it): a
# Gaussian's gradient is a float32 sum of M per-pixel terms, and any two orders of it differ
# by at most 2 (M - 1) 2^-24 sum|terms|. M is at most a few hundred here (each scene's
# Gaussians cover a few hundred pixels at most), so the relative L2 over all Gaussians stays
# below 300 * 6e-8 = 2e-5 unless cancellation is severe, which the L2 over all averages out.
REL_L2 = 2e-5
COSINE = 1 - 1e-9


def _workloads():
    return [parity_scene(0), parity_scene(4), (model_workload("guitar", 0, 3, 120, 90), (0.1, 0.2, 0.3))]


@pytest.mark.parametrize("tile_size, pixel_block", [(16, 2), (16, 8), (8, 2), (32, 2)])
def test_pixel_block_keeps_the_image_and_the_gradients_within_the_band(tile_size, pixel_block):
    for workload, background in _workloads():
        c = workload.camera
        v = Cotangents.standard_normal(pixel_block, c.height, c.width)
        base = fast_vjp(workload, v, background=background, device="cpu", tile_size=tile_size)
        other = fast_vjp(workload, v, background=background, device="cpu", tile_size=tile_size,
                         pixel_block=pixel_block)
        for name in ("rgb", "alpha", "depth"):
            np.testing.assert_array_equal(getattr(other, name), getattr(base, name), err_msg=name)
        for k in GROUPS:
            assert np.abs(base.grads[k]).max() > 0, k
            assert_grads_agree(f"{workload.name} {k}", other.grads[k], base.grads[k], rel_l2=REL_L2, cosine=COSINE)


def test_the_default_block_is_four_follows_a_smaller_tile_and_records_what_runs():
    """4 x 4 is the layout measured fastest (docs/benchmarks.md). A tile smaller than that
    (tile_size 1 or 2, which a user may set) gets the tile's side as its block, held as
    the value itself, so a config or record says what ran (it used to say 4 while 2 ran);
    that layout renders the image of every other."""
    assert RasterOptions().pixel_block == DEFAULT_PIXEL_BLOCK == 4
    assert [RasterOptions(tile_size=t).pixel_block for t in (1, 2, 4, 8, 64)] == [1, 2, 4, 4, 4]
    small = RasterOptions(tile_size=2)
    assert small == RasterOptions(tile_size=2, pixel_block=2) and small.to_dict()["pixel_block"] == 2
    assert RasterOptions.from_dict(small.to_dict()) == small
    assert RasterOptions.from_kwargs(tile_size=2).pixel_block == 2
    assert RasterOptions.from_dict({"tile_size": 2}, prefix="raster.").pixel_block == 2
    workload, background = parity_scene(1)
    c = workload.camera
    v = Cotangents.standard_normal(1, c.height, c.width)
    default = fast_vjp(workload, v, background=background, device="cpu", tile_size=2)
    ones = fast_vjp(workload, v, background=background, device="cpu", tile_size=2, pixel_block=1)
    np.testing.assert_array_equal(default.rgb, ones.rgb)


def test_a_block_larger_than_the_tile_is_refused_not_capped():
    """A pixel_block given larger than the tile used to run as the tile's side while the
    config said otherwise; now it is one line naming the field and the fix."""
    message = ("pixel_block: at most tile_size (2), got 8; use pixel_block <= 2, or leave it out (the default "
               "follows a smaller tile)")
    with pytest.raises(InputError) as info:
        RasterOptions(tile_size=2, pixel_block=8)
    assert str(info.value) == message
    with pytest.raises(InputError) as info:
        RasterOptions.from_kwargs(tile_size=2, pixel_block=8)
    assert str(info.value) == message
    with pytest.raises(InputError) as info:
        RasterOptions.from_dict({"tile_size": 2, "pixel_block": 4}, prefix="raster.")
    assert str(info.value) == ("raster.pixel_block: at most tile_size (2), got 4; use pixel_block <= 2, or leave "
                               "it out (the default follows a smaller tile)")


@pytest.mark.parametrize("options, message", [
    ({"pixel_block": 3}, "pixel_block: expected a power of two in [1, 8], got 3"),
    ({"pixel_block": 16}, "pixel_block: expected a power of two in [1, 8], got 16"),
    ({"pixel_block": True}, "pixel_block: expected a power of two in [1, 8], got True"),
    ({"tile_size": 64, "pixel_block": 1}, "pixel_block: at most 32 blocks per tile side, got tile_size 64 / "
                                         "pixel_block 1; use pixel_block >= 2"),
])
def test_bad_pixel_blocks_are_one_line_errors(options, message):
    with pytest.raises(InputError) as info:
        RasterOptions(**options)
    assert str(info.value) == message


def test_smaller_blocks_perform_fewer_evaluations_with_the_same_useful_ones():
    """The counts `bench raster` reports follow the layout: a real model's faint, small
    Gaussians meet few 2 x 2 blocks of a 4 x 4 block, so 2 x 2 lanes perform fewer
    evaluations (each lane list shorter, 4 packets per 16 x 16 tile sorted by length);
    the useful evaluations are the image's, the same at every layout (the ones inside the
    cutoff but outside the support are not: the blocks follow the support)."""
    w = model_workload("guitar", 0, 3, 120, 90)
    four = work_stats(w.gaussians, w.camera, RasterOptions(device="cpu"))
    two = work_stats(w.gaussians, w.camera, RasterOptions(device="cpu", pixel_block=2))
    assert two.useful == four.useful and two.pairs == four.pairs
    assert two.block_evaluations < four.block_evaluations and two.performed < four.performed
    assert two.useful_share > four.useful_share


def test_the_drjit_backend_passes_pixel_block_on(monkeypatch):
    """`compare`'s drjit backend hands its `RasterOptions` to the rasterizer as they are, the
    lane layout included (it used to name the fields it passed, and would drop a new one)."""
    import splatbench.raster
    from splatbench.backends.builtins.drjit_backend import make_drjit_backend

    seen = {}

    def rasterize(*args, **kwargs):
        seen.update(kwargs)
        return None, None, None, None

    monkeypatch.setattr(splatbench.raster, "rasterize", rasterize)
    backend = make_drjit_backend(pixel_block=2, tile_size=8)
    backend.fn(None, None, None, None, None, None)
    assert seen["options"].pixel_block == 2 and seen["options"].tile_size == 8  # the typed record, whole
    assert seen["options"] == RasterOptions(pixel_block=2, tile_size=8)  # every field, none dropped or renamed
    assert set(seen) == {"options", "sh_degree", "background"}
