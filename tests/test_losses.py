"""The fused D-SSIM (splatbench.train.dssim) against kornia's SSIM, value and gradient.

Two checks. In float64 both evaluate the same formula, so they agree to float64
rounding: a wrong partial derivative or adjoint would miss by orders of magnitude
more. In float32 (what the trainer runs) the fused pass sums in another order than
kornia, so it cannot match kornia's float32 bits; it must be as close to the float64
truth as kornia's own float32 result is (a factor 4 of headroom for the different
summation order, plus a few float32 ulps where kornia happens to round exactly).
"""

from __future__ import annotations

import kornia
import pytest
import torch

from splatbench.errors import InputError
from splatbench.train.dssim import dssim, gaussian_window
from splatbench.metrics.image import to_bchw
from splatbench.train.losses import photometric_loss

EPS32 = float(torch.finfo(torch.float32).eps)


def kornia_dssim(pred, target, window):
    return 1 - kornia.metrics.ssim(pred, target, window, max_val=1.0).mean()


def images(seed: int, shape=(1, 3, 37, 29), dtype=torch.float64):
    """A smooth image plus noise and a sharp edge (structure at every scale), and a
    perturbed copy as the target, all in [0, 1]."""
    g = torch.Generator().manual_seed(seed)
    b, c, h, w = shape
    yy, xx = torch.meshgrid(torch.linspace(0, 1, h, dtype=dtype), torch.linspace(0, 1, w, dtype=dtype), indexing="ij")
    base = 0.5 + 0.3 * torch.sin(6 * xx + 4 * yy + torch.arange(c, dtype=dtype).view(1, c, 1, 1))
    base = base + 0.2 * (xx > 0.6) + 0.05 * torch.rand(shape, generator=g, dtype=dtype)
    target = (base + 0.1 * torch.rand(shape, generator=g, dtype=dtype)).clamp(0, 1)
    return base.expand(b, c, h, w).clamp(0, 1).contiguous(), target


def value_and_grad(fn, pred, target, window):
    p = pred.clone().requires_grad_(True)
    loss = fn(p, target, window)
    loss.backward()
    return loss.detach(), p.grad


@pytest.mark.parametrize("window", [11, 5])
@pytest.mark.parametrize("seed", [0, 1])
def test_fused_dssim_is_kornias_formula_in_float64(seed, window):
    pred, target = images(seed)
    v, g = value_and_grad(dssim, pred, target, window)
    kv, kg = value_and_grad(kornia_dssim, pred, target, window)
    # the same maths in float64: about 1e-16 relative per operation, a few hundred operations
    assert abs(float(v - kv)) <= 1e-12
    torch.testing.assert_close(g, kg, rtol=1e-9, atol=1e-12 * float(kg.abs().max()))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fused_dssim_matches_kornia_to_float32_precision(seed):
    pred64, target64 = images(seed, shape=(1, 3, 64, 48))
    truth_v, truth_g = value_and_grad(kornia_dssim, pred64, target64, 11)
    pred, target = pred64.float(), target64.float()
    v, g = value_and_grad(dssim, pred, target, 11)
    kv, kg = value_and_grad(kornia_dssim, pred, target, 11)
    assert v.dtype == g.dtype == torch.float32
    k_err_v = abs(float(kv) - float(truth_v))
    assert abs(float(v) - float(truth_v)) <= 4 * k_err_v + 4 * EPS32
    scale = float(truth_g.abs().max())
    k_err_g = float((kg.double() - truth_g).abs().max())
    assert float((g.double() - truth_g).abs().max()) <= 4 * k_err_g + 4 * EPS32 * scale


def test_fused_dssim_batches_and_matches_the_window_kornia_uses():
    w = gaussian_window(11, dtype=torch.float64)
    kw = kornia.filters.get_gaussian_kernel1d(11, 1.5, dtype=torch.float64).reshape(-1)
    torch.testing.assert_close(w, kw, rtol=1e-15, atol=0)
    pred, target = images(3, shape=(2, 3, 20, 24))
    v, g = value_and_grad(dssim, pred, target, 11)
    kv, kg = value_and_grad(kornia_dssim, pred, target, 11)
    assert abs(float(v - kv)) <= 1e-12
    torch.testing.assert_close(g, kg, rtol=1e-9, atol=1e-12 * float(kg.abs().max()))


def test_photometric_loss_uses_the_fused_dssim_and_keeps_its_value():
    pred64, target64 = images(4, shape=(1, 3, 32, 32))
    pred = pred64[0].permute(1, 2, 0).float()  # [H, W, 3]
    target = target64[0].permute(1, 2, 0).float()
    p = pred.clone().requires_grad_(True)
    loss = photometric_loss(p, target, 0.2, 11)
    loss.backward()
    expected = 0.8 * (pred - target).abs().mean() + 0.2 * kornia_dssim(to_bchw(pred), to_bchw(target), 11)
    # float32 sums of 3072 terms in different orders: a few ulps of a loss of order 0.1
    assert abs(float(loss.detach()) - float(expected)) <= 16 * EPS32
    q = pred.clone().requires_grad_(True)
    (0.8 * (q - target).abs().mean() + 0.2 * kornia_dssim(to_bchw(q), to_bchw(target), 11)).backward()
    # the L1 part is identical; the D-SSIM part differs by float32 rounding (see the test above:
    # about 1e-4 of the largest D-SSIM gradient), which is 0.2 x 6e-3 here
    torch.testing.assert_close(p.grad, q.grad, rtol=0, atol=1e-4 * float(q.grad.abs().max()))


def test_too_small_an_image_or_mismatched_shapes_are_one_line():
    with pytest.raises(InputError, match="ssim_window: 11 needs images larger than 5 px"):
        dssim(torch.rand(1, 3, 5, 9), torch.rand(1, 3, 5, 9))
    with pytest.raises(InputError, match="dssim: expected two"):
        dssim(torch.rand(1, 3, 8, 8), torch.rand(1, 3, 8, 9))
    # the SSIM map's own boundary: an image without its batch axis (before: a ValueError from
    # unpacking the shape, the check after it unreachable)
    from splatbench.metrics.ssim import ssim_map

    with pytest.raises(InputError, match=r"^ssim: expected two \[B, C, H, W\] images of one shape, got \[3, 8, 8\]"):
        ssim_map(torch.rand(3, 8, 8), torch.rand(3, 8, 8))


@pytest.mark.parametrize("seed", [0, 1])
def test_ssim_metric_is_kornias_to_float32_precision(seed):
    """The evaluation's SSIM (`ssim_metric`, the Dr.Jit SSIM of `splatbench.metrics.ssim`)
    against kornia's: the same maths summed in another order (separable blurs against
    kornia's 2D kernel), so in float32 it must be as close to the float64 truth as
    kornia's own float32 mean SSIM (factor 4 for the order, plus 4 ulps)."""
    from splatbench.metrics.image import ssim_metric

    pred64, target64 = images(seed, shape=(1, 3, 40, 56))
    truth = float(kornia.metrics.ssim(pred64, target64, 11, max_val=1.0).mean())
    hwc = [t[0].permute(1, 2, 0) for t in (pred64, target64)]
    ours = ssim_metric(*(t.float() for t in hwc))
    theirs = float(kornia.metrics.ssim(pred64.float(), target64.float(), 11, max_val=1.0).mean())
    assert abs(ours - truth) <= 4 * abs(theirs - truth) + 4 * EPS32
    assert abs(ssim_metric(*hwc) - truth) <= 1e-12  # float64: the same maths to float64 rounding
