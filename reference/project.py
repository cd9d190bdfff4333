"""Projection of 3D Gaussians to the image plane (mirrors ``splatbench.raster.project``).

Written from ``docs/conventions.md`` only; every step below carries the number of the
step it implements there. Everything is float64.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

MODES = ("matched", "exact")
RADII = ("3sigma", "opacity")
# Convention alternatives the oracle can follow besides graphdeco's (docs/backends.md, the vocabulary).
QUAT_ORDERS = ("wxyz", "xyzw")
SCALE_ACTIVATIONS = ("exp", "raw")  # raw: log_scales used as the scales themselves
OPACITY_ACTIVATIONS = ("sigmoid", "raw")  # raw: logits clamped to [0, 1] used as opacities
LOG_SCALE_CLIP = 20.0  # scales = exp(clip(log_scales, -20, 20)) in matched mode
BIG_FACTOR = 1e4  # cull when a 2D variance exceeds (1e4 * max(W, H))^2
JACOBIAN_GUARD = 0.3  # graphdeco's 1.3 * tan(fov / 2) limit, split per side


# ----------------------------------------------------------------------------
# Boundary checks (shared by the modules of this package; nothing from splatbench)
# ----------------------------------------------------------------------------

def _as_array(name, value, spec, sizes, *, allow_inf=False):
    """Return ``value`` as a float64 array of shape ``spec``, or raise a one-line ValueError.

    ``spec`` holds ints (exact sizes), None (any) or letters (sizes that must agree across
    fields, bound in ``sizes``). Non-finite entries are rejected, naming the first bad
    index; with ``allow_inf`` only NaN is rejected.
    """
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot convert to a float64 array ({exc})") from None
    want = "[" + ", ".join("?" if d is None else str(d) for d in spec) + "]"
    if array.ndim != len(spec):
        raise ValueError(f"{name}: expected shape {want}, got {list(array.shape)}")
    for got, dim in zip(array.shape, spec):
        if isinstance(dim, str) and sizes.setdefault(dim, got) != got:
            raise ValueError(f"{name}: expected shape {want} with {dim}={sizes[dim]}, got {list(array.shape)}")
        if isinstance(dim, int) and got != dim:
            raise ValueError(f"{name}: expected shape {want}, got {list(array.shape)}")
    bad = np.isnan(array) if allow_inf else ~np.isfinite(array)
    if bad.any():
        where = np.unravel_index(int(np.argmax(bad)), array.shape)
        raise ValueError(f"{name}: non-finite value {float(array[where])!r} at index {[int(i) for i in where]}")
    return array


def _as_size(name, value):
    """A positive int image size."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name}: expected a positive int, got {value!r}")
    return int(value)


def _as_choice(name, value, options):
    if value not in options:
        raise ValueError(f"{name}: expected one of {list(options)}, got {value!r}")
    return value


def _as_scalar(name, value, *, low=None, allow_inf=False):
    """A float scalar, finite (or only not NaN with ``allow_inf``), optionally >= ``low``."""
    x = float(value)
    ok = not np.isnan(x) if allow_inf else np.isfinite(x)
    if not ok or (low is not None and x < low):
        raise ValueError(f"{name}: expected a {'' if allow_inf else 'finite '}number"
                         f"{'' if low is None else f' >= {low}'}, got {value!r}")
    return x


def _sigmoid(x):
    """Logistic function without overflow warnings for large |x|."""
    e = np.exp(-np.abs(x))
    return np.where(x >= 0, 1.0 / (1.0 + e), e / (1.0 + e))


# ----------------------------------------------------------------------------
# 3D covariance
# ----------------------------------------------------------------------------

QUAT_MIN = 1e-20  # conventions.md: smaller quaternions count as zero


