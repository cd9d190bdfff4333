"""Random-cotangent VJPs of the fast rasterizer (shared by the gradient and golden tests)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

import splatbench
from splatbench.backends.compare_measure import Cotangents  # the one random-cotangent helper

GROUPS = ("means", "log_scales", "quats", "opacity_logits", "sh")


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
