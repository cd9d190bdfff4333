"""D-SSIM ``1 - mean SSIM``, the training loss's SSIM term, with its gradient formed in the
forward pass (`splatbench.metrics.ssim.ssim_map`: kornia's SSIM computed by Dr.Jit where
the rasterizer runs, the same SSIM as the evaluation metric); autograd's backward only
scales that gradient. `tests/test_losses.py` checks value and gradient against kornia's.
"""

from __future__ import annotations

import torch

from splatbench.metrics.ssim import gaussian_window, ssim_map


class _FusedDssim(torch.autograd.Function):
    @staticmethod
    def forward(ctx, pred: torch.Tensor, target: torch.Tensor, window: int) -> torch.Tensor:
        s, grad = ssim_map(pred, target, window, grad=pred.requires_grad)
        if grad is not None:
            ctx.save_for_backward(grad)  # d(1 - mean S)/dx
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
