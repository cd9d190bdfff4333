"""`splatbench.rasterize`: the differentiable entry point for torch.

A `torch.autograd.Function` runs the Dr.Jit pipeline with AD enabled on the inputs
that need gradients (a frozen group costs no gradient work), keeps the Dr.Jit
graph alive until torch's backward, then seeds the outputs' cotangents and
traverses the graph back to the inputs.

Tensors cross between torch and Dr.Jit through DLPack, without a copy and without a
host round trip: Dr.Jit arrays built from the parameter tensors alias their memory
(on the CPU and on CUDA alike), and the gradients handed to torch alias Dr.Jit's.
Torch's saved-tensor check makes an in-place change of a parameter between the
forward and the backward pass an error instead of a silently wrong gradient.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch

from splatbench.errors import InputError
from splatbench.raster.device import Device, dr, get_device
from splatbench.raster.hooks import NO_HOOKS, Hooks
from splatbench.raster.options import RasterOptions
from splatbench.raster.pipeline import (SH_ABS_MAX, Frame, check_background, check_options, check_view, check_sh_range,
                                       render_frame, resolve_sh_degree)
from splatbench.guards import check_finite, check_shape

if TYPE_CHECKING:
    from splatbench.cameras import Camera

PARAMS = ("means", "log_scales", "quats", "opacity_logits", "sh")


@dataclass
class RasterInfo:
    """What densification needs from one rasterized view.

    radii [N] int32 (0 = culled); visible [N] bool; width, height; num_pairs;
    sh_degree. After ``loss.backward()``: ``means2d_grad`` [N, 2], the gradient of the
    loss with respect to the screen-space means (pixels), and ``means2d_absgrad``
    [N, 2], the per-pixel absolute values summed (AbsGS). Both are None before, and
    ``means2d_grad`` stays None when ``means`` does not require grad and ``absgrad`` is
    off (a frozen group costs no work in the compositing backward).
    """

    radii: torch.Tensor    # [N] int32
    visible: torch.Tensor  # [N] bool
    width: int
    height: int
    num_pairs: int
    sh_degree: int
    _frame: Frame | None = field(default=None, repr=False)

    @property
    def means2d_grad(self) -> torch.Tensor | None:
        grad = self._frame.state.grad_means2d if self._frame is not None else None
        return None if grad is None else torch.from_numpy(np.array(grad.numpy(), dtype=np.float32).T.copy())

    @property
    def means2d_absgrad(self) -> torch.Tensor | None:
        grad = self._frame.state.abs_grad_means2d if self._frame is not None else None
        return None if grad is None else torch.from_numpy(np.array(grad.numpy(), dtype=np.float32).T.copy())


def torch_device(dev: Device) -> torch.device:
    """The torch device whose memory the Dr.Jit ``dev`` can read in place."""
    return torch.device("cuda" if dev.name == "cuda" else "cpu")


def parameter_device(device: str) -> torch.device:
    """Where a caller that renders on ``device`` ("cpu", "cuda", "auto") should keep its torch
    parameters and optimizer state: torch's CUDA device when the rasterizer runs on CUDA and
    this torch has CUDA (no host copy per call: on an H200 the 1M / 800² forward+backward took
    231.9 ms with CPU parameters and 16.4 ms with CUDA ones in one process, and a training step
    at 256² ran x2.77 faster, reports/cuda/README.md 2026-11-28), else the CPU. A CPU-only
    torch beside Dr.Jit's CUDA keeps CPU parameters and copies each call."""
    if torch_device(get_device(device)).type == "cuda" and torch.cuda.is_available():
        return torch.device("cuda")
    return torch.device("cpu")


def to_drjit(dev: Device, t: torch.Tensor):
    """A Dr.Jit tensor viewing ``t`` (moved to ``dev``'s memory and made contiguous
    float32 first only where it is not already: then the copy is what is viewed)."""
    t = t.detach().to(device=torch_device(dev), dtype=torch.float32).contiguous()
    if t.is_cuda:  # torch and Dr.Jit use different CUDA streams: finish torch's writes first
        torch.cuda.synchronize(t.device)
    return dev.t.TensorXf(t)


def to_torch(x) -> torch.Tensor:
    """A torch tensor viewing the Dr.Jit array or tensor ``x`` (evaluated first, and on
    CUDA finished: torch reads it on another stream)."""
    dr.eval(x)
    if dr.backend_v(x) == dr.JitBackend.CUDA:
        dr.sync_thread()
    return torch.from_dlpack(x)


