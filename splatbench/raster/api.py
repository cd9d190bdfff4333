"""`splatbench.render`: numpy in, numpy out (no gradients)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from splatbench.errors import InputError
from splatbench.raster.device import dr, get_device
from splatbench.raster.options import RasterOptions
from splatbench.raster.pipeline import (check_background, check_options, check_sh_range, check_view, frame_to_numpy,
                                       render_frame, resolve_sh_degree)

if TYPE_CHECKING:
    from splatbench.cameras import Camera
    from splatbench.gaussians import Gaussians


@dataclass(frozen=True)
class RenderResult:
    """One rendered view.

    rgb [H, W, 3] float32; alpha [H, W] float32 in [0, 1]; depth [H, W] float32,
    expected camera z of the visible splats (0 where alpha is 0); radii [N] int32,
    screen radius in pixels (0 = culled); visible [N] bool; num_pairs: Gaussian-tile
    pairs composited; sh_degree: the degree evaluated.
    """

    rgb: np.ndarray      # [H, W, 3]
    alpha: np.ndarray    # [H, W]
    depth: np.ndarray    # [H, W]
    radii: np.ndarray    # [N]
    visible: np.ndarray  # [N]
    num_pairs: int
    sh_degree: int


def to_tensor(m, array: np.ndarray):
    """A float32 Dr.Jit tensor holding a copy of ``array``."""
    return m.TensorXf(np.array(array, dtype=np.float32, order="C"))


def render(
    gaussians: Gaussians,          # N Gaussians, SH with K bases
    camera: Camera,                # width W, height H
    *,
    sh_degree: int | None = None,
    background=(0.0, 0.0, 0.0),
    options: RasterOptions | None = None,
) -> RenderResult:                 # rgb [H, W, 3], alpha [H, W], depth [H, W], radii [N], visible [N]
    """Render ``gaussians`` seen from ``camera`` with the Dr.Jit tile rasterizer.

    Args:
        gaussians: `splatbench.Gaussians` (N Gaussians, SH with K bases).
        camera: `splatbench.Camera` (width W, height H).
        sh_degree: SH bands to evaluate (default: all that ``gaussians.sh`` holds).
        background: RGB behind the splats.
        options: the rasterizer's `RasterOptions` (tile_size, alpha_min, alpha_max,
            transmittance_min, eps2d, near, far, radius, antialiased, device); None: the defaults.

    Returns:
        `RenderResult` with rgb [H, W, 3], alpha [H, W], depth [H, W], radii [N], visible [N].

    Example:
        >>> res = splatbench.render(gaussians, camera)
        >>> res.rgb.shape, res.alpha.shape, res.radii.shape
        ((H, W, 3), (H, W), (N,))
    """
    from splatbench.gaussians import Gaussians

    if not isinstance(gaussians, Gaussians):
        raise InputError(f"gaussians: expected splatbench.Gaussians, got {type(gaussians).__name__}")
    opts = check_options(options)
    check_view(camera, opts)
    degree = resolve_sh_degree(gaussians.sh.shape[1], sh_degree)
    if gaussians.sh.size:
        flat = int(np.argmax(np.abs(gaussians.sh)))
        check_sh_range(float(np.abs(gaussians.sh).flat[flat]), np.unravel_index(flat, gaussians.sh.shape))
    bg = check_background(background)
    m = get_device(opts.device).t
    with dr.suspend_grad():
        frame = render_frame(to_tensor(m, gaussians.means), to_tensor(m, gaussians.log_scales),
                             to_tensor(m, gaussians.quats), to_tensor(m, gaussians.opacity_logits),
                             to_tensor(m, gaussians.sh), camera, sh_degree=degree, background=bg, options=opts)
        rgb, alpha, depth = frame_to_numpy(frame, camera.height, camera.width)
        radii = np.array(frame.projection.radii.numpy(), dtype=np.int32)
        visible = np.array(frame.projection.visible.numpy(), dtype=bool)
    return RenderResult(rgb, alpha, depth, radii, visible, frame.state.bins.num_pairs, degree)
