"""The Dr.Jit device of a render: LLVM on the CPU, CUDA where a GPU exists.

The same rasterizer code runs on both; a `Device` carries the array types so no
module-level state decides where work happens. (A rasterizer plugin, the other thing
called a backend, is `splatbench.backends.Backend`.)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType

import drjit as dr

from splatbench import _llvm
from splatbench.devices import check_device, no_cuda
from splatbench.errors import InputError


@dataclass(frozen=True)
class Device:
    """The Dr.Jit array namespace used for one render (``drjit.llvm.ad`` or ``drjit.cuda.ad``)."""

    name: str  # Dr.Jit's backend: "llvm" or "cuda"
    t: ModuleType


def cuda_available() -> bool:
    return bool(dr.has_backend(dr.JitBackend.CUDA))


@lru_cache(maxsize=None)
def _llvm_packet_width() -> int:
    return _llvm.packet_width()


def packet_width(m: ModuleType) -> int:
    """SIMD lanes per packet of the array namespace ``m``'s backend: Dr.Jit's LLVM packet
    width on this CPU (`_llvm.packet_width`), 1 otherwise (a CUDA thread is one lane)."""
    return _llvm_packet_width() if m.__name__.startswith("drjit.llvm") else 1


@lru_cache(maxsize=None)
def get_device(device: str = "auto") -> Device:
    """The `Device` for ``device`` ("cpu", "cuda" or "auto": CUDA when available)."""
    if check_device(device) == "auto":
        device = "cuda" if cuda_available() else "cpu"
    if device == "cuda":
        if not cuda_available():
            raise no_cuda("Dr.Jit")
        import drjit.cuda.ad as t
        return Device("cuda", t)
    try:
        _llvm.require()
    except _llvm.LLVMNotFoundError as exc:
        raise InputError(f"device: 'cpu' needs Dr.Jit's LLVM backend: {exc}") from None
    if not dr.has_backend(dr.JitBackend.LLVM):
        raise InputError("device: 'cpu' requested but Dr.Jit's LLVM backend is unavailable")
    import drjit.llvm.ad as t
    return Device("llvm", t)
