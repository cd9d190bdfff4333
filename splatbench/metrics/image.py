"""Image metrics for evaluation: PSNR and SSIM (`splatbench.metrics.ssim`: kornia's SSIM). LPIPS:
`splatbench.metrics.perceptual`."""

from __future__ import annotations

import math

import numpy as np
import torch


def to_bchw(image: torch.Tensor) -> torch.Tensor:
    """[H, W, 3] -> [1, 3, H, W] (a view)."""
    return image.permute(2, 0, 1).unsqueeze(0)


def psnr(pred: torch.Tensor | np.ndarray, target: torch.Tensor | np.ndarray, *, clamp: bool = True) -> float:
    """PSNR in dB (peak 1) of [H, W, 3] images; inf if equal. The one PSNR of splatbench.

    Tensors or arrays (arrays are computed in their own dtype, e.g. float64). ``pred`` is
    clamped to [0, 1] (an evaluation of a trained model's display image) unless
    ``clamp=False`` (the raster run kind compares unclipped radiance with the exact model).
    """
    pred, target = torch.as_tensor(pred), torch.as_tensor(target)
    mse = float((((pred.clamp(0, 1) if clamp else pred) - target) ** 2).mean())
    return math.inf if mse == 0 else -10.0 * math.log10(mse)


def ssim_metric(pred: torch.Tensor, target: torch.Tensor, window: int = 11) -> float:
    """Mean SSIM (kornia's ``kornia.metrics.ssim``: Gaussian window 11, σ = 1.5, computed by
    `splatbench.metrics.ssim.ssim_map`) of [H, W, 3] images, ``pred`` clamped to [0, 1]."""
    from splatbench.metrics.ssim import ssim_map  # late: Dr.Jit, which only evaluation needs here

    with torch.no_grad():
        s, _ = ssim_map(to_bchw(pred.clamp(0, 1)), to_bchw(target), window)
        return float(s.mean())


__all__ = ["psnr", "ssim_metric", "to_bchw"]