def _new_scope(dev: Device) -> None:
    """Start a new Dr.Jit scope (basic block) on ``dev`` (a `Device`).

    PyTorch runs the backward of CUDA tensors on its own per-device thread, so Dr.Jit
    variables made there and on the caller's thread meet in later calls; Dr.Jit needs a
    new scope at each such hand-over (`drjit.detail.new_scope`), as its own torch
    wrapper (`drjit.interop`) does at both ends of forward and backward."""
    dr.detail.new_scope(dr.JitBackend.CUDA if dev.name == "cuda" else dr.JitBackend.LLVM)


class _Rasterize(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, log_scales, quats, opacity_logits, sh, camera, degree, background, options,
                absgrad, hooks, info_box):
        dev = get_device(options.device)
        _new_scope(dev)
        m = dev.t
        params = (means, log_scales, quats, opacity_logits, sh)
        inputs = [to_drjit(dev, t) for t in params]
        # The Dr.Jit inputs alias these tensors' memory: let torch detect in-place changes.
        ctx.save_for_backward(*params)
        for x, needs in zip(inputs, ctx.needs_input_grad[:5]):
            if needs:
                dr.enable_grad(x)
        frame = render_frame(*inputs, camera, sh_degree=degree, background=background, options=options,
                             absgrad=absgrad, hooks=hooks)
        ctx.timer, ctx.absgrad = hooks.timer, absgrad
        H, W = camera.height, camera.width
        # Outputs live where the parameters do (a no-op when Dr.Jit runs on that device).
        out = means.device
        rgb = to_torch(frame.rgb).T.reshape(H, W, 3).contiguous().to(out)  # Array3f views as [3, H*W]
        alpha = to_torch(frame.alpha).reshape(H, W).to(out)
        depth = to_torch(frame.depth).reshape(H, W).to(out)
        ctx.dr_inputs, ctx.frame, ctx.m, ctx.dev = inputs, frame, m, dev
        ctx.saved_shapes = [tuple(t.shape) for t in (means, log_scales, quats, opacity_logits, sh)]
        ctx.saved_devices = [t.device for t in (means, log_scales, quats, opacity_logits, sh)]
        info_box.append(frame)
        _new_scope(dev)
        return rgb, alpha, depth

    @staticmethod
    def backward(ctx, v_rgb, v_alpha, v_depth):
        m, frame, inputs = ctx.m, ctx.frame, ctx.dr_inputs
        if not any(ctx.needs_input_grad[:5]):
            return (None,) * 12
        _ = ctx.saved_tensors  # raises if a parameter was changed in place since the forward pass
        dev = ctx.dev
        _new_scope(dev)  # this may be torch's autograd thread, not the forward's

        def cotangent(v, shape):
            return to_drjit(dev, v.reshape(shape)).array

        v_rgb = cotangent(v_rgb, (-1, 3))  # [H*W * 3], pixel-major
        pixel = dr.arange(m.UInt32, dr.width(frame.alpha)) * 3
        dr.set_grad(frame.rgb, m.Array3f(*(dr.gather(m.Float, v_rgb, pixel + c) for c in range(3))))
        dr.set_grad(frame.alpha, cotangent(v_alpha, (-1,)))
        dr.set_grad(frame.depth, cotangent(v_depth, (-1,)))
        dr.enqueue(dr.ADMode.Backward, frame.rgb, frame.alpha, frame.depth)
        dr.traverse(dr.ADMode.Backward)
        if ctx.timer is not None:
            dr.eval([dr.grad(x) for x in inputs])
            ctx.timer.mark("backward_preprocess")
        state = frame.state
        if ctx.saved_shapes[0][0] == 0:  # no Gaussians: the compositing op had nothing to differentiate
            empty = m.Array2f(m.Float(), m.Float())
            if ctx.needs_input_grad[0] and state.grad_means2d is None:
                state.grad_means2d = empty
            if ctx.absgrad and state.abs_grad_means2d is None:
                state.abs_grad_means2d = empty
        grads = []
        for x, needs, like, where in zip(inputs, ctx.needs_input_grad[:5], ctx.saved_shapes, ctx.saved_devices):
            if not needs:
                grads.append(None)
                continue
            if math.prod(like) == 0:  # no Gaussians (all pruned): Dr.Jit's grad of an empty array is a scalar
                grads.append(torch.zeros(like, device=where))
                continue
            grads.append(to_torch(dr.grad(x)).reshape(like).to(where))
        ctx.dr_inputs = None  # release the Dr.Jit graph
        _new_scope(dev)
        return (*grads, None, None, None, None, None, None, None)


