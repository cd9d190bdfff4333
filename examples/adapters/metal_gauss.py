"""splatbench backend for metal-gauss's pure-PyTorch rasterizer (`metal_gauss.render(..., backend="torch_ref")`).

metal-gauss (PyPI `metal-gauss`, MIT) is a Metal rasterizer for Apple Silicon; its `torch_ref`
backend is "the differentiable pure-PyTorch reference ... Runs on MPS and CPU" and the default of
`metal_gauss.render`. Install it apart from splatbench's environment and put it on the path:

    pip install --no-deps --target out/conform_public/site-metal-gauss metal-gauss==0.2.1
    PYTHONPATH=.:out/conform_public/site-metal-gauss splatbench conform examples.adapters.metal_gauss:render

Faithful: this adapter only translates splatbench's call into the package's documented API
(`torch_ref.render` docstring: quats (N, 4) wxyz, scales linear, opacities in [0, 1], SH (N, B, 3),
K the pinhole intrinsics, viewmat world -> camera, `near`/`far`, `background`) and keeps the
package's defaults for everything else (tile 32, antialias off). It declares only what the package
documents: tiles of 32 pixels (the `tile` argument), outputs rgb and alpha (`rasterize` returns no
depth image), differentiable by autograd. Whatever else it does differently is for conform to find.
"""

from __future__ import annotations

import math
from importlib.metadata import PackageNotFoundError, version

import torch

from splatbench.backends import BackendInfo

try:
    from metal_gauss import render as _mg_render
except ImportError as e:  # one line, with the fix
    raise ImportError("examples.adapters.metal_gauss needs metal-gauss on PYTHONPATH: "
                      "pip install --no-deps --target out/conform_public/site-metal-gauss metal-gauss==0.2.1") from e

TILE = 32  # metal_gauss.torch_ref.render's default `tile`


def _version() -> str:
    try:
        return version("metal-gauss")
    except PackageNotFoundError:
        return "unknown"


def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
    """splatbench's backend signature (splatbench/backends/base.py) -> rgb [H, W, 3], alpha [H, W], depth [H, W]
    (depth zeros: metal-gauss renders none).

    means [N, 3]; log_scales [N, 3]; quats [N, 4] (w, x, y, z); opacity_logits [N]; sh [N, K, 3]."""
    dt, dev = means.dtype, means.device
    K = torch.tensor([[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]], dtype=dt, device=dev)
    viewmat = torch.tensor(camera.world_to_camera, dtype=dt, device=dev)  # a copy: Camera arrays are read-only
    degree = int(round(math.sqrt(sh.shape[1]))) - 1 if sh_degree is None else int(sh_degree)
    bg = (0.0, 0.0, 0.0) if background is None else tuple(float(v) for v in background)
    rgb, alpha, _info = _mg_render(
        means, quats, log_scales.exp(), torch.sigmoid(opacity_logits), sh, K, viewmat,
        camera.width, camera.height, sh_degree=degree, tile=TILE,
        near=float(camera.near), far=float(camera.far), background=bg, backend="torch_ref")
    return rgb, alpha, torch.zeros_like(alpha)


render.backend_info = BackendInfo(
    name="metal-gauss (torch_ref)", version=_version(), devices=("cpu",), gradients=True,
    outputs=("rgb", "alpha"), tile_size=TILE,
    description="metal-gauss's pure-PyTorch rasterizer (metal_gauss/torch_ref.py), its documented API and defaults")
