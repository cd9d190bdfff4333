"""The trainer's D-SSIM (`splatbench.train.dssim` over `metrics.ssim`, Dr.Jit kernels) timed beside the torch
implementation it replaced (c53a18f: grouped convolutions on torch's thread), with each
one's error against float64: a measurement for issue 30, rerunnable anywhere.

    python tools/dssim_speed.py 128 256 800          # square image sides, 3 channels
    python tools/dssim_speed.py 256 --drjit-threads 1

For each size: the value's and the gradient's error against the float64 D-SSIM (the
summation orders differ, so the two float32 results differ in the last bits; their
errors are of one size), then the best of 7 wall and CPU times (process, all threads)
of value + gradient for each. Torch runs on one thread, as the trainer's default
``torch_threads = 1``; Dr.Jit on its pool (``--drjit-threads``: its size; with 1 the CPU
time counts compute only, not the pool's waiting on a busy machine).
"""

from __future__ import annotations

import argparse
import functools
import time

import torch
import torch.nn.functional as F

from splatbench.metrics.ssim import gaussian_window, ssim_terms
from splatbench.train.dssim import dssim

def _fold_reflect(t: torch.Tensor, dim: int, pad: int) -> torch.Tensor:
    """Adjoint of reflect padding along ``dim``: [.., n + 2 pad, ..] -> [.., n, ..], each
    padded position added onto the source it copied (edge not repeated)."""
    n = t.shape[dim] - 2 * pad
    out = t.narrow(dim, pad, n).clone()
    out.narrow(dim, 1, pad).add_(t.narrow(dim, 0, pad).flip(dim))            # left: position -j copied j
    out.narrow(dim, n - 1 - pad, pad).add_(t.narrow(dim, n + pad, pad).flip(dim))  # right: n-1+j copied n-1-j
    return out


class _Blur:
    """The separable, reflect-padded Gaussian blur of [1, C, H, W] maps, and its adjoint."""

    def __init__(self, window: int, channels: int, height: int, width: int, dtype, device) -> None:
        g = gaussian_window(window, dtype=dtype).to(device)
        self.pad = window // 2
        self.channels = channels
        self.kh = g.view(1, 1, 1, window).repeat(channels, 1, 1, 1)  # along W
        self.kv = g.view(1, 1, window, 1).repeat(channels, 1, 1, 1)  # along H

    def __call__(self, t: torch.Tensor) -> torch.Tensor:
        p = self.pad
        padded = F.pad(t, (p, p, p, p), mode="reflect")
        return F.conv2d(F.conv2d(padded, self.kh, groups=self.channels), self.kv, groups=self.channels)

    def adjoint(self, g: torch.Tensor) -> torch.Tensor:
        padded = F.conv_transpose2d(F.conv_transpose2d(g, self.kv, groups=self.channels), self.kh,
                                    groups=self.channels)
        return _fold_reflect(_fold_reflect(padded, 3, self.pad), 2, self.pad)


@functools.lru_cache(maxsize=16)
def _blur(window: int, channels: int, height: int, width: int, dtype, device) -> _Blur:
    """One `_Blur` per shape, built once (training calls the loss with one shape every step)."""
    return _Blur(window, channels, height, width, dtype, device)


class _TorchDssim(torch.autograd.Function):
    @staticmethod
    def forward(ctx, pred: torch.Tensor, target: torch.Tensor, window: int) -> torch.Tensor:
        x, y = pred.detach(), target.detach()
        c = x.shape[1]
        blur = _blur(window, 5 * c, x.shape[2], x.shape[3], x.dtype, x.device)
        mu_x, mu_y, e_xx, e_yy, e_xy = blur(torch.cat([x, y, x * x, y * y, x * y], dim=1)).split(c, dim=1)
        s, partials = ssim_terms(mu_x, mu_y, e_xx, e_yy, e_xy, grad=pred.requires_grad)
        if partials is not None:
            d_mu, d_exx, d_exy = partials
            adj = _blur(window, 3 * c, x.shape[2], x.shape[3], x.dtype, x.device)
            g_mu, g_xx, g_xy = adj.adjoint(torch.cat([d_mu, d_exx, d_exy], dim=1)).split(c, dim=1)
            # d(1 - mean S)/dx
            ctx.save_for_backward(-(g_mu + 2 * x * g_xx + y * g_xy) / s.numel())
        return 1 - s.mean()

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        (grad,) = ctx.saved_tensors
        return grad_out * grad, None, None


def torch_dssim(pred: torch.Tensor, target: torch.Tensor, window: int = 11) -> torch.Tensor:
    """c53a18f's `splatbench.train.dssim.dssim` (torch's grouped convolutions)."""
    return _TorchDssim.apply(pred, target.to(pred.dtype), window)


def _best(fn, k: int = 7) -> tuple[float, float]:
    fn()
    walls, cpus = [], []
    for _ in range(k):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return 1e3 * min(walls), 1e3 * min(cpus)


def _value_and_grad(fn, x, y):
    xq = x.clone().requires_grad_()
    value = fn(xq, y)
    value.backward()
    return float(value.detach()), xq.grad


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sizes", type=int, nargs="*", default=[128, 256, 800])
    ap.add_argument("--drjit-threads", type=int, default=0)
    args = ap.parse_args()
    if args.drjit_threads:
        import drjit as dr

        dr.set_thread_count(args.drjit_threads)
    torch.set_num_threads(1)
    for size in args.sizes:
        gen = torch.Generator().manual_seed(0)
        x = F.avg_pool2d(torch.rand(1, 3, size, size, generator=gen), 3, 1, 1)
        y = (x + 0.1 * torch.rand(1, 3, size, size, generator=gen)).clamp(0, 1)
        truth, truth_g = _value_and_grad(dssim, x.double(), y.double())
        scale = float(truth_g.abs().max())
        line = [f"{size}x{size}:"]
        for name, fn in (("torch (c53a18f)", torch_dssim), ("drjit (now)", dssim)):
            v, g = _value_and_grad(fn, x, y)
            wall, cpu = _best(lambda: _value_and_grad(fn, x, y))
            g_err = float((g.double() - truth_g).abs().max()) / scale
            line.append(f"{name}: value error {v - truth:+.1e}, gradient error {g_err:.1e} of max |grad|, "
                        f"wall {wall:.1f} ms, CPU {cpu:.1f} ms;")
        print(" ".join(line))


if __name__ == "__main__":
    main()
