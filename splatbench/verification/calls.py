"""Running a backend for a check: its forward and its VJP, every fault in one line.

compare, conform and regress call a rasterizer plugin (`splatbench.backends.Backend`) through
these: `render` (the checked call: an exception, other than three outputs or a wrong shape is a
`Fault`), `forward` (the outputs as float64 numpy, NaN refused with the pixel), `vjp` (the
gradient of sum(v . outputs) for `Cotangents` v, per parameter group). A `Fault` is one line
naming what went wrong and, for an exception, the innermost frame of its traceback.
"""

from __future__ import annotations

import inspect
import traceback
from collections.abc import Sequence

import numpy as np

from splatbench.backends.base import OUTPUTS, Backend, as_numpy
from splatbench.gaussians import GROUPS
from splatbench.render_inputs import RenderInput
from splatbench.verification.cotangents import Cotangents

#: The output of each channel of a stacked [H, W, 5] image.
CHANNEL_OUTPUTS = ("rgb", "rgb", "rgb", "alpha", "depth")


class Fault(Exception):
    """The backend misbehaved (raised, wrong shape, NaN): the check fails with this one line.

    ``usage``: the fault says the backend was wired up wrong (its signature cannot take the call,
    it returns other than three outputs of the right shapes), not that it computes something wrong:
    conform and regress stop on it (exit 2) instead of reporting it as a defect of every scene."""

    def __init__(self, message: str, *, usage: bool = False):
        super().__init__(message)
        self.usage = usage


def last_frame(exc: BaseException) -> str:
    """" (at FILE:LINE in FUNCTION)" of the innermost frame of ``exc``'s traceback ("" when it has none)."""
    frames = traceback.extract_tb(exc.__traceback__)
    if not frames:
        return ""
    f = frames[-1]
    return f" (at {f.filename}:{f.lineno} in {f.name})"


def raised(exc: BaseException, what: str = "backend raised") -> str:
    """``"backend raised ExcType: first line (at FILE:LINE in FUNCTION)"``: a backend's exception in one line."""
    first = (str(exc).strip().splitlines() or [""])[0]
    return f"{what} {type(exc).__name__}: {first}".rstrip(": ") + last_frame(exc)


def check_signature(backend: Backend) -> None:
    """Raise a usage `Fault` when the backend's function cannot be called as the checks call it:
    fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=, background=)."""
    try:
        sig = inspect.signature(backend.fn)
    except (TypeError, ValueError):  # no signature to read (a C function): the call itself will tell
        return
    try:
        sig.bind(*([None] * 6), sh_degree=None, background=None)
    except TypeError as exc:
        raise Fault(f"its signature {sig} cannot be called as fn(means, log_scales, quats, opacity_logits, sh, "
                    f"camera, *, sh_degree=, background=) ({exc})", usage=True) from None


def param_tensors(s: RenderInput, device: str) -> list:
    """The five parameter groups of ``s`` as float32 torch tensors on ``device``, in a backend's argument order."""
    import torch

    return [torch.tensor(getattr(s, k), dtype=torch.float32, device=device) for k in GROUPS]


def stack(out) -> np.ndarray:
    """rgb [H, W, 3], alpha [H, W], depth [H, W] -> [H, W, 5] float64 (`CHANNEL_OUTPUTS`)."""
    rgb, alpha, depth = (np.asarray(x, dtype=np.float64) for x in out)
    return np.concatenate([rgb, alpha[..., None], depth[..., None]], axis=-1)


def render(backend: Backend, params: Sequence, camera, *, sh_degree: int | None = None,
           background: tuple[float, float, float] | None = None) -> tuple:
    """The backend's (rgb, alpha, depth) as it returns them, after checks of their number and shapes."""
    try:
        out = backend(*params, camera, sh_degree=sh_degree, background=background)
    except Exception as exc:  # noqa: BLE001 - any failure of user code is a finding about it, in one line
        raise Fault(raised(exc)) from None
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        what = f"{type(out).__name__} of {len(out)}" if isinstance(out, (tuple, list)) else type(out).__name__
        raise Fault(f"backend returned a {what}, expected the 3 outputs (rgb, alpha, depth)", usage=True)
    H, W = camera.height, camera.width
    for name, x, shape in zip(OUTPUTS, out, ((H, W, 3), (H, W), (H, W))):
        got = tuple(getattr(x, "shape", ()))
        if got != shape:
            raise Fault(f"{name}: shape {list(got)}, expected {list(shape)} (H={H}, W={W})", usage=True)
    return out


def forward(backend: Backend, s: RenderInput, device: str, outputs: Sequence[str] = OUTPUTS) -> np.ndarray:
    """The backend's outputs on ``s`` without gradients, stacked [H, W, 5] float64 (`stack`); a non-finite
    value of one of ``outputs`` is a `Fault` naming the first such pixel."""
    import torch

    with torch.no_grad():
        out = stack([as_numpy(x) for x in render(backend, param_tensors(s, device), s.camera,
                                                  sh_degree=s.sh_degree, background=s.background)])
    bad = ~np.isfinite(out)
    bad[..., [c for c, name in enumerate(CHANNEL_OUTPUTS) if name not in outputs]] = False
    if bad.any():
        i, j, c = (int(k) for k in np.argwhere(bad)[0])
        raise Fault(f"non-finite {CHANNEL_OUTPUTS[c]} at pixel (row {i}, col {j})")
    return out


def vjp(backend: Backend, params: Sequence, camera, v: Cotangents, *, sh_degree: int | None = None,
        background: tuple[float, float, float] | None = None) -> dict[str, np.ndarray]:
    """Gradient of sum(v . outputs) for each parameter group (float64 numpy; zeros where the backend
    gives none), taken on leaf copies of ``params`` (torch tensors of any dtype and device). A backend
    that raises, or whose outputs carry no autograd graph, is a `Fault`; the gradients are returned as
    they are (`finite_gradients` refuses NaN)."""
    import torch

    leaves = [p.detach().clone().requires_grad_(True) for p in params]
    out = render(backend, leaves, camera, sh_degree=sh_degree, background=background)
    if not all(isinstance(x, torch.Tensor) for x in out) or not any(x.requires_grad for x in out):
        if all(isinstance(x, torch.Tensor) and not x.detach().any() for x in out):
            raise Fault("the backend drew nothing on this scene (every output zero), so its outputs carry no "
                        "autograd graph: a cull, not a missing backward")
        raise Fault("outputs carry no autograd graph (declare gradients=False if the backend has none)")
    try:
        v.loss(*out).backward()
    except Exception as exc:  # noqa: BLE001
        raise Fault(raised(exc, "backward raised")) from None
    return {k: (np.zeros(p.shape) if p.grad is None else as_numpy(p.grad)) for k, p in zip(GROUPS, leaves)}


def finite_gradients(grads: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``grads`` unchanged, or a `Fault` naming the first group with a non-finite entry."""
    for k, g in grads.items():
        if not np.isfinite(g).all():
            raise Fault(f"non-finite gradient of {k}")
    return grads