def quat_to_rotmat(quats):
    """Rotation matrices from quaternions of any length (mirrors splatbench's quaternion activation).

    Args:
        quats: [N, 4] (w, x, y, z), finite, any length. Normalised overflow-safely as
            ``q' = q / max|q_i|`` then ``q' / |q'|``; a quaternion with max|q_i| < 1e-20
            counts as zero, and a zero quaternion gives ``q̂ = 0``, which the formula
            below maps to the identity.

    Returns:
        R: [N, 3, 3] float64.
    """
    q = _as_array("quats", quats, (None, 4), {})
    biggest = np.max(np.abs(q), axis=1, keepdims=True)  # [N, 1]
    q = np.divide(q, biggest, out=np.zeros_like(q), where=biggest >= QUAT_MIN)
    length = np.sqrt(np.sum(q * q, axis=1, keepdims=True))  # in [1, 2] unless q == 0
    q = np.divide(q, length, out=np.zeros_like(q), where=length > 0)
    w, x, y, z = q.T
    R = np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], axis=1)
    return R.reshape(-1, 3, 3)


def covariance(log_scales, quats, *, clip=True):
    """World-space covariances ``Σ = R S Sᵀ Rᵀ`` (mirrors splatbench's covariance step of project).

    Args:
        log_scales: [N, 3]; ``scales = exp(clip(log_scales, -20, 20))``, or
            ``exp(log_scales)`` with ``clip=False`` (exact mode).
        quats: [N, 4] (w, x, y, z), any length (see `quat_to_rotmat`).

    Returns:
        Σ: [N, 3, 3] float64, symmetric positive semi-definite.
    """
    sizes = {}
    log_scales = _as_array("log_scales", log_scales, ("N", 3), sizes)
    _as_array("quats", quats, ("N", 4), sizes)
    if clip:
        log_scales = np.clip(log_scales, -LOG_SCALE_CLIP, LOG_SCALE_CLIP)
    M = quat_to_rotmat(quats) * np.exp(log_scales)[:, None, :]  # R S: scales the columns
    return np.einsum("nik,njk->nij", M, M)  # (R S)(R S)ᵀ


# ----------------------------------------------------------------------------
# Projection
# ----------------------------------------------------------------------------

class Projection(NamedTuple):
    """Per-Gaussian screen-space quantities. Culled Gaussians hold zeros (and radius 0),
    except ``cutoff_sq``, which is inf for every Gaussian in exact mode."""

    means2d: np.ndarray  # [N, 2] (u, v) continuous pixel coordinates, origin top-left corner
    conics: np.ndarray  # [N, 3] (A, B, C) = (xx, xy, yy) of inverse(Σ2D)
    depths: np.ndarray  # [N] camera z
    opacities: np.ndarray  # [N] sigmoid(logit), times the antialiasing factor when enabled
    cutoff_sq: np.ndarray  # [N] R², Mahalanobis radius squared (inf in exact mode)
    radii: np.ndarray  # [N] int32, ceil(max(rx, ry)); 0 when culled
    visible: np.ndarray  # [N] bool, radii > 0


