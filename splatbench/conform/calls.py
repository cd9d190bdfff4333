"""The backend side of `splatbench conform`: render a probe scene, take a VJP, report faults in one line."""

from __future__ import annotations

import contextlib
import inspect
import io
import os
import sys
import tempfile
import traceback

import numpy as np

from splatbench.backends.base import Backend, as_numpy
from splatbench.conform.oracle import stack
from splatbench.gaussians import GROUPS
from splatbench.render_inputs import RenderInput

COTANGENT_SEED = 1234
OUTPUT_CHANNELS = {"rgb": slice(0, 3), "alpha": slice(3, 4), "depth": slice(4, 5)}


class Captured:
    """What was written to stdout and stderr inside `captured` (``.text``, set on exit)."""

    text = ""


@contextlib.contextmanager
def captured():
    """Capture everything written to stdout and stderr, by Python or by native code (file descriptors
    1 and 2), so a backend's prints stay out of conform's table and JSON."""
    box = Captured()
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.redirect_stderr(io.StringIO()) as err:
                try:
                    yield box
                finally:
                    box.text = out.getvalue() + err.getvalue()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            box.text = sink.read().decode("utf-8", "replace") + box.text


class Fault(Exception):
    """The backend misbehaved (raised, wrong shape, NaN): the probe fails with this one line.

    ``usage``: the fault says the backend was wired up wrong (its signature cannot take conform's call,
    it returns other than three outputs of the right shapes), not that it computes something wrong:
    conform stops on it (exit 2) instead of reporting it as a defect of every probe."""

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
    """Raise a usage `Fault` when the backend's function cannot be called as conform calls it:
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


def param_tensors(s: RenderInput, device: str, grad: bool) -> list:
    """The five parameter groups of ``s`` as float32 torch tensors on ``device``, in a backend's argument
    order, leaves that require grad when ``grad``."""
    import torch

    return [torch.tensor(getattr(s, k), dtype=torch.float32, device=device, requires_grad=grad) for k in GROUPS]


def _render(backend: Backend, s: RenderInput, params: list):
    """The backend's (rgb, alpha, depth) as given, after checks of shape and values."""
    try:
        out = backend(*params, s.camera, sh_degree=s.sh_degree, background=s.background)
    except Exception as exc:  # noqa: BLE001 - any failure of user code is a probe failure, reported in one line
        raise Fault(raised(exc)) from None
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        what = f"{type(out).__name__} of {len(out)}" if isinstance(out, (tuple, list)) else type(out).__name__
        raise Fault(f"backend returned a {what}, expected the 3 outputs (rgb, alpha, depth)", usage=True)
    H, W = s.camera.height, s.camera.width
    for name, x, shape in zip(("rgb", "alpha", "depth"), out, ((H, W, 3), (H, W), (H, W))):
        got = tuple(getattr(x, "shape", ()))
        if got != shape:
            raise Fault(f"{name}: shape {list(got)}, expected {list(shape)} (H={H}, W={W})", usage=True)
    return out


def outputs(backend: Backend, s: RenderInput, device: str) -> np.ndarray:
    import torch

    with torch.no_grad():
        out = stack([as_numpy(x) for x in _render(backend, s, param_tensors(s, device, False))])
    bad = ~np.isfinite(out)
    if bad.any():
        i, j, c = (int(k) for k in np.argwhere(bad)[0])
        raise Fault(f"non-finite {_channel_name(c)} at pixel (row {i}, col {j})")
    return out


def _channel_name(c: int) -> str:
    return ("rgb", "rgb", "rgb", "alpha", "depth")[c]


def cotangents(s: RenderInput, outputs: tuple[str, ...]) -> np.ndarray:
    """Seeded normal cotangents [H, W, 5]; zero for outputs the backend does not produce."""
    v = np.random.default_rng(COTANGENT_SEED).standard_normal((s.camera.height, s.camera.width, 5))
    for name, sl in OUTPUT_CHANNELS.items():
        if name not in outputs:
            v[..., sl] = 0.0
    return v


def vjp(backend: Backend, s: RenderInput, v: np.ndarray, device: str) -> dict[str, np.ndarray]:
    import torch

    params = param_tensors(s, device, True)
    out = _render(backend, s, params)
    if not all(isinstance(x, torch.Tensor) for x in out) or not any(x.requires_grad for x in out):
        if all(isinstance(x, torch.Tensor) and not x.detach().any() for x in out):
            raise Fault("the backend drew nothing on this scene (every output zero), so its outputs carry no "
                        "autograd graph: a cull, not a missing backward")
        raise Fault("outputs carry no autograd graph (declare gradients=False if the backend has none)")
    loss = sum((x.double() * torch.as_tensor(v[..., sl].reshape(x.shape), device=x.device)).sum()
               for x, sl in zip(out, OUTPUT_CHANNELS.values()) if x.requires_grad)
    try:
        loss.backward()
    except Exception as exc:  # noqa: BLE001
        raise Fault(raised(exc, "backward raised")) from None
    grads = {k: np.zeros(p.shape) if p.grad is None else as_numpy(p.grad) for k, p in zip(GROUPS, params)}
    for k, g in grads.items():
        if not np.isfinite(g).all():
            raise Fault(f"non-finite gradient of {k}")
    return grads


