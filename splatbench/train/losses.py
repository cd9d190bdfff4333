"""The 3DGS photometric loss: ``(1 - λ) · L1 + λ · (1 − SSIM)`` (λ = 0.2, window 11).

SSIM is kornia's (``kornia.metrics.ssim``: Gaussian window, σ = 1.5, "same"
padding; computed by `splatbench.metrics.ssim`), averaged over pixels and channels.
Images are [H, W, 3] in [0, 1]. The loss's D-SSIM term is `splatbench.train.dssim.dssim`,
the same value with its gradient formed in one fused pass (tested against kornia's);
the SSIM metric is `splatbench.metrics.image.ssim_metric` (the same SSIM).
"""

from __future__ import annotations

import torch

from splatbench.metrics.image import to_bchw
from splatbench.train.dssim import dssim


def photometric_loss(pred: torch.Tensor, target: torch.Tensor, ssim_lambda: float = 0.2,
                     window: int = 11) -> torch.Tensor:
    """``(1 - ssim_lambda) · mean|pred − target| + ssim_lambda · (1 − SSIM(pred, target))``.

    Args:
        pred: [H, W, 3] rendered image (differentiable).
        target: [H, W, 3] ground truth.
    """
    l1 = (pred - target).abs().mean()
    if ssim_lambda == 0:
        return l1
    return (1 - ssim_lambda) * l1 + ssim_lambda * dssim(to_bchw(pred), to_bchw(target), window)


__all__ = ["photometric_loss"]
