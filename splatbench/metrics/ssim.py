"""SSIM: its map and, for the training loss, the gradient of ``1 - mean SSIM``, computed by
Dr.Jit where the rasterizer runs. The one SSIM of splatbench: the evaluation metric
(`splatbench.metrics.image.ssim_metric`) and the loss's D-SSIM (`splatbench.train.dssim`).

The maths is kornia's ``kornia.metrics.ssim(pred, target, window, max_val=1)``: a
sampled Gaussian window (σ = 1.5, ``window`` taps, sum 1) applied with reflect padding
("same" size), ``c1 = 0.01²``, ``c2 = 0.03²``, ``eps = 1e-12`` added to the denominator,
here applied separably. With

    μx, μy, Exx, Eyy, Exy   the blurred maps of x, y, x², y², xy
    A1 = 2 μx μy + c1       A2 = 2 (Exy − μx μy) + c2
    B1 = μx² + μy² + c1     B2 = (Exx − μx²) + (Eyy − μy²) + c2
    S = A1 A2 / (B1 B2 + eps),  D = B1 B2 + eps

the per-pixel partial derivatives (the blurred maps held fixed) are

    ∂S/∂μx  = 2 μy (A2 − A1) / D − 2 μx S (B2 − B1) / D
    ∂S/∂Exx = −S B1 / D
    ∂S/∂Exy = 2 A1 / D

and ``∂mean(S)/∂x = Blurᵀ(∂S/∂μx) + 2 x Blurᵀ(∂S/∂Exx) + y Blurᵀ(∂S/∂Exy)``, divided
by the number of map values, where ``Blurᵀ`` is the exact adjoint of the padded blur
(per axis: the transposed, zero-padded correlation onto the padded length, then the
reflect padding folded back). Only ``pred`` gets a gradient; ``target`` is data.

Where it runs: Dr.Jit kernels on the device of the tensors (LLVM on Dr.Jit's thread
pool for CPU tensors, CUDA for CUDA tensors), which read and write torch's memory
through DLPack (no copy of a contiguous input): the horizontal blur of the five maps
(one kernel), the vertical blur with the SSIM map (and its three partials) (one
kernel), and for the gradient each adjoint blur and its fold (two kernels per axis).
Each blur sums its taps in a fixed order (tap 0 first), so results are deterministic,
independent of the thread count; the order differs from kornia's 2D convolution and from
the torch convolutions the loss used before (c53a18f), so values differ from theirs in
the last bits: `tests/test_losses.py` checks value and gradient against kornia's in
float64 (the same maths, to float64 rounding) and in float32 (as close to the float64
truth as kornia's own float32 result). Why Dr.Jit: torch's convolutions ran on one torch
thread (``torch_threads = 1``) while the rasterizer's pool waited, and slowed sharply
at large images; kornia alone added 20 MiB to a training process's peak (docs/benchmarks.md,
"Training").
"""

from __future__ import annotations

from types import ModuleType

import drjit as dr
import torch

SIGMA = 1.5
C1, C2, EPS = 0.01 ** 2, 0.03 ** 2, 1e-12


