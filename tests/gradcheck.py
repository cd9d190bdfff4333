"""Random-cotangent VJPs of the fast rasterizer (shared by the gradient and golden tests)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from splatbench.backends.base import GROUPS
from splatbench.raster.options import RasterOptions
from splatbench.verification.cotangents import Cotangents  # the one random-cotangent helper
from splatbench.raster.hooks import NO_HOOKS, Hooks
from splatbench.raster.torch_bridge import rasterize_with_hooks


@dataclass(frozen=True)
class VJP:
    """Outputs of one render and the gradient of sum(v . output) for each group."""

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    grads: dict[str, np.ndarray]


#: Keyword arguments of `rasterize` itself; every other keyword of `fast_vjp` is a `RasterOptions` field.
CALL_KEYS = ("sh_degree", "background", "absgrad")


def fast_vjp(workload, v: Cotangents, hooks: Hooks = NO_HOOKS, **options) -> VJP:
    """``hooks``: e.g. ``Hooks(loop_ad=True)``, Dr.Jit's loop AD instead of the hand-written backward;
    ``options``: `CALL_KEYS` go to the call, the rest into its `RasterOptions`."""
    g = workload.gaussians
    params = [torch.tensor(getattr(g, k), requires_grad=True) for k in GROUPS]
    call = {k: v for k, v in options.items() if k in CALL_KEYS}
    raster = RasterOptions(**{k: v for k, v in options.items() if k not in CALL_KEYS})
    rgb, alpha, depth, _ = rasterize_with_hooks(*params, workload.camera, hooks, options=raster, **call)
    v.loss(rgb, alpha, depth).backward()
    return VJP(rgb.detach().numpy(), alpha.detach().numpy(), depth.detach().numpy(),
               {k: p.grad.numpy().copy() for k, p in zip(GROUPS, params)})