def _check(name: str, t, spec, sizes) -> float:
    """Validate one parameter tensor; returns its largest |value| (0 when empty).

    One `torch.aminmax` pass (NaN propagates into it) instead of elementwise
    temporaries: at 1M Gaussians, ``sh.abs()`` alone is a 192 MB copy."""
    if not isinstance(t, torch.Tensor):
        raise InputError(f"{name}: expected a torch.Tensor, got {type(t).__name__}")
    if not t.is_floating_point():
        raise InputError(f"{name}: expected a floating-point tensor, got dtype {t.dtype}")
    check_shape(name, tuple(t.shape), spec, sizes)
    if not t.numel():
        return 0.0
    lo, hi = (float(x) for x in torch.aminmax(t.detach()))
    if not (math.isfinite(lo) and math.isfinite(hi)):  # numpy only to name the entry
        check_finite(name, t.detach().cpu().numpy())
    return max(-lo, hi)


def rasterize(
    means: torch.Tensor,           # [N, 3]
    log_scales: torch.Tensor,      # [N, 3]
    quats: torch.Tensor,           # [N, 4] (w, x, y, z)
    opacity_logits: torch.Tensor,  # [N]
    sh: torch.Tensor,              # [N, K, 3], K = (d+1)^2
    camera: Camera,                # width W, height H
    *,
    sh_degree: int | None = None,
    background=None,               # 3 values in [0, 1] (default black)
    absgrad: bool = False,
    options: RasterOptions | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, RasterInfo]:  # [H, W, 3], [H, W], [H, W], info
    """Differentiable 3DGS rasterization of torch tensors through the Dr.Jit pipeline.

    Args:
        means: [N, 3] world positions. log_scales: [N, 3]. quats: [N, 4] (w, x, y, z).
        opacity_logits: [N]. sh: [N, K, 3], K = (d+1)^2 bases.
        camera: `splatbench.Camera` (width W, height H).
        sh_degree: SH bands to evaluate (default: all in ``sh``); higher bands get zero gradient.
        background: RGB behind the splats (default black).
        absgrad: also accumulate ``info.means2d_absgrad`` (AbsGS) in the backward pass.
        options: the rasterizer's `RasterOptions` (None: the defaults).

    Returns:
        rgb [H, W, 3], alpha [H, W], depth [H, W] (float32 torch tensors, differentiable
        with respect to every input with ``requires_grad``), and a `RasterInfo`.
    """
    return rasterize_with_hooks(means, log_scales, quats, opacity_logits, sh, camera, NO_HOOKS, sh_degree=sh_degree,
                                background=background, absgrad=absgrad, options=options)


def rasterize_with_hooks(means, log_scales, quats, opacity_logits, sh, camera, hooks: Hooks, *,
                         sh_degree: int | None = None, background=None, absgrad: bool = False,
                         options: RasterOptions | None = None):
    """`rasterize` with test and benchmark `Hooks` (the gradient tests' and the stage
    timings' entry point; arguments and results as for `rasterize`)."""
    sizes: dict[str, int] = {}
    _check("means", means, ("N", 3), sizes)
    _check("log_scales", log_scales, ("N", 3), sizes)
    _check("quats", quats, ("N", 4), sizes)
    _check("opacity_logits", opacity_logits, ("N",), sizes)
    sh_largest = _check("sh", sh, ("N", None, 3), sizes)
    opts = check_options(options)
    check_view(camera, opts)
    degree = resolve_sh_degree(sh.shape[1], sh_degree)
    if sh_largest > SH_ABS_MAX:  # only then find where (a full |sh| temporary)
        flat = int(sh.detach().abs().argmax())
        check_sh_range(float(sh.detach().reshape(-1)[flat].abs()), np.unravel_index(flat, tuple(sh.shape)))
    bg = check_background(background)
    box: list[Frame] = []  # receives the Dr.Jit frame from inside autograd's forward
    rgb, alpha, depth = _Rasterize.apply(means, log_scales, quats, opacity_logits, sh, camera, degree, bg,
                                         opts, absgrad, hooks, box)
    frame = box[0]
    proj = frame.projection
    info = RasterInfo(
        radii=torch.from_numpy(np.array(proj.radii.numpy(), dtype=np.int32)),
        visible=torch.from_numpy(np.array(proj.visible.numpy(), dtype=bool)),
        width=camera.width, height=camera.height, num_pairs=frame.state.bins.num_pairs,
        sh_degree=degree, _frame=frame,
    )
    return rgb, alpha, depth, info
