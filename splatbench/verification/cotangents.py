"""The random cotangents of every gradient check: the one place they are drawn.

A gradient check takes the VJP of loss = sum(v . outputs) for seeded standard normal
cotangents v: random v make the per-pixel terms of a gradient entry cancel, so a wrong term
shows (`splatbench.verification.bounds.gradient_bound`). compare, conform, regress, stress and
the rasterizer's own gradient tests draw them here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from splatbench.backends.base import OUTPUTS
from splatbench.verification.bounds import DEPTH_ALPHA_MIN

#: Output channels of a stacked [H, W, 5] image (rgb, alpha, depth), as conform's oracle keeps them.
OUTPUT_CHANNELS = {"rgb": slice(0, 3), "alpha": slice(3, 4), "depth": slice(4, 5)}


@dataclass(frozen=True)
class Cotangents:
    """v_rgb [H, W, 3], v_alpha [H, W], v_depth [H, W] (float64; zero for undeclared outputs)."""

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray

    @classmethod
    def standard_normal(cls, seed: int | Sequence[int], height: int, width: int) -> Cotangents:
        """Every entry standard normal, drawn rgb, alpha, depth from one ``np.random.default_rng(seed)``."""
        rng = np.random.default_rng(seed)
        return cls(rng.standard_normal((height, width, 3)), rng.standard_normal((height, width)),
                   rng.standard_normal((height, width)))

    @classmethod
    def random(cls, seed: int | Sequence[int], height: int, width: int, outputs: Sequence[str] = OUTPUTS, *,
               alpha: np.ndarray | None = None) -> Cotangents:
        """`standard_normal`, zero for the outputs not in ``outputs``; with ``alpha`` [H, W] (the
        oracle's or a reference's), v_depth kept only where alpha > `DEPTH_ALPHA_MIN` (depth = sum /
        alpha amplifies alpha's error by 1 / alpha, so depth is weighted only where it is defined)."""
        n = cls.standard_normal(seed, height, width)
        v = {"rgb": n.rgb, "alpha": n.alpha,
             "depth": n.depth if alpha is None else n.depth * (alpha > DEPTH_ALPHA_MIN)}
        return cls(*(v[k] if k in outputs else np.zeros_like(v[k]) for k in OUTPUTS))

    def stacked(self) -> np.ndarray:
        """[H, W, 5]: rgb, alpha, depth along the last axis (`OUTPUT_CHANNELS`)."""
        return np.concatenate([self.rgb, self.alpha[..., None], self.depth[..., None]], axis=-1)

    def loss(self, rgb, alpha, depth):
        """sum(v . outputs) for torch or numpy outputs (torch: v cast to each output's dtype and device,
        so the gradient handed to the backend's backward is v in its own precision)."""
        if hasattr(rgb, "detach"):
            import torch

            t = lambda a, like: torch.as_tensor(a, dtype=like.dtype, device=like.device)  # noqa: E731
            return (rgb * t(self.rgb, rgb)).sum() + (alpha * t(self.alpha, alpha)).sum() \
                + (depth * t(self.depth, depth)).sum()
        return float((rgb * self.rgb).sum() + (alpha * self.alpha).sum() + (depth * self.depth).sum())
