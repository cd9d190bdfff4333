"""splatbench: a differentiable-rendering comparison testbed for 3D Gaussian Splatting."""

from splatbench import _llvm

# Dr.Jit must load a libLLVM >= 16 (older ones abort the process): pick it before
# any submodule imports drjit or mitsuba. Raises LLVMNotFoundError naming the fix.
_llvm.configure()

__version__ = "0.1.0"
