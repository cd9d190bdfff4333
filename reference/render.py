"""Full forward pass: project, colour, composite (mirrors ``splatbench.raster.render``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from reference.band import projection_error
from reference.composite import composite
from reference.project import JACOBIAN_GUARD, _as_array, _as_choice, project
from reference.sh import eval_sh, sh_degree_for


SH_VIEW_DIRECTIONS = ("camera_to_mean", "mean_to_camera", "world_origin")
SORT_KEYS = ("view_z", "distance", "world_z", "index")
DEPTH_MODES = ("normalised", "unnormalised", "distance")


class RenderOutput(NamedTuple):
    """Rendered image plus per-Gaussian visibility."""

    rgb: np.ndarray  # [H, W, 3]
    alpha: np.ndarray  # [H, W] 1 - final transmittance
    depth: np.ndarray  # [H, W] expected camera z (0 where alpha == 0)
    radii: np.ndarray  # [N] int32 screen radius, 0 when culled
    visible: np.ndarray  # [N] bool
    band: np.ndarray | None = None  # [H, W] bool, the boundary band (reference.band); None unless asked
    tie_slack: np.ndarray | None = None  # [H, W] how far depth ties may move the pixel; None unless asked
    grad_band: np.ndarray | None = None  # [N] bool, the Gaussians in the gradient band; None unless asked
    grad_weight: np.ndarray | None = None  # [H, W] relative change of the other gradient terms; None unless asked


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
           antialiased=False, pixel_offset=0.5, quat_order="wxyz", scale_activation="exp",
           opacity_activation="sigmoid", jacobian_guard=JACOBIAN_GUARD, sh_view_direction="camera_to_mean",
           sh_dir_means=None, sh_basis="graphdeco", sh_max_degree=3, sh_degree_arg=True, colour_clamp="min0",
           background_mode="weighted", sort_key="view_z", depth_mode="normalised",
           band=False) -> RenderOutput:
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

    Convention alternatives (the defaults are graphdeco's; docs/backends.md lists them):
        sh_view_direction: "camera_to_mean" (normalize(mean - camera centre)), "mean_to_camera"
            (its negative) or "world_origin" (normalize(mean)); sh_dir_means [N, 3]: the means
            the direction is taken from (default ``means``; fixed means make the direction
            "detached" under finite differences). sh_basis, colour_clamp: see `eval_sh`.
        sh_max_degree: the highest band evaluated (0..3); sh_degree_arg False evaluates every
            band ``sh`` holds whatever ``sh_degree`` says.
        sort_key: "view_z" (camera z), "distance" (to the camera centre), "world_z" or "index".
        depth_mode: "normalised" (D / alpha), "unnormalised" (D) or "distance" (the expected
            distance to the camera centre, normalised).
        pixel_offset, background_mode: see `composite`; quat_order, scale_activation,
            opacity_activation, jacobian_guard: see `project`.

    Returns:
        `RenderOutput` (rgb [H, W, 3], alpha [H, W], depth [H, W], radii [N], visible [N],
        band [H, W] bool and tie_slack [H, W], grad_band [N] bool, the Gaussians whose own
        gradient float32 may compute under another decision, and grad_weight [H, W], how much
        (relative) a decision there changes the other gradient terms (`reference.band`), all
        None unless ``band``).
    """
    proj = project(means, log_scales, quats, opacity_logits, K, world_to_camera, width, height,
                   mode=mode, eps2d=eps2d, near=near, far=far, radius=radius,
                   alpha_min=alpha_min, antialiased=antialiased, quat_order=quat_order,
                   scale_activation=scale_activation, opacity_activation=opacity_activation,
                   jacobian_guard=jacobian_guard)
    means = np.asarray(means, dtype=np.float64)
    sh = _as_array("sh", sh, (means.shape[0], None, 3), {})
    degree = sh_degree_for(sh.shape[1], sh_degree if sh_degree_arg else None)
    if isinstance(sh_max_degree, bool) or sh_max_degree not in (0, 1, 2, 3):
        raise ValueError(f"sh_max_degree: expected an int in 0..3, got {sh_max_degree!r}")
    degree = min(degree, int(sh_max_degree))

    # Colour of the visible Gaussians only (culled ones are never drawn).
    eye = camera_centre(world_to_camera)
    at = means if sh_dir_means is None else _as_array("sh_dir_means", sh_dir_means, (means.shape[0], 3), {})
    view = {"camera_to_mean": lambda m: m - eye, "mean_to_camera": lambda m: eye - m, "world_origin": lambda m: m}
    dirs = _normalize(view[_as_choice("sh_view_direction", sh_view_direction, SH_VIEW_DIRECTIONS)](at))
    colors = np.zeros((means.shape[0], 3))
    vis = proj.visible
    colors[vis] = eval_sh(sh[vis], dirs[vis], degree, basis=sh_basis, colour_clamp=colour_clamp)

    distance = np.linalg.norm(means - eye, axis=1)
    keys = {"view_z": proj.depths, "distance": distance, "world_z": means[:, 2],
            "index": np.arange(means.shape[0], dtype=np.float64)}[_as_choice("sort_key", sort_key, SORT_KEYS)]
    depth_of = distance if _as_choice("depth_mode", depth_mode, DEPTH_MODES) == "distance" else proj.depths
    errors = None
    if band:  # the boundary band (reference.band); its depth-tie test reads the compositing depths
        errors = projection_error(means, log_scales, quats, opacity_logits, K, world_to_camera, proj.conics,
                                  radius=radius, eps2d=eps2d, antialiased=antialiased)
    out = composite(proj.means2d, proj.conics, proj.opacities, colors, np.where(vis, depth_of, 0.0),
                    proj.cutoff_sq, vis, width, height, mode=mode, background=background,
                    alpha_min=alpha_min, alpha_max=alpha_max, transmittance_min=transmittance_min,
                    pixel_offset=pixel_offset, sort_keys=keys, background_mode=background_mode,
                    normalise_depth=depth_mode != "unnormalised", errors=errors)
    return RenderOutput(out.rgb, out.alpha, out.depth, proj.radii, proj.visible, out.band, out.tie_slack,
                        out.grad_band, out.grad_weight)
