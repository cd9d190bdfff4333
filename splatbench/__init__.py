"""splatbench: a differentiable-rendering comparison testbed for 3D Gaussian Splatting.

Public API:
    Gaussians   raw 3DGS parameters (means [N, 3], log_scales [N, 3], quats [N, 4],
                opacity_logits [N], sh [N, K, 3]); PLY I/O in the graphdeco layout.
    Camera      pinhole camera, OpenCV axes; Mitsuba / COLMAP / Blender converters.
    render      numpy in, numpy out: rgb [H, W, 3], alpha [H, W], depth [H, W], radii [N].
    rasterize   torch in, torch out, differentiable with respect to all five groups.
    RasterOptions, RenderResult, RasterInfo.
"""

from splatbench import _llvm

# Dr.Jit must load a libLLVM >= 16 (older ones abort the process): pick it before
# any submodule imports drjit or mitsuba. With none, the LLVM backend is switched off and
# the CPU device (and Mitsuba's LLVM variant) raise the reason when asked for; CUDA works.
_llvm.configure()

from splatbench.cameras import Camera  # noqa: E402
from splatbench.errors import InputError, SplatbenchError  # noqa: E402
from splatbench.gaussians import Gaussians  # noqa: E402

from splatbench.versions import SPLATBENCH_VERSION as __version__  # noqa: E402

# The rasterizer (Dr.Jit, and torch for `rasterize`) loads on first use, so that
# `import splatbench`, the CLI and experiment workers start without paying for it.
_LAZY = {name: "splatbench.raster" for name in ("render", "rasterize", "RasterOptions", "RenderResult",
                                                  "RasterInfo")}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'splatbench' has no attribute {name!r}")

__all__ = ["Gaussians", "Camera", "render", "rasterize", "RasterOptions", "RenderResult", "RasterInfo",
           "InputError", "SplatbenchError", "__version__"]