def gaussian_window(window: int, *, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """[window] samples of exp(−n² / 2σ²), n = −window//2 .. window//2, σ = 1.5, summing to 1."""
    n = torch.arange(window, dtype=dtype) - window // 2
    g = torch.exp(-(n * n) / (2 * SIGMA ** 2))
    return g / g.sum()


def ssim_terms(mu_x, mu_y, e_xx, e_yy, e_xy, *, grad: bool):
    """The SSIM map S from the five blurred maps, and with ``grad`` its partials [∂S/∂μx,
    ∂S/∂Exx, ∂S/∂Exy] (else None): the module doc's formulas in plain arithmetic, so that
    Dr.Jit arrays and torch tensors (``tools/dssim_speed.py``'s baseline) share them."""
    a1 = 2 * mu_x * mu_y + C1
    a2 = 2 * (e_xy - mu_x * mu_y) + C2
    b1 = mu_x * mu_x + mu_y * mu_y + C1
    b2 = (e_xx - mu_x * mu_x) + (e_yy - mu_y * mu_y) + C2
    d = b1 * b2 + EPS
    s = a1 * a2 / d
    if not grad:
        return s, None
    return s, [(2 * mu_y * (a2 - a1) - 2 * mu_x * s * (b2 - b1)) / d, -s * b1 / d, 2 * a1 / d]


def _module(t: torch.Tensor) -> ModuleType:
    """Dr.Jit's plain (non-AD) array namespace for the device of ``t``: drjit.llvm or drjit.cuda."""
    from splatbench.raster.device import get_device

    name = get_device("cuda" if t.is_cuda else "cpu").name
    if name == "cuda":
        import drjit.cuda as m
    else:
        import drjit.llvm as m
    return m


def _reflect(q, n: int):
    """Reflect padding's source index of position ``q`` in [-pad, n - 1 + pad] (edge not repeated)."""
    q = dr.select(q < 0, -q, q)
    return dr.select(q > n - 1, 2 * (n - 1) - q, q)


def _fold(m, f, arr, pos, n: int, pad: int, base, stride):
    """Adjoint of reflect padding along one axis at position ``pos`` of ``n``: the padded
    array ``arr`` (positions ``0 .. n + 2 pad``, at ``base + t * stride``) at ``pos + pad``,
    plus the padded positions that copied ``pos`` (``pad - pos`` for 1 <= pos <= pad,
    ``2 (n - 1) - pos + pad`` for n - 1 - pad <= pos <= n - 2)."""
    u = m.UInt32
    out = dr.gather(f, arr, u(base + (pos + pad) * stride))
    lo = (pos >= 1) & (pos <= pad)
    out += dr.gather(f, arr, u(base + dr.select(lo, pad - pos, 0) * stride), lo)
    hi = (pos >= n - 1 - pad) & (pos <= n - 2)
    return out + dr.gather(f, arr, u(base + dr.select(hi, 2 * (n - 1) - pos + pad, 0) * stride), hi)


def _dssim_maps(m, f, x, y, planes: int, height: int, width: int, taps: list[float], grad: bool):
    """(SSIM map, d(1 - mean S)/dx or None) of ``planes`` images of height x width stored
    plane by plane, row by row in the flat Dr.Jit arrays ``x``, ``y`` of type ``f``."""
    i32, u = m.Int32, m.UInt32
    window, n = len(taps), planes * height * width
    pad = window // 2
    idx = dr.arange(i32, n)
    col, rows = idx % width, idx // width  # rows: plane * height + row
    row, plane = rows % height, rows // height
    acc = [f(0)] * 5
    for k, g in enumerate(taps):  # along the width: x, y, x², y², xy
        src = u(rows * width + _reflect(col + (k - pad), width))
        xv, yv = dr.gather(f, x, src), dr.gather(f, y, src)
        acc = [dr.fma(g, t, a) for a, t in zip(acc, (xv, yv, xv * xv, yv * yv, xv * yv))]
    dr.eval(acc)
    blurred = [f(0)] * 5
    for k, g in enumerate(taps):  # along the height
        src = u((plane * height + _reflect(row + (k - pad), height)) * width + col)
        blurred = [dr.fma(g, dr.gather(f, a, src), b) for b, a in zip(blurred, acc)]
    s, partials = ssim_terms(*blurred, grad=grad)
    if partials is None:
        dr.eval(s)
        return s, None
    dr.eval(s, partials)
    del acc, blurred
    # adjoint along the height: transposed correlation onto height + 2 pad rows, then folded
    tall = height + 2 * pad
    j = dr.arange(i32, planes * tall * width)
    c2, r2 = j % width, j // width
    q2, p2 = r2 % tall, r2 // tall
    z = [f(0)] * 3
    for k, g in enumerate(taps):
        i = q2 - k
        ok = (i >= 0) & (i < height)
        src = u((p2 * height + dr.select(ok, i, 0)) * width + c2)
        z = [dr.fma(g, dr.gather(f, a, src, ok), zz) for zz, a in zip(z, partials)]
    dr.eval(z)
    del partials, j, c2, r2, q2, p2
    v = [_fold(m, f, zz, row, height, pad, plane * (tall * width) + col, width) for zz in z]
    dr.eval(v)
    del z
    # adjoint along the width, folded, and the gradient
    wide = width + 2 * pad
    j = dr.arange(i32, planes * height * wide)
    q3, r3 = j % wide, j // wide
    z = [f(0)] * 3
    for k, g in enumerate(taps):
        i = q3 - k
        ok = (i >= 0) & (i < width)
        src = u(r3 * width + dr.select(ok, i, 0))
        z = [dr.fma(g, dr.gather(f, a, src, ok), zz) for zz, a in zip(z, v)]
    dr.eval(z)
    del v, j, q3, r3
    g_mu, g_xx, g_xy = (_fold(m, f, zz, col, width, pad, rows * wide, 1) for zz in z)
    out = -(g_mu + 2 * x * g_xx + y * g_xy) / n
    dr.eval(out)
    return s, out


def ssim_map(pred: torch.Tensor, target: torch.Tensor, window: int = 11, *,
             grad: bool = False) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The SSIM map S [B, C, H, W] of ``pred`` against ``target`` ([B, C, H, W], float32 or
    float64, in [0, 1]) and, with ``grad``, the gradient of ``1 - mean(S)`` with respect to
    ``pred`` [B, C, H, W] (else None): torch tensors viewing Dr.Jit's results."""
    if pred.shape != target.shape or pred.dim() != 4:  # before the shape is unpacked
        from splatbench.errors import InputError

        raise InputError(f"ssim: expected two [B, C, H, W] images of one shape, got {list(pred.shape)} and "
                         f"{list(target.shape)}")
    b, c, h, w = pred.shape
    if min(h, w) <= window // 2:
        from splatbench.errors import InputError

        raise InputError(f"ssim_window: {window} needs images larger than {window // 2} px, got {w}x{h}")
    if pred.dtype not in (torch.float32, torch.float64):
        from splatbench.errors import InputError

        raise InputError(f"ssim: expected float32 or float64 images, got {pred.dtype}")
    m = _module(pred)
    tensor, f = (m.TensorXf64, m.Float64) if pred.dtype == torch.float64 else (m.TensorXf, m.Float)
    x, y = pred.detach().contiguous(), target.detach().to(pred.dtype).contiguous()
    if x.is_cuda:  # torch and Dr.Jit use different CUDA streams: finish torch's writes first
        torch.cuda.synchronize(x.device)
    taps = [float(v) for v in gaussian_window(window, dtype=pred.dtype)]
    s, g = _dssim_maps(m, f, tensor(x).array, tensor(y).array, b * c, h, w, taps, grad)
    if x.is_cuda:
        dr.sync_thread()
    as_torch = (lambda a: torch.from_dlpack(tensor(a, (b, c, h, w))))
    return as_torch(s), (as_torch(g) if g is not None else None)


__all__ = ["ssim_map", "ssim_terms", "gaussian_window", "SIGMA", "C1", "C2", "EPS"]
