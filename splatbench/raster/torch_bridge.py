"""`splatbench.rasterize`: the differentiable entry point for torch.

A `torch.autograd.Function` runs the Dr.Jit pipeline with AD enabled on the inputs
that need gradients (a frozen group costs no gradient work), keeps the Dr.Jit
graph alive until torch's backward, then seeds the outputs' cotangents and
traverses the graph back to the inputs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from splatbench.errors import InputError
from splatbench.raster.backend import dr, get_backend
from splatbench.raster.options import RasterOptions
from splatbench.raster.pipeline import (Frame, check_background, check_clip_planes, check_sh_range, render_frame,
                                       resolve_sh_degree)
from splatbench.checks import check_finite, check_shape

PARAMS = ("means", "log_scales", "quats", "opacity_logits", "sh")


@dataclass
class RasterInfo:
    """What densification needs from one rasterized view.

    radii [N] int32 (0 = culled); visible [N] bool; width, height; num_pairs;
    sh_degree. After ``loss.backward()``: ``means2d_grad`` [N, 2], the gradient of the
    loss with respect to the screen-space means (pixels), and ``means2d_absgrad``
    [N, 2], the per-pixel absolute values summed (AbsGS). Both are None before.
    """

    radii: torch.Tensor
    visible: torch.Tensor
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


class _Rasterize(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, log_scales, quats, opacity_logits, sh, camera, degree, background, options,
                loop_ad, absgrad, timer, info_box):
        m = get_backend(options.device).t
        inputs = []
        for t in (means, log_scales, quats, opacity_logits, sh):
            x = m.TensorXf(np.array(t.detach().cpu().numpy(), dtype=np.float32, order="C"))
            inputs.append(x)
        for x, needs in zip(inputs, ctx.needs_input_grad[:5]):
            if needs:
                dr.enable_grad(x)
        frame = render_frame(*inputs, camera, sh_degree=degree, background=background, options=options,
                             loop_ad=loop_ad, absgrad=absgrad, timer=timer)
        ctx.timer = timer
        H, W = camera.height, camera.width
        rgb = torch.from_numpy(np.array(frame.rgb.numpy(), dtype=np.float32).T.reshape(H, W, 3).copy())
        alpha = torch.from_numpy(np.array(frame.alpha.numpy(), dtype=np.float32).reshape(H, W))
        depth = torch.from_numpy(np.array(frame.depth.numpy(), dtype=np.float32).reshape(H, W))
        ctx.dr_inputs, ctx.frame, ctx.m = inputs, frame, m
        ctx.saved_shapes = [tuple(t.shape) for t in (means, log_scales, quats, opacity_logits, sh)]
        info_box.append(frame)
        return rgb, alpha, depth

    @staticmethod
    def backward(ctx, v_rgb, v_alpha, v_depth):
        m, frame, inputs = ctx.m, ctx.frame, ctx.dr_inputs
        if not any(ctx.needs_input_grad[:5]):
            return (None,) * 13
        v_rgb = np.ascontiguousarray(v_rgb.detach().cpu().numpy().reshape(-1, 3).T, dtype=np.float32)
        dr.set_grad(frame.rgb, m.Array3f(v_rgb))
        dr.set_grad(frame.alpha, m.Float(np.ascontiguousarray(v_alpha.detach().cpu().numpy().reshape(-1),
                                                               dtype=np.float32)))
        dr.set_grad(frame.depth, m.Float(np.ascontiguousarray(v_depth.detach().cpu().numpy().reshape(-1),
                                                               dtype=np.float32)))
        dr.enqueue(dr.ADMode.Backward, frame.rgb, frame.alpha, frame.depth)
        dr.traverse(dr.ADMode.Backward)
        if ctx.timer is not None:
            dr.eval([dr.grad(x) for x in inputs])
            ctx.timer.mark("backward_preprocess")
        grads = []
        for x, needs, like in zip(inputs, ctx.needs_input_grad[:5], ctx.saved_shapes):
            if not needs:
                grads.append(None)
                continue
            g = np.array(dr.grad(x).numpy(), dtype=np.float32).reshape(like)
            grads.append(torch.from_numpy(g))
        ctx.dr_inputs = None  # release the Dr.Jit graph
        return (*grads, None, None, None, None, None, None, None, None)


def _check(name: str, t, spec, sizes) -> torch.Tensor:
    if not isinstance(t, torch.Tensor):
        raise InputError(f"{name}: expected a torch.Tensor, got {type(t).__name__}")
    if not t.is_floating_point():
        raise InputError(f"{name}: expected a floating-point tensor, got dtype {t.dtype}")
    check_shape(name, tuple(t.shape), spec, sizes)
    if not bool(torch.isfinite(t.detach()).all()):  # fast path; numpy only to name the entry
        check_finite(name, t.detach().cpu().numpy())
    return t


def rasterize(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree: int | None = None,
              background=None, absgrad: bool = False, loop_ad: bool = False, timer=None, **options):
    """Differentiable 3DGS rasterization of torch tensors through the Dr.Jit pipeline.

    Args:
        means: [N, 3] world positions. log_scales: [N, 3]. quats: [N, 4] (w, x, y, z).
        opacity_logits: [N]. sh: [N, K, 3], K = (d+1)^2 bases.
        camera: `splatbench.Camera` (width W, height H).
        sh_degree: SH bands to evaluate (default: all in ``sh``); higher bands get zero gradient.
        background: RGB behind the splats (default black).
        absgrad: also accumulate ``info.means2d_absgrad`` (AbsGS) in the backward pass.
        timer: benchmarks only; a `StageTimer` charged per stage (forward and backward).
        loop_ad: test-only; differentiate compositing with Dr.Jit's loop AD instead of
            the hand-written backward pass.
        **options: `RasterOptions` fields.

    Returns:
        rgb [H, W, 3], alpha [H, W], depth [H, W] (float32 torch tensors, differentiable
        with respect to every input with ``requires_grad``), and a `RasterInfo`.
    """
    sizes: dict[str, int] = {}
    _check("means", means, ("N", 3), sizes)
    _check("log_scales", log_scales, ("N", 3), sizes)
    _check("quats", quats, ("N", 4), sizes)
    _check("opacity_logits", opacity_logits, ("N",), sizes)
    _check("sh", sh, ("N", None, 3), sizes)
    opts = RasterOptions.from_kwargs(**options)
    check_clip_planes(camera, opts)
    degree = resolve_sh_degree(sh.shape[1], sh_degree)
    if sh.numel():
        flat = int(sh.detach().abs().argmax())
        check_sh_range(float(sh.detach().reshape(-1)[flat].abs()), np.unravel_index(flat, tuple(sh.shape)))
    bg = check_background(background)
    box: list[Frame] = []  # receives the Dr.Jit frame from inside autograd's forward
    rgb, alpha, depth = _Rasterize.apply(means, log_scales, quats, opacity_logits, sh, camera, degree, bg,
                                         opts, loop_ad, absgrad, timer, box)
    frame = box[0]
    proj = frame.projection
    info = RasterInfo(
        radii=torch.from_numpy(np.array(proj.radii.numpy(), dtype=np.int32)),
        visible=torch.from_numpy(np.array(proj.visible.numpy(), dtype=bool)),
        width=camera.width, height=camera.height, num_pairs=frame.state.bins.num_pairs,
        sh_degree=degree, _frame=frame,
    )
    return rgb, alpha, depth, info
