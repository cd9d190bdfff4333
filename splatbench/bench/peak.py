"""The machine's measured FP32 peak: a short Dr.Jit kernel of chained FMAs.

`fp32_peak` is what "share of peak" in `splatbench bench raster` divides by. Each
lane runs CHAINS independent chains of DEPTH dependent fused multiply-adds (enough
independent chains to hide the FMA latency), on every core Dr.Jit's thread pool uses.
The kernel compiles in an untimed warm-up; each timed run is one launch of the cached
kernel, and the best of the runs is kept (a peak, not a typical value: anything else
on the machine only makes a run slower).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

CHAINS = 16
DEPTH = 96
FLOPS_PER_FMA = 2


@dataclass(frozen=True)
class PeakResult:
    """gflops: best FP32 rate measured (10^9 flop/s, an FMA counts 2); lanes, chains,
    depth: the kernel's shape; runs: timed launches."""

    gflops: float
    lanes: int
    chains: int
    depth: int
    runs: int


def fp32_peak(device: str = "cpu", lanes: int = 1 << 20, runs: int = 5) -> PeakResult:
    """Measure the FP32 FMA rate of the Dr.Jit backend for ``device`` ("cpu" or "cuda")."""
    from splatbench.raster.device import dr, get_device

    m = get_device(device).t

    def launch() -> float:
        with dr.suspend_grad():
            x = m.Float(dr.arange(m.Float, lanes)) * 1e-7
            # Opaque constants: the compiler can neither fold nor reassociate the chains.
            b, c = dr.opaque(m.Float, 0.999999), dr.opaque(m.Float, 1e-7)
            acc = [x + k for k in range(CHAINS)]
            for _ in range(DEPTH):
                acc = [dr.fma(a, b, c) for a in acc]
            total = acc[0]
            for a in acc[1:]:
                total = total + a
            dr.sync_thread()
            t0 = time.perf_counter()
            dr.eval(total)
            dr.sync_thread()
            return time.perf_counter() - t0

    launch()  # compile (or load from ~/.drjit)
    best = min(launch() for _ in range(runs))
    flops = lanes * CHAINS * DEPTH * FLOPS_PER_FMA
    return PeakResult(round(flops / best / 1e9, 2), lanes, CHAINS, DEPTH, runs)
