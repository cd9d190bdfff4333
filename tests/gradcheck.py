"""Random-cotangent VJPs of the fast rasterizer (shared by the gradient and golden tests)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

import splatbench

GROUPS = ("means", "log_scales", "quats", "opacity_logits", "sh")


@dataclass(frozen=True)
class Cotangents:
    """v_rgb [H, W, 3], v_alpha [H, W], v_depth [H, W] (float64)."""

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray

    @classmethod
    def random(cls, seed: int, height: int, width: int) -> Cotangents:
        rng = np.random.default_rng(seed)
        return cls(rng.standard_normal((height, width, 3)), rng.standard_normal((height, width)),
                   rng.standard_normal((height, width)))

    def loss(self, rgb, alpha, depth):
        """sum(v . output) for numpy or torch outputs."""
        if isinstance(rgb, torch.Tensor):
            t = lambda a: torch.as_tensor(a, dtype=rgb.dtype)  # noqa: E731
            return (rgb * t(self.rgb)).sum() + (alpha * t(self.alpha)).sum() + (depth * t(self.depth)).sum()
        return float((rgb * self.rgb).sum() + (alpha * self.alpha).sum() + (depth * self.depth).sum())


@dataclass(frozen=True)
class VJP:
    """Outputs of one render and the gradient of sum(v . output) for each group."""

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    grads: dict[str, np.ndarray]


def fast_vjp(workload, v: Cotangents, **options) -> VJP:
    g = workload.gaussians
    params = [torch.tensor(getattr(g, k), requires_grad=True) for k in GROUPS]
    rgb, alpha, depth, _ = splatbench.rasterize(*params, workload.camera, **options)
    v.loss(rgb, alpha, depth).backward()
    return VJP(rgb.detach().numpy(), alpha.detach().numpy(), depth.detach().numpy(),
               {k: p.grad.numpy().copy() for k, p in zip(GROUPS, params)})
