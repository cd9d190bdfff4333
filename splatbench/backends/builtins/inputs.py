"""Validation at the boundary of the torch-facing built-in backends (torch, gsplat, mitsuba)."""

from __future__ import annotations

from typing import NamedTuple

from splatbench.backends.base import GROUPS
from splatbench.guards import check_finite, check_shape
from splatbench.errors import InputError
from splatbench.raster.pipeline import check_background, check_sh_range, resolve_sh_degree

SPECS = (("N", 3), ("N", 3), ("N", 4), ("N",), ("N", None, 3))


class Checked(NamedTuple):
    sh_degree: int                            # validated against sh's K bases
    background: tuple[float, float, float]    # RGB, black when None was given


def check_inputs(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None,
                 background=None) -> Checked:
    """Raise a one-line `InputError` naming the field unless the backend signature's inputs are valid.

    Shapes as in `splatbench.backends.base`; every value finite; |sh| within the supported range.
    """
    import torch

    from splatbench.cameras import Camera

    sizes: dict[str, int] = {}
    for name, t, spec in zip(GROUPS, (means, log_scales, quats, opacity_logits, sh), SPECS):
        if not isinstance(t, torch.Tensor):
            raise InputError(f"{name}: expected a torch.Tensor, got {type(t).__name__}")
        if not t.is_floating_point():
            raise InputError(f"{name}: expected a floating-point tensor, got dtype {t.dtype}")
        check_shape(name, tuple(t.shape), spec, sizes)
        if not bool(torch.isfinite(t.detach()).all()):
            check_finite(name, t.detach().cpu().numpy())
    if not isinstance(camera, Camera):
        raise InputError(f"camera: expected a splatbench.Camera, got {type(camera).__name__}")
    degree = resolve_sh_degree(sh.shape[1], sh_degree)
    if sh.numel():
        flat = int(sh.detach().abs().argmax())
        index = [int(i) for i in torch.unravel_index(torch.tensor(flat), tuple(sh.shape))]
        check_sh_range(float(sh.detach().reshape(-1)[flat].abs()), index)
    return Checked(degree, check_background(background))
