"""Image metrics for evaluation: PSNR, SSIM (kornia) and, when available offline, LPIPS.

LPIPS needs the ``lpips`` package *and* its backbone weights already on disk (the
torchvision AlexNet checkpoint in torch's hub cache); nothing is ever downloaded.
When either is missing, `lpips_metric` returns None and a note saying why.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

#: The torchvision AlexNet checkpoint LPIPS("alex") loads (torch hub cache, never fetched here).
ALEXNET_CHECKPOINT = "alexnet-owt-7be5be79.pth"


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
    """Mean SSIM (``kornia.metrics.ssim``: Gaussian window 11, σ = 1.5) of [H, W, 3]
    images, ``pred`` clamped to [0, 1]."""
    import kornia  # late: kornia takes a second to import and only evaluation needs it

    with torch.no_grad():
        return float(kornia.metrics.ssim(to_bchw(pred.clamp(0, 1)), to_bchw(target), window, max_val=1.0).mean())


def lpips_metric() -> tuple[Callable[[torch.Tensor, torch.Tensor], float] | None, str]:
    """``(fn, note)``: ``fn(pred, target) -> float`` (LPIPS-Alex, lower is better) or None
    when the ``lpips`` package or its weights are not available offline; ``note`` says which."""
    try:
        import lpips  # noqa: F401
    except ImportError:
        return None, "LPIPS skipped: the 'lpips' package is not installed"
    checkpoint = Path(torch.hub.get_dir()) / "checkpoints" / ALEXNET_CHECKPOINT
    if not checkpoint.is_file():
        return None, f"LPIPS skipped: backbone weights {checkpoint} are not on disk (no download at run time)"
    try:
        model = lpips.LPIPS(net="alex", verbose=False).eval()
    except Exception as exc:  # any load failure: report, never fetch
        return None, f"LPIPS skipped: cannot load the model offline ({type(exc).__name__}: {exc})"

    def fn(pred: torch.Tensor, target: torch.Tensor) -> float:
        with torch.no_grad():
            return float(model(to_bchw(pred.clamp(0, 1)) * 2 - 1, to_bchw(target) * 2 - 1).mean())

    return fn, "LPIPS (AlexNet)"


__all__ = ["psnr", "ssim_metric", "lpips_metric", "to_bchw"]
