"""The ``drjit`` backend: splatbench's own tile rasterizer behind the `Backend` interface."""

from __future__ import annotations

from splatbench.backends.base import Backend, BackendInfo

DESCRIPTION = ("splatbench's Dr.Jit tile rasterizer (LLVM on the CPU, CUDA where Dr.Jit finds a GPU) with "
               "its analytic backward pass; graphdeco-inria 3DGS conventions (docs/conventions.md)")


def make_drjit_backend(**options) -> Backend:
    """The ``drjit`` backend; ``options`` are `splatbench.RasterOptions` fields (graphdeco defaults).

    The declared approximations are the options actually used, so a backend made with
    ``radius="opacity"`` is compared against the reference with that rule.
    """
    from splatbench.raster import rasterize
    from splatbench.raster.device import cuda_available
    from splatbench.raster.options import RasterOptions
    from splatbench.versions import SPLATBENCH_VERSION

    opts = RasterOptions.from_kwargs(**options)
    info = BackendInfo(
        name="drjit", version=SPLATBENCH_VERSION,
        devices=("cpu", "cuda") if cuda_available() else ("cpu",),
        alpha_min=opts.alpha_min, alpha_max=opts.alpha_max, transmittance_min=opts.transmittance_min,
        eps2d=opts.eps2d, radius=opts.radius, tile_size=opts.tile_size, antialiased=opts.antialiased,
        description=DESCRIPTION)
    def drjit(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        rgb, alpha, depth, _ = rasterize(means, log_scales, quats, opacity_logits, sh, camera,
                                         sh_degree=sh_degree, background=background, options=opts)
        return rgb, alpha, depth

    return Backend(drjit, info)
