"""D-SSIM ``1 - mean SSIM`` with its gradient in one fused pass (the training loss's SSIM term).

The value is kornia's ``1 - kornia.metrics.ssim(pred, target, window).mean()``: a
sampled Gaussian window (σ = 1.5, ``window`` taps, sum 1) applied separably with
reflect padding ("same" size), ``c1 = 0.01²``, ``c2 = 0.03²``, ``eps = 1e-12`` added
to the denominator. The forward pass blurs the five maps ``x, y, x², y², xy`` in one
grouped, separable convolution and, since the loss is a scalar, computes the gradient
with respect to ``pred`` there and then; autograd's backward only scales it. With

    μx, μy, Exx, Eyy, Exy   the blurred maps
    A1 = 2 μx μy + c1       A2 = 2 (Exy − μx μy) + c2
    B1 = μx² + μy² + c1     B2 = (Exx − μx²) + (Eyy − μy²) + c2
    S = A1 A2 / (B1 B2 + eps),  D = B1 B2 + eps

the per-pixel partial derivatives (the blurred maps held fixed) are

    ∂S/∂μx  = 2 μy (A2 − A1) / D − 2 μx S (B2 − B1) / D
    ∂S/∂Exx = −S B1 / D
    ∂S/∂Exy = 2 A1 / D

and ``∂mean(S)/∂x = Blurᵀ(∂S/∂μx) + 2 x Blurᵀ(∂S/∂Exx) + y Blurᵀ(∂S/∂Exy)``, divided
by the number of map values, where ``Blurᵀ`` is the exact adjoint of the padded blur
(transposed convolutions, then the reflect padding folded back). Only ``pred`` gets a
gradient; ``target`` is data. `tests/test_losses.py` checks value and gradient against
kornia's in float64 (same maths) and float32 (the same rounding error as kornia's).
Speed against kornia is not measured yet.
"""

from __future__ import annotations

import functools

import torch
import torch.nn.functional as F

SIGMA = 1.5
C1, C2, EPS = 0.01 ** 2, 0.03 ** 2, 1e-12


def gaussian_window(window: int, *, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """[window] samples of exp(−n² / 2σ²), n = −window//2 .. window//2, σ = 1.5, summing to 1."""
    n = torch.arange(window, dtype=dtype) - window // 2
    g = torch.exp(-(n * n) / (2 * SIGMA ** 2))
    return g / g.sum()


def _fold_reflect(t: torch.Tensor, dim: int, pad: int) -> torch.Tensor:
    """Adjoint of reflect padding along ``dim``: [.., n + 2 pad, ..] -> [.., n, ..], each
    padded position added onto the source it copied (edge not repeated)."""
    n = t.shape[dim] - 2 * pad
    out = t.narrow(dim, pad, n).clone()
    out.narrow(dim, 1, pad).add_(t.narrow(dim, 0, pad).flip(dim))            # left: position -j copied j
    out.narrow(dim, n - 1 - pad, pad).add_(t.narrow(dim, n + pad, pad).flip(dim))  # right: n-1+j copied n-1-j
    return out


class _Blur:
    """The separable, reflect-padded Gaussian blur of [1, C, H, W] maps, and its adjoint."""

    def __init__(self, window: int, channels: int, height: int, width: int, dtype, device) -> None:
        if min(height, width) <= window // 2:
            from splatbench.errors import InputError

            raise InputError(f"ssim_window: {window} needs images larger than {window // 2} px, got "
                             f"{width}x{height}")
        g = gaussian_window(window, dtype=dtype).to(device)
        self.pad = window // 2
        self.channels = channels
        self.kh = g.view(1, 1, 1, window).repeat(channels, 1, 1, 1)  # along W
        self.kv = g.view(1, 1, window, 1).repeat(channels, 1, 1, 1)  # along H

    def __call__(self, t: torch.Tensor) -> torch.Tensor:
        p = self.pad
        padded = F.pad(t, (p, p, p, p), mode="reflect")
        return F.conv2d(F.conv2d(padded, self.kh, groups=self.channels), self.kv, groups=self.channels)

    def adjoint(self, g: torch.Tensor) -> torch.Tensor:
        padded = F.conv_transpose2d(F.conv_transpose2d(g, self.kv, groups=self.channels), self.kh,
                                    groups=self.channels)
        return _fold_reflect(_fold_reflect(padded, 3, self.pad), 2, self.pad)


@functools.lru_cache(maxsize=16)
def _blur(window: int, channels: int, height: int, width: int, dtype, device) -> _Blur:
    """One `_Blur` per shape, built once (training calls the loss with one shape every step)."""
    return _Blur(window, channels, height, width, dtype, device)


class _FusedDssim(torch.autograd.Function):
    @staticmethod
    def forward(ctx, pred: torch.Tensor, target: torch.Tensor, window: int) -> torch.Tensor:
        x, y = pred.detach(), target.detach()
        c = x.shape[1]
        blur = _blur(window, 5 * c, x.shape[2], x.shape[3], x.dtype, x.device)
        mu_x, mu_y, e_xx, e_yy, e_xy = blur(torch.cat([x, y, x * x, y * y, x * y], dim=1)).split(c, dim=1)
        a1 = 2 * mu_x * mu_y + C1
        a2 = 2 * (e_xy - mu_x * mu_y) + C2
        b1 = mu_x * mu_x + mu_y * mu_y + C1
        b2 = (e_xx - mu_x * mu_x) + (e_yy - mu_y * mu_y) + C2
        d = b1 * b2 + EPS
        s = a1 * a2 / d
        if pred.requires_grad:
            d_mu = (2 * mu_y * (a2 - a1) - 2 * mu_x * s * (b2 - b1)) / d
            d_exx = -s * b1 / d
            d_exy = 2 * a1 / d
            adj = _blur(window, 3 * c, x.shape[2], x.shape[3], x.dtype, x.device)
            g_mu, g_xx, g_xy = adj.adjoint(torch.cat([d_mu, d_exx, d_exy], dim=1)).split(c, dim=1)
            # d(1 - mean S)/dx
            ctx.save_for_backward(-(g_mu + 2 * x * g_xx + y * g_xy) / s.numel())
        return 1 - s.mean()

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        (grad,) = ctx.saved_tensors
        return grad_out * grad, None, None


def dssim(pred: torch.Tensor, target: torch.Tensor, window: int = 11) -> torch.Tensor:
    """``1 − mean SSIM`` of [B, C, H, W] images in [0, 1] (kornia's SSIM, ``max_val = 1``),
    a scalar differentiable in ``pred`` (fused: the gradient is formed in the forward pass)."""
    if pred.shape != target.shape or pred.dim() != 4:
        from splatbench.errors import InputError

        raise InputError(f"dssim: expected two [B, C, H, W] images of one shape, got {list(pred.shape)} and "
                         f"{list(target.shape)}")
    return _FusedDssim.apply(pred, target.to(pred.dtype), window)


__all__ = ["dssim", "gaussian_window"]