def project(means, log_scales, quats, opacity_logits, K, world_to_camera, width, height, *,
            mode="matched", eps2d=0.3, near=0.01, far=1e10, radius="3sigma",
            alpha_min=1 / 255, antialiased=False, quat_order="wxyz", scale_activation="exp",
            opacity_activation="sigmoid", jacobian_guard=JACOBIAN_GUARD) -> Projection:
    """Project 3D Gaussians to 2D (mirrors ``splatbench.raster.project``).

    Args:
        means: [N, 3] world positions.
        log_scales: [N, 3] log of the per-axis scales.
        quats: [N, 4] (w, x, y, z) rotations, any length.
        opacity_logits: [N]; opacity = sigmoid(logit).
        K: [3, 3] intrinsics [[fx, 0, cx], [0, fy, cy], [0, 0, 1]].
        world_to_camera: [4, 4] OpenCV camera (x right, y down, z forward).
        width, height: image size in pixels.
        mode: "matched" follows conventions.md steps 1-10; "exact" is the smooth function
            for finite differences: culls only outside the clip planes (near <= z <= far),
            no log-scale clip, no radius cutoff (cutoff_sq = inf), no big or off-screen
            cull; the Jacobian clamp stays (it belongs to the projection model). Radii are
            then the 3-sigma extent, for information only.
        eps2d: added to the diagonal of Σ2D (low-pass filter).
        near, far: matched-mode depth culling planes.
        radius: "3sigma" (R² = 9) or "opacity" (R² = 2 ln(o / alpha_min), culling
            o <= alpha_min).
        alpha_min: alpha threshold used by radius="opacity".
        antialiased: Mip-Splatting opacity compensation o *= sqrt(det Σ2D_raw / det Σ2D).
        quat_order: "wxyz" (graphdeco) or "xyzw" (quaternions read with w last).
        scale_activation: "exp" (graphdeco) or "raw" (log_scales used as scales).
        opacity_activation: "sigmoid" (graphdeco) or "raw" (logits clamped to [0, 1]).
        jacobian_guard: the Jacobian clamp's margin (0.3: graphdeco's 1.3 x the half field of
            view), or None for no clamp.

    Returns:
        `Projection` (means2d [N, 2], conics [N, 3], depths [N], opacities [N],
        cutoff_sq [N], radii [N] int32, visible [N] bool).

    Note: a Gaussian whose Σ2D is not finite or not positive definite is dropped in
    exact mode as well (it cannot be drawn; with eps2d > 0 this needs float64 overflow).
    """
    sizes = {}
    means = _as_array("means", means, ("N", 3), sizes)
    log_scales = _as_array("log_scales", log_scales, ("N", 3), sizes)
    quats = _as_array("quats", quats, ("N", 4), sizes)
    logits = _as_array("opacity_logits", opacity_logits, ("N",), sizes)
    K = _as_array("K", K, (3, 3), sizes)
    W = _as_array("world_to_camera", world_to_camera, (4, 4), sizes)
    width, height = _as_size("width", width), _as_size("height", height)
    exact = _as_choice("mode", mode, MODES) == "exact"
    _as_choice("radius", radius, RADII)
    eps2d = _as_scalar("eps2d", eps2d, low=0.0)
    near, far = _as_scalar("near", near), _as_scalar("far", far, allow_inf=True)
    alpha_min = _as_scalar("alpha_min", alpha_min, low=0.0)
    if _as_choice("quat_order", quat_order, QUAT_ORDERS) == "xyzw":
        quats = quats[:, [3, 0, 1, 2]]
    raw_scales = _as_choice("scale_activation", scale_activation, SCALE_ACTIVATIONS) == "raw"
    raw_opacity = _as_choice("opacity_activation", opacity_activation, OPACITY_ACTIVATIONS) == "raw"
    guard = np.inf if jacobian_guard is None else _as_scalar("jacobian_guard", jacobian_guard, low=0.0)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    n = means.shape[0]

    # Culled Gaussians may divide by zero or overflow below; they are masked at the end.
    with np.errstate(all="ignore"):
        # 1. Camera space.
        Wr = W[:3, :3]
        t = means @ Wr.T + W[:3, 3]  # [N, 3]
        z = t[:, 2]
        # 2. Depth cull: the camera's clip planes bound the scene in both modes (in exact mode
        #    too: a Gaussian a hair in front of the eye is not part of what the camera sees, and
        #    without the plane its projection, ~1/z, would cover the image).
        keep = (z >= near) & (z <= far)

        # 3. EWA Jacobian, with graphdeco's clamp of x/z and y/z, in both modes: the clamp is part
        #    of the projection model (where the EWA linearisation is taken), not of the rasterizer's
        #    shortcuts. Unclamped, a Gaussian far outside the view (x/z ~ 100 near the eye) gets a
        #    footprint stretched by ~x/z that smears across the image: on garden that alone put the
        #    exact render 17 dB from every rasterizer (46.5 dB with the clamp; docs/conventions.md).
        tx, ty = t[:, 0], t[:, 1]
        lim_x_pos = (width - cx) / fx + guard * (width / 2) / fx
        lim_x_neg = cx / fx + guard * (width / 2) / fx
        lim_y_pos = (height - cy) / fy + guard * (height / 2) / fy
        lim_y_neg = cy / fy + guard * (height / 2) / fy
        tx = z * np.clip(t[:, 0] / z, -lim_x_neg, lim_x_pos)
        ty = z * np.clip(t[:, 1] / z, -lim_y_neg, lim_y_pos)
        J = np.zeros((n, 2, 3))
        J[:, 0, 0] = fx / z
        J[:, 0, 2] = -fx * tx / z**2
        J[:, 1, 1] = fy / z
        J[:, 1, 2] = -fy * ty / z**2
        # The 2D mean uses the unclamped camera point.
        means2d = np.stack([fx * t[:, 0] / z + cx, fy * t[:, 1] / z + cy], axis=1)

        # 4. Σ2D = J Wr Σ Wrᵀ Jᵀ + eps2d I.
        if raw_scales:  # the scales' sign does not matter: Σ = R S Sᵀ Rᵀ
            M = quat_to_rotmat(quats) * log_scales[:, None, :]
            cov_world = np.einsum("nik,njk->nij", M, M)
        else:
            cov_world = covariance(log_scales, quats, clip=not exact)
        cov_cam = Wr @ cov_world @ Wr.T
        cov2d_raw = J @ cov_cam @ J.transpose(0, 2, 1)  # [N, 2, 2]
        xx = cov2d_raw[:, 0, 0] + eps2d
        xy = cov2d_raw[:, 0, 1]
        yy = cov2d_raw[:, 1, 1] + eps2d
        det = xx * yy - xy * xy

        # 5. Cull degenerate or non-finite Σ2D (both modes) and huge ones (matched).
        keep &= np.isfinite(means2d).all(axis=1) & np.isfinite(xx) & np.isfinite(yy)
        keep &= np.isfinite(xy) & np.isfinite(det) & (det > 0)
        if not exact:
            keep &= np.maximum(xx, yy) <= (BIG_FACTOR * max(width, height)) ** 2

        # 6. Conic = inverse(Σ2D) as (A, B, C).
        conics = np.stack([yy / det, -xy / det, xx / det], axis=1)
        keep &= np.isfinite(conics).all(axis=1)

        # 7. Opacity, with the Mip-Splatting compensation.
        opacities = np.clip(logits, 0.0, 1.0) if raw_opacity else _sigmoid(logits)
        if antialiased:
            det_raw = np.maximum(cov2d_raw[:, 0, 0] * cov2d_raw[:, 1, 1] - cov2d_raw[:, 0, 1] ** 2, 0.0)
            opacities = opacities * np.sqrt(det_raw / det)
            keep &= np.isfinite(opacities)

        # 8. Cutoff radius (Mahalanobis units), R².
        if exact:
            cutoff_sq = np.full(n, np.inf)
        elif radius == "3sigma":
            cutoff_sq = np.full(n, 9.0)
        else:
            keep &= opacities > alpha_min
            cutoff_sq = 2.0 * np.log(opacities / alpha_min)

        # 9. Screen extent (exact bounding box of the ellipse d² <= R²) and off-screen cull.
        r = 3.0 if exact else np.sqrt(cutoff_sq)
        rx, ry = r * np.sqrt(xx), r * np.sqrt(yy)
        if not exact:
            u, v = means2d[:, 0], means2d[:, 1]
            keep &= (u + rx >= 0) & (u - rx <= width) & (v + ry >= 0) & (v - ry <= height)

        # 10. Integer radii; visible = radii > 0.
        extent = np.where(keep, np.ceil(np.maximum(rx, ry)), 0.0)
        radii = np.clip(extent, 0, np.iinfo(np.int32).max).astype(np.int32)
        visible = radii > 0

    zero = ~visible
    return Projection(
        means2d=np.where(zero[:, None], 0.0, means2d),
        conics=np.where(zero[:, None], 0.0, conics),
        depths=np.where(zero, 0.0, z),
        opacities=np.where(zero, 0.0, opacities),
        cutoff_sq=cutoff_sq if exact else np.where(zero, 0.0, cutoff_sq),
        radii=radii,
        visible=visible,
    )
