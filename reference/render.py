"""Full forward pass: project, colour, composite (mirrors ``splatbench.raster.render``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from reference.band import projection_error
from reference.composite import composite
from reference.project import _as_array, project
from reference.sh import eval_sh, sh_degree_for


class RenderOutput(NamedTuple):
    """Rendered image plus per-Gaussian visibility."""

    rgb: np.ndarray  # [H, W, 3]
    alpha: np.ndarray  # [H, W] 1 - final transmittance
    depth: np.ndarray  # [H, W] expected camera z (0 where alpha == 0)
    radii: np.ndarray  # [N] int32 screen radius, 0 when culled
    visible: np.ndarray  # [N] bool
    band: np.ndarray | None = None  # [H, W] bool, the boundary band (reference.band); None unless asked
    tie_slack: np.ndarray | None = None  # [H, W] how far depth ties may move the pixel; None unless asked


def camera_centre(world_to_camera):
    """World position of the camera, ``-Rᵀ t``. world_to_camera: [4, 4] -> [3]."""
    W = np.asarray(world_to_camera, dtype=np.float64)
    return -W[:3, :3].T @ W[:3, 3]


def _normalize(v):
    """Unit rows of v: [N, 3], overflow-safe like the quaternion rule; zero rows stay zero."""
    biggest = np.max(np.abs(v), axis=1, keepdims=True)
    v = np.divide(v, biggest, out=np.zeros_like(v), where=biggest > 0)
    length = np.sqrt(np.sum(v * v, axis=1, keepdims=True))
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)


def render(means, log_scales, quats, opacity_logits, sh, K, world_to_camera, width, height, *,
           mode="matched", background=(0.0, 0.0, 0.0), sh_degree=None, eps2d=0.3, near=0.01,
           far=1e10, radius="3sigma", alpha_min=1 / 255, alpha_max=0.99, transmittance_min=1e-4,
           antialiased=False, band=False) -> RenderOutput:
    """Render Gaussians to an image (mirrors ``splatbench.raster.render``).

    Args:
        means: [N, 3]; log_scales: [N, 3]; quats: [N, 4] (w, x, y, z);
        opacity_logits: [N]; sh: [N, K, 3], K in {1, 4, 9, 16}.
        K: [3, 3] intrinsics; world_to_camera: [4, 4] (OpenCV axes).
        width, height: image size.
        mode: "matched" (the fast path's rules) or "exact" (smooth; see `project`, `composite`).
        background: [3]. sh_degree: None = every band in ``sh``; a larger degree than
            ``sh`` holds is a ValueError. band: also return the boundary band (matched mode;
            `reference.band`). Remaining keywords: see `project` and `composite`.

    Returns:
        `RenderOutput` (rgb [H, W, 3], alpha [H, W], depth [H, W], radii [N], visible [N],
        band [H, W] bool and tie_slack [H, W], both None unless ``band``).
    """
    proj = project(means, log_scales, quats, opacity_logits, K, world_to_camera, width, height,
                   mode=mode, eps2d=eps2d, near=near, far=far, radius=radius,
                   alpha_min=alpha_min, antialiased=antialiased)
    means = np.asarray(means, dtype=np.float64)
    sh = _as_array("sh", sh, (means.shape[0], None, 3), {})
    degree = sh_degree_for(sh.shape[1], sh_degree)

    # Colour of the visible Gaussians only (culled ones are never drawn).
    dirs = _normalize(means - camera_centre(world_to_camera))
    colors = np.zeros((means.shape[0], 3))
    vis = proj.visible
    colors[vis] = eval_sh(sh[vis], dirs[vis], degree)

    errors = None
    if band:
        errors = projection_error(means, log_scales, quats, opacity_logits, K, world_to_camera, proj.conics,
                                  radius=radius, eps2d=eps2d, antialiased=antialiased)
    out = composite(proj.means2d, proj.conics, proj.opacities, colors, proj.depths,
                    proj.cutoff_sq, vis, width, height, mode=mode, background=background,
                    alpha_min=alpha_min, alpha_max=alpha_max, transmittance_min=transmittance_min,
                    errors=errors)
    return RenderOutput(out.rgb, out.alpha, out.depth, proj.radii, proj.visible, out.band, out.tie_slack)
