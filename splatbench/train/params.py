"""Gaussians <-> torch parameter groups, one Adam per group, the position schedule.

Groups (`splatbench.strategies.base.PARAM_GROUPS`): means [N, 3], log_scales [N, 3],
quats [N, 4], opacity_logits [N], sh_dc [N, 1, 3], sh_rest [N, K-1, 3]. Each is a
leaf ``torch.nn.Parameter``; a group whose learning rate is 0 is frozen
(``requires_grad=False``), so the rasterizer does no gradient work for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from splatbench.gaussians import Gaussians
from splatbench.strategies.base import PARAM_GROUPS, Optimizers, Params
from splatbench.train.adam import FusedAdam


def params_from_gaussians(gaussians: Gaussians, lrs: dict[str, float],
                          device: torch.device | str = "cpu") -> Params:
    """Torch leaf tensors per group (float32, on torch ``device``); groups with ``lrs[name] == 0``
    are frozen."""
    sh = torch.from_numpy(np.array(gaussians.sh, dtype=np.float32))
    arrays = {
        "means": torch.from_numpy(np.array(gaussians.means, dtype=np.float32)),
        "log_scales": torch.from_numpy(np.array(gaussians.log_scales, dtype=np.float32)),
        "quats": torch.from_numpy(np.array(gaussians.quats, dtype=np.float32)),
        "opacity_logits": torch.from_numpy(np.array(gaussians.opacity_logits, dtype=np.float32)),
        "sh_dc": sh[:, :1].contiguous(),
        "sh_rest": sh[:, 1:].contiguous(),
    }
    return {name: torch.nn.Parameter(arrays[name].to(device), requires_grad=lrs[name] > 0) for name in PARAM_GROUPS}


def gaussians_from_params(params: Params, sh_degree: int | None = None) -> Gaussians:
    """The current Gaussians as numpy; ``sh_degree`` truncates SH to that many bands."""
    sh = torch.cat([params["sh_dc"], params["sh_rest"]], dim=1).detach()
    if sh_degree is not None:
        sh = sh[:, : (sh_degree + 1) ** 2]
    host = {name: params[name].detach().cpu().numpy() for name in ("means", "log_scales", "quats", "opacity_logits")}
    return Gaussians(**host, sh=sh.cpu().numpy())


def make_optimizers(params: Params, lrs: dict[str, float], eps: float) -> Optimizers:
    """One Adam per group (3DGS: eps 1e-15), holding exactly ``params[name]``.

    Frozen groups get an optimizer too (strategies edit every group's moments
    together); it never steps their tensor, which never has a gradient. The update
    is torch's fused Adam kernel (one pass over each tensor; on the CPU about 4x faster
    than the default per-tensor update at 20,000 Gaussians, docs/training.md
    "Throughput"), called by `splatbench.train.adam.FusedAdam`: bit-identical to
    ``torch.optim.Adam(fused=True)`` without the ~70 MB that ``torch.optim`` pulls in
    (``torch._dynamo``), equal to the default Adam's to float32 rounding and as deterministic.
    """
    return {name: FusedAdam(params[name], lr=lrs[name], eps=eps, name=name) for name in PARAM_GROUPS}


def refreeze(params: Params, lrs: dict[str, float]) -> None:
    """Keep frozen groups frozen after a strategy replaced their tensors."""
    for name in PARAM_GROUPS:
        if lrs[name] == 0 and params[name].requires_grad:
            params[name].requires_grad_(False)


@dataclass(frozen=True)
class ExponentialLR:
    """3DGS's position schedule: log-linear from ``initial`` to ``final`` over ``steps``,
    both multiplied by ``scale`` (the scene extent). ``initial == 0`` (frozen) is always
    0; otherwise both must be > 0 (`TrainConfig.validate` checks it)."""

    initial: float   # learning rate at step 0 (before scaling)
    final: float     # learning rate at step ``steps`` (before scaling)
    steps: int       # length of the decay (the run's iterations)
    scale: float = 1.0  # multiplier (scene extent)

    def __call__(self, step: int) -> float:
        if self.initial == 0:
            return 0.0
        t = min(max(step / max(self.steps, 1), 0.0), 1.0)
        return self.scale * math.exp((1 - t) * math.log(self.initial) + t * math.log(self.final))


def set_lr(optimizer: FusedAdam, lr: float) -> None:
    for group in optimizer.param_groups:
        group["lr"] = lr


def scene_extent(cameras) -> float:
    """3DGS's ``cameras_extent``: 1.1 x the largest distance of a camera centre from their mean."""
    centres = np.stack([c.center for c in cameras]).astype(np.float64)
    radius = float(np.linalg.norm(centres - centres.mean(axis=0), axis=1).max())
    return 1.1 * radius if radius > 0 else 1.0


__all__ = ["params_from_gaussians", "gaussians_from_params", "make_optimizers", "refreeze", "ExponentialLR",
           "set_lr", "scene_extent"]
