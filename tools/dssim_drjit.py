"""D-SSIM (value and gradient) written in Dr.Jit, timed beside the trainer's torch D-SSIM
(`splatbench.train.dssim`): a measurement for issue 30 ("the D-SSIM on the rasterizer's
device"), not used by training.

    python tools/dssim_drjit.py 128 256 800        # square image sides, 3 channels

The same maths as `splatbench.train.dssim` (kornia's SSIM: separable 11-tap Gaussian,
reflect padding, c1, c2, eps; gradient formed in the forward pass), in Dr.Jit LLVM
kernels on Dr.Jit's thread pool: horizontal blur of x, y, x², y², xy (one kernel); the
vertical blur, the SSIM map and its three partials (one kernel); each adjoint blur as a
zero-padded transposed correlation and the reflection folded back (two kernels per axis).
Every tap is a `dr.gather`. For each size it prints the value's and the gradient's
difference from the float64 torch D-SSIM beside the float32 torch D-SSIM's own (the
summation order differs, so the bits do not match; the error is of the same size), and
the best of 7 wall and CPU (process, all threads) times of each. Torch runs on one
thread, as the trainer's default ``torch_threads = 1``; Dr.Jit on its own pool.
"""

from __future__ import annotations

import sys
import time

import drjit as dr
import drjit.llvm as m
import torch

from splatbench.train.dssim import C1, C2, EPS, dssim, gaussian_window


def _reflect(q, n: int):
    q = dr.select(q < 0, -q, q)
    return dr.select(q > n - 1, 2 * (n - 1) - q, q)


def _fold(arr, pos, n: int, p: int, base, stride):
    """Adjoint of reflect padding along one axis: padded position t = pos + p, plus the
    positions that copied ``pos`` (1 <= pos <= p on the low side, n-1-p <= pos <= n-2 on the high)."""
    F, U = m.Float, m.UInt32
    out = dr.gather(F, arr, U(base + (pos + p) * stride))
    lo = (pos >= 1) & (pos <= p)
    out += dr.gather(F, arr, U(base + dr.select(lo, p - pos, 0) * stride), lo)
    hi = (pos >= n - 1 - p) & (pos <= n - 2)
    return out + dr.gather(F, arr, U(base + dr.select(hi, 2 * (n - 1) - pos + p, 0) * stride), hi)


def dssim_drjit(x: torch.Tensor, y: torch.Tensor, window: int = 11) -> tuple[torch.Tensor, torch.Tensor]:
    """(1 - mean SSIM, its gradient in x) of [B, C, H, W] float32 CPU tensors."""
    F, I, U = m.Float, m.Int32, m.UInt32
    B, C, H, W = x.shape
    planes, n, p = B * C, x.numel(), window // 2
    g = [float(v) for v in gaussian_window(window, dtype=x.dtype)]
    xa, ya = m.TensorXf(x.detach().contiguous()).array, m.TensorXf(y.detach().contiguous()).array
    idx = dr.arange(I, n)
    col, rest = idx % W, idx // W
    r, plane = rest % H, rest // H
    acc = [F(0)] * 5
    for k in range(window):  # horizontal blur of x, y, x², y², xy
        src = U(rest * W + _reflect(col + (k - p), W))
        xv, yv = dr.gather(F, xa, src), dr.gather(F, ya, src)
        acc = [dr.fma(g[k], t, a) for a, t in zip(acc, (xv, yv, xv * xv, yv * yv, xv * yv))]
    dr.eval(acc)
    bl = [F(0)] * 5
    for k in range(window):  # vertical blur
        src = U(plane * (H * W) + _reflect(r + (k - p), H) * W + col)
        bl = [dr.fma(g[k], dr.gather(F, a, src), b) for b, a in zip(bl, acc)]
    mu_x, mu_y, e_xx, e_yy, e_xy = bl
    a1, a2 = 2 * mu_x * mu_y + C1, 2 * (e_xy - mu_x * mu_y) + C2
    b1, b2 = mu_x * mu_x + mu_y * mu_y + C1, (e_xx - mu_x * mu_x) + (e_yy - mu_y * mu_y) + C2
    d = b1 * b2 + EPS
    s = a1 * a2 / d
    maps = [(2 * mu_y * (a2 - a1) - 2 * mu_x * s * (b2 - b1)) / d, -s * b1 / d, 2 * a1 / d]
    dr.eval(s, maps)
    hp = H + 2 * p  # vertical adjoint onto the padded rows, then folded
    j = dr.arange(I, planes * hp * W)
    c2, rest2 = j % W, j // W
    q2, pl2 = rest2 % hp, rest2 // hp
    z = [F(0)] * 3
    for k in range(window):
        i = q2 - k
        act = (i >= 0) & (i < H)
        src = U(pl2 * (H * W) + dr.select(act, i, 0) * W + c2)
        z = [dr.fma(g[k], dr.gather(F, a, src, act), zz) for zz, a in zip(z, maps)]
    dr.eval(z)
    v = [_fold(zz, r, H, p, plane * (hp * W) + col, W) for zz in z]
    dr.eval(v)
    wp = W + 2 * p  # horizontal adjoint, folded, combined
    j3 = dr.arange(I, planes * H * wp)
    q3, row3 = j3 % wp, j3 // wp
    z2 = [F(0)] * 3
    for k in range(window):
        i = q3 - k
        act = (i >= 0) & (i < W)
        src = U(row3 * W + dr.select(act, i, 0))
        z2 = [dr.fma(g[k], dr.gather(F, a, src, act), zz) for zz, a in zip(z2, v)]
    dr.eval(z2)
    f = [_fold(zz, col, W, p, rest * wp, 1) for zz in z2]
    grad = -(f[0] + 2 * xa * f[1] + ya * f[2]) / n
    dr.eval(s, grad)
    s_t, g_t = (torch.from_dlpack(m.TensorXf(a, (B, C, H, W))) for a in (s, grad))
    return 1 - s_t.mean(), g_t


def _best(fn, k: int = 7) -> tuple[float, float]:
    fn()
    walls, cpus = [], []
    for _ in range(k):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return 1e3 * min(walls), 1e3 * min(cpus)


def main(sizes: list[int]) -> None:
    torch.set_num_threads(1)
    for size in sizes:
        gen = torch.Generator().manual_seed(0)
        x = torch.nn.functional.avg_pool2d(torch.rand(1, 3, size, size, generator=gen), 3, 1, 1)
        y = (x + 0.1 * torch.rand(1, 3, size, size, generator=gen)).clamp(0, 1)
        x64 = x.double().requires_grad_()
        truth = dssim(x64, y.double())
        truth.backward()
        xt = x.clone().requires_grad_()
        tv = dssim(xt, y)
        tv.backward()
        dv, dg = dssim_drjit(x, y)
        scale = float(x64.grad.abs().max())

        def torch_step():
            xq = x.clone().requires_grad_()
            dssim(xq, y).backward()

        tw, tc = _best(torch_step)
        dw, dc = _best(lambda: dssim_drjit(x, y))
        print(f"{size}x{size}: value error vs float64 drjit {float(dv) - float(truth.detach()):+.2e} torch "
              f"{float(tv.detach()) - float(truth.detach()):+.2e}; gradient max error / max |grad| drjit "
              f"{float((dg.double() - x64.grad).abs().max()) / scale:.2e} torch "
              f"{float((xt.grad.double() - x64.grad).abs().max()) / scale:.2e}; "
              f"torch wall {tw:.1f} ms CPU {tc:.1f} ms, drjit wall {dw:.1f} ms CPU {dc:.1f} ms")


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [128, 256, 800])
