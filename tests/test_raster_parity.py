"""Forward parity: the Dr.Jit rasterizer against `reference.render(mode="matched")`.

Tolerance, derived rather than observed. float32 has unit roundoff u = 2^-24 ~ 6e-8.
A pixel value is sum_i T_i a_i c_i over at most L composited terms; T_i is a product
of i factors (relative error <= i u) and each a_i c_i takes ~20 float32 operations
(projection, conic inverse, exp), so the absolute error is at most
(2 L + 20) u max|c|. Our scenes composite L <= 150 terms per pixel with |c| <= ~2:
(320) u * 2 ~ 4e-5 as a hard bound, 2e-5 as the per-pixel tolerance in practice
for the random-walk sum (errors of independent terms add in quadrature, not
linearly). Depth is compared as depth * alpha (the composited sum of T a z, the
quantity the rasterizer computes) scaled by the largest depth in the scene,
because depth = sum / alpha amplifies alpha's absolute error by 1 / alpha.

Boundary band: a pixel where float32 and float64 fall on different sides of a
discrete decision (the 3-sigma cutoff, alpha_min, the early stop) differs by a whole
contribution. The oracle derives those pixels (`reference.band`: some contribution
within the worst-case float32 error of a decision) and two contributions whose depths
may swap widen that pixel's tolerance by what the swap changes; outside the band the
tolerance holds strictly (tests/compare.py `assert_render_close`).
"""

from __future__ import annotations


import numpy as np
import pytest

import splatbench
from splatbench.backends import reference_render
from splatbench.raster.options import RasterOptions
from splatbench.workloads import GARDEN_SFM, load_npz, model_workload
from tests.compare import EPS32, assert_render_close
from tests.scenes import parity_scene

ATOL = 2e-5


def check_parity(tag: str, workload, background, device: str = "cpu", **options) -> None:
    fast = splatbench.render(workload.gaussians, workload.camera, background=background,
                            options=RasterOptions(device=device, **options))
    g = workload.gaussians  # the reference follows the same options (tile_size and device have no counterpart)
    ref = reference_render(options, g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, workload.camera,
                           background=background, band=True)
    assert_render_close(tag, fast.rgb, fast.alpha, fast.depth, ref, ATOL)
    # Culling is decided per Gaussian on float32 vs float64 values; a box touching the
    # image edge or a radius at an integer may flip, by at most one pixel of radius.
    assert int((fast.visible != ref.visible).sum()) <= 1
    both = fast.visible & ref.visible
    assert np.abs(fast.radii[both].astype(int) - ref.radii[both]).max(initial=0) <= 1


@pytest.mark.parametrize("seed", range(20))
def test_forward_parity_random_scenes(seed, device):
    workload, background = parity_scene(seed)
    check_parity(workload.name, workload, background, device)


@pytest.mark.parametrize("options", [
    {"radius": "opacity"},
    {"antialiased": True},
    {"tile_size": 8},
    {"alpha_min": 0.05, "transmittance_min": 0.05},
    {"eps2d": 0.0},
], ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()))
def test_forward_parity_options(options, device):
    workload, background = parity_scene(3)
    check_parity(f"{workload.name}-{'-'.join(map(str, options.values()))}", workload, background, device, **options)


def test_tile_size_does_not_change_the_image():
    """Tiles are an acceleration only: the per-pixel cutoff decides (conventions.md)."""
    workload, _ = parity_scene(1)
    images = [splatbench.render(workload.gaussians, workload.camera, options=RasterOptions(tile_size=ts)).rgb
              for ts in (4, 8, 16, 32)]
    for img in images[1:]:
        # Same float32 operations in the same order per pixel: identical up to FMA
        # contraction differences between kernels, a few ulp of values <= ~2.
        np.testing.assert_allclose(img, images[0], rtol=0, atol=8 * EPS32)


def test_forward_parity_garden_view():
    """Real SfM data at reduced resolution: 138,766 Gaussians seeded as 3DGS does."""
    workload = load_npz(GARDEN_SFM, view=0)
    small = type(workload)(workload.name, workload.gaussians, workload.camera.scaled(0.25))
    check_parity("garden", small, (0.0, 0.0, 0.0))


@pytest.mark.parametrize("model", ["guitar", pytest.param("biker", marks=pytest.mark.slow)])
def test_forward_parity_real_model(model):
    """A real trained model (bundled, PlayCanvas, MIT): every fourth Gaussian, one view of three
    at 48x48 -- real opacities, scales and overlaps, which put many more contributions on a
    decision than the synthetic scenes do; the band the oracle derives must hold them."""
    workload = model_workload(model, 1, 3, 48, 48)
    thin = workload.gaussians.subset(np.arange(0, len(workload.gaussians), 4))
    check_parity(workload.name, type(workload)(workload.name, thin, workload.camera), (0.0, 0.0, 0.0))
