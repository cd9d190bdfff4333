"""The boundary band: the pixels where float32 may take a discrete decision the other way.

A float32 rasterizer that follows the same conventions as this oracle differs from it by
rounding only -- a few ulp per composited term -- except at a pixel where some
contribution lies within float32 error of a discrete decision:

    the cutoff        sigma against 0.5 R² (3 sigma, or the opacity-aware radius)
    alpha_min         alpha = o exp(-sigma) against alpha_min
    the early stop    the transmittance T_next against transmittance_min
    a depth tie       two contributions whose camera z are within float32 error of each
                      other, composited in either order

At the first three float32 may add or drop a whole contribution and the pixel differs by
far more than rounding: those pixels are the band. A swap changes the pixel by a known
amount (T a_i a_j |c_i - c_j|), which widens that pixel's bound (the tie slack) instead. `projection_error` bounds, per Gaussian, the float32 error of
the quantities those decisions read; `pixel_band` marks one pixel. ``render(band=True)``
returns the band of a matched-mode render ([H, W] bool) and the tie slack ([H, W]).

The bounds are first-order worst cases (|δx| <= n u |x| for n roundings, u = 2^-24,
float32's unit roundoff), each constant counted below from the operations a float32
rasterizer performs (the inputs rounded to float32 included). Being worst cases they
overestimate the actual error (typically by 10-100x): the band holds every pixel that
float32 *could* decide differently, so outside it a rasterizer's error is rounding only.

The gradient band carries the band over to gradients (``render(band=True)``: ``grad_band``
[N] bool, ``grad_weight`` [H, W]). A Gaussian's gradient sums its per-pixel terms. Where
float32 may add or drop contribution k (a band pixel), k's own term there changes by a whole
term, and every other term at that pixel by a relative a_k at most (the transmittance behind k
changes by the factor 1 - a_k; the colour behind those in front by T_k a_k c_k); at an early
stop float32 may take differently, the contribution at the stop changes whole and every
other term by T there (about transmittance_min: the terms from the stop on are weighted by it); a depth swap changes the pair's terms whole and the others' by T a_i a_j.
One decision changes the gradient and not the image: the alpha_max clamp (alpha is continuous
across it, its derivative jumps to 0). So the gradient band is the Gaussians whose own term
some decision may change whole (the flipped, stopped, swapped and clamp-borderline ones: a
handful on a real model), and ``grad_weight`` the relative change every other term at that
pixel may take, which widens the other Gaussians' bound instead (as the tie slack widens the
forward bound). Outside the gradient band a Gaussian's gradient differs from the float64 one
by rounding and those weighted changes only.

Not in the band: per-Gaussian culling (near/far plane, the image border, the huge-Gaussian
cull), which flips a Gaussian only within float32 error of the near plane or the border,
where its contributions are already at the cutoff or off the image.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

U = 2.0 ** -24  # float32 unit roundoff

# Camera-space point t = Wr m + tw: m and W rounded to float32 (1 u each per product), a
# 3-term dot product plus tw (gamma_4 = 4 u): 6 u of s = |Wr| |m| + |tw|; 8 leaves room for
# an implementation that multiplies the homogeneous 4x4 matrix instead.
C_POINT = 8
# Sigma_2D = J Wr (R S)(R S)^T Wr^T J^T + eps2d I, normwise relative to |J|² |S|²:
# quaternion normalisation 4 u, rotation matrix entries 4, R S 1, (R S)(R S)^T 4,
# Wr . Wr^T 2 x (4 + 1 rounding of Wr), J's entries 3 x 2, J . J^T 2 x 4, + eps2d 1: 41 u; 48.
C_COV = 48
# sigma = 0.5 (A dx² + C dy²) + B dx dy: dx, dy 1 u each (squared: 2), 3 products, 3 adds,
# the 0.5: 8 u of sigma_abs = 0.5 (|A| dx² + |C| dy²) + |B dx dy|.
C_SIGMA = 8
# opacity = sigmoid(logit): exp, add, divide, 1 u each, 1 for the input rounding: 4 u.
C_OPACITY = 4
# alpha = opacity * exp(-sigma): exp 2 u, product 1 u.
C_ALPHA = 3


class ProjectionError(NamedTuple):
    """Per-Gaussian float32 error bounds of the projected quantities (all [N], float64)."""

    mean_px: np.ndarray  # |δ means2d| (pixels, max over u and v)
    depth: np.ndarray  # |δ z| (camera z, the sort key)
    cov_abs: np.ndarray  # ||δ Sigma_2D|| (pixels², normwise)
    inverse_rel: np.ndarray  # relative error of the conic from the 2x2 inversion: 3 u (AC + B²)/(AC - B²) + 2 u
    opacity_rel: np.ndarray  # |δ o| / o
    cutoff_abs: np.ndarray  # |δ (0.5 R²)|: 0 for 3 sigma (exactly 4.5), δ ln(o) for radius "opacity"
    position_id: np.ndarray  # [N] int: Gaussians with bitwise equal means share an id (they tie in float32 too)


def projection_error(means, log_scales, quats, opacity_logits, K, world_to_camera, conics, *,
                     radius="3sigma", eps2d=0.3, antialiased=False) -> ProjectionError:
    """Float32 error bounds of one projection (see the module doc for the constants).

    Args:
        means [N, 3], log_scales [N, 3], quats [N, 4], opacity_logits [N]: the parameters.
        K [3, 3], world_to_camera [4, 4]: the camera.
        conics [N, 3]: (A, B, C) of the projection (float64; zeros for culled Gaussians).
        radius, eps2d, antialiased: the projection's options.

    Returns:
        `ProjectionError`.
    """
    means = np.asarray(means, dtype=np.float64)
    log_scales = np.asarray(log_scales, dtype=np.float64)
    logits = np.asarray(opacity_logits, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    W = np.asarray(world_to_camera, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    with np.errstate(all="ignore"):
        t = means @ W[:3, :3].T + W[:3, 3]
        s = np.abs(means) @ np.abs(W[:3, :3]).T + np.abs(W[:3, 3])  # [N, 3] magnitude of each dot product
        z = np.abs(t[:, 2])
        dt = C_POINT * U * s
        # u = fx x / z + cx: first order in (δx, δz), plus the division, product and sum (3 u).
        du = fx / z * (dt[:, 0] + np.abs(t[:, 0] / z) * dt[:, 2]) + 3 * U * (np.abs(fx * t[:, 0] / z) + abs(cx))
        dv = fy / z * (dt[:, 1] + np.abs(t[:, 1] / z) * dt[:, 2]) + 3 * U * (np.abs(fy * t[:, 1] / z) + abs(cy))
        # |J|_F² (unclamped: the clamp only shrinks |x/z|) and |S|_F² = sum exp(2 log s) (R orthonormal).
        j2 = (fx / z) ** 2 * (1 + (t[:, 0] / z) ** 2) + (fy / z) ** 2 * (1 + (t[:, 1] / z) ** 2)
        s2 = np.exp(2 * np.clip(log_scales, -20, 20)).sum(axis=1)
        # exp(log s) with log s rounded: relative u |log s| per scale, twice in S S^T; J's entries
        # read t / z, relative C_POINT u s / z, twice in J . J^T.
        rel = C_COV * U + 2 * U * np.abs(log_scales).max(axis=1) + 2 * dt.max(axis=1) / z
        cov_abs = rel * j2 * s2
        A, B, C = np.asarray(conics, dtype=np.float64).T
        det_q = A * C - B * B
        inverse_rel = 3 * U * (A * C + B * B) / det_q + 2 * U
        o = 1 / (1 + np.exp(-logits))
        opacity_rel = C_OPACITY * U + U * np.abs(logits) * (1 - o)
        if antialiased:  # o * sqrt(det(Sigma_raw) / det(Sigma)): half the relative errors of both determinants
            xx, xy, yy = C / det_q, -B / det_q, A / det_q
            det = xx * yy - xy * xy
            det_raw = (xx - eps2d) * (yy - eps2d) - xy * xy
            ddet = cov_abs * (xx + yy) + 3 * U * (xx * yy + xy * xy)
            ddet_raw = cov_abs * (xx + yy) + 3 * U * ((xx - eps2d) * (yy - eps2d) + xy * xy)
            opacity_rel = opacity_rel + 0.5 * (ddet / det + ddet_raw / det_raw) + 2 * U
        cutoff_abs = opacity_rel + 2 * U if radius == "opacity" else np.zeros(len(means))
    _, position_id = np.unique(means, axis=0, return_inverse=True)
    bad = lambda x: np.where(np.isfinite(x), x, np.inf)  # noqa: E731 - culled: unbounded (never drawn)
    return ProjectionError(bad(np.maximum(du, dv)), bad(C_POINT * U * s[:, 2]), bad(cov_abs), bad(inverse_rel),
                           bad(opacity_rel), bad(cutoff_abs), position_id.reshape(-1))


def sigma_slack(err: ProjectionError, conics, cutoff_sq) -> np.ndarray:
    """[N] an upper bound of |δ sigma| at every pixel with sigma <= R² (twice the cutoff).

    With Q the conic and λ its largest eigenvalue, |Q d|² <= 2 λ sigma and sigma_abs <=
    (A + C) |d|² / 2 <= (A + C) sigma / λ_min; the bounding box of the matched-mode
    candidates is padded by this, so that a contribution float32 may keep is a candidate.
    """
    A, B, C = np.asarray(conics, dtype=np.float64).T
    with np.errstate(all="ignore"):
        half_tr, root = (A + C) / 2, np.sqrt(((A - C) / 2) ** 2 + B * B)
        lam, lam_min = half_tr + root, half_tr - root
        sig = np.asarray(cutoff_sq, dtype=np.float64)
        slack = (2 * np.sqrt(lam * sig) * err.mean_px + lam * sig * err.cov_abs
                 + (err.inverse_rel + C_SIGMA * U) * (A + C) * sig / lam_min + err.cutoff_abs)
    return np.where(np.isfinite(slack), slack, np.inf)


class PixelBand(NamedTuple):
    """One pixel's verdict (`pixel_bands`)."""

    in_band: bool  # float32 may add or drop a whole contribution here
    tie_slack: float  # how far swapping near-tied contributions moves the pixel (0 in the band)
    grad_own: np.ndarray  # [M] bool: candidates whose own gradient term here float32 may compute under another decision
    grad_weight: float  # how much (relative) such a decision changes every other candidate's gradient term here


def pixel_band(err: ProjectionError, cand, dx, dy, A, B, C, sigma, half_r2, alpha_raw, keep, alphas,
               stop, colors, depths, *, alpha_min, alpha_max, transmittance_min) -> tuple[bool, float]:
    """`pixel_bands` without the gradient band: (in the band, tie slack)."""
    out = pixel_bands(err, cand, dx, dy, A, B, C, sigma, half_r2, alpha_raw, keep, alphas, stop, colors, depths,
                      alpha_min=alpha_min, alpha_max=alpha_max, transmittance_min=transmittance_min)
    return out.in_band, out.tie_slack


def pixel_bands(err: ProjectionError, cand, dx, dy, A, B, C, sigma, half_r2, alpha_raw, keep, alphas,
                stop, colors, depths, *, alpha_min, alpha_max, transmittance_min) -> PixelBand:
    """Whether one pixel is in the band (module doc), how much depth ties widen its bound, and its
    part of the gradient band.

    Args:
        err: `projection_error` of the render. cand [M]: Gaussian indices of the candidates
            at this pixel, in compositing order; dx, dy, A, B, C, sigma, half_r2 (0.5 R²),
            alpha_raw (o exp(-sigma), unclamped), keep (passes the cutoff and
            alpha_min): [M] each. alphas [K]: the kept contributions' (clamped) alphas,
            stop: how many of them are composited (K when no early stop), colors [K, 3], depths [K].
        alpha_min, alpha_max, transmittance_min: the thresholds.

    Returns:
        `PixelBand`: the tie slack bounds how far swapping the near-tied contributions moves the
        pixel: any of rgb, alpha, or depth * alpha (camera z units). grad_own marks the
        contributions a decision here may add, drop, reorder or unclamp (their own gradient term
        here changes by a whole term); grad_weight bounds the relative change that decision makes
        to every other contribution's term here: a_k for an added or dropped contribution k (the
        transmittance behind it changes by the factor 1 - a_k, the colour behind those in front by
        T_k a_k c_k), the transmittance T at an early stop, T a_i a_j for a swap of i and j.
    """
    nothing = np.zeros(cand.size, dtype=bool)
    if cand.size == 0:
        return PixelBand(False, 0.0, nothing, 0.0)
    qx, qy = A * dx + B * dy, B * dx + C * dy
    sigma_abs = 0.5 * (np.abs(A) * dx * dx + np.abs(C) * dy * dy) + np.abs(B * dx * dy)
    # First order: ∂sigma/∂d = Q d against the mean's error; δQ = -Q δSigma Q gives
    # |δsigma| <= |Q d|² ||δSigma|| / 2; then the inversion's and sigma's own roundings.
    d_sigma = (np.abs(qx) + np.abs(qy)) * err.mean_px[cand] + 0.5 * (qx * qx + qy * qy) * err.cov_abs[cand] \
        + (err.inverse_rel[cand] + C_SIGMA * U) * sigma_abs
    d_alpha = d_sigma + err.opacity_rel[cand] + C_ALPHA * U  # relative error of alpha
    with np.errstate(divide="ignore"):
        cut_margin = sigma - half_r2
        log_alpha = np.log(alpha_raw / alpha_min)
        log_clamp = np.log(alpha_raw / alpha_max)
    cut_unsure = np.abs(cut_margin) <= d_sigma + err.cutoff_abs[cand]
    alpha_unsure = (np.abs(log_alpha) <= d_alpha) & (alpha_min <= alpha_max)
    cut_in = (cut_margin < 0) | cut_unsure
    alpha_in = (log_alpha > 0) | alpha_unsure
    may_keep = cut_in & alpha_in
    flip = (cut_unsure | alpha_unsure) & may_keep  # a contribution float32 may keep or skip
    # The alpha_max clamp: alpha is continuous across it, its derivative is not (gradient band only).
    own = flip | (may_keep & (np.abs(log_clamp) <= d_alpha) & (alpha_max < 1))
    weight = float(np.minimum(alpha_raw[flip], alpha_max).max(initial=0.0))
    if alphas.size == 0:
        return PixelBand(bool(flip.any()), 0.0, own, weight)
    kept, kept_at = cand[keep], np.flatnonzero(keep)
    # Early stop: 1 - a has relative error (a δa + u) / (1 - a) (δa = 0 when alpha_max clamps
    # it), the product one u per factor; compared with transmittance_min in log space.
    da = np.where(alpha_raw[keep] >= alpha_max, U, d_alpha[keep])
    last = min(stop + 1, alphas.size)  # the contributions composited, and the one that stopped it
    a = alphas[:last]
    T_before = np.concatenate([[1.0], np.cumprod(1 - a)])
    with np.errstate(divide="ignore"):
        eps_t = np.cumsum((a * da[:last] + U) / (1 - a) + U)
        log_t = np.log(T_before[1:] / transmittance_min) if transmittance_min > 0 else np.full(last, np.inf)
    stop_unsure = np.flatnonzero(np.abs(log_t) <= eps_t)
    if stop_unsure.size:
        # float32 may stop before the first unsure contribution m, or composite past it: m's own term
        # changes whole; every term from m on is weighted by T <= T_before[m] (about transmittance_min),
        # so the others change by that much relative to the pixel's terms.
        m = stop_unsure[0]
        own[kept_at[m]] = True
        weight = max(weight, float(T_before[m]))
    if flip.any() or stop_unsure.size:
        return PixelBand(True, 0.0, own, weight)
    # Depth order: adjacent contributions whose z may swap in float32 (unless their means are
    # bitwise equal: then float32 computes the same z for both and breaks the tie the same way).
    # A swap is no whole contribution: T (a_i c_i + (1 - a_i) a_j c_j) against the other order
    # differs by T a_i a_j (c_j - c_i) (alpha not at all: 1 - prod(1 - a) is order-free), so it
    # widens this pixel's bound by that much instead of putting the pixel in the band.
    if last > 1:
        ids, dz = err.position_id[kept[:last]], err.depth[kept[:last]]
        close = (np.diff(depths[:last]) <= dz[1:] + dz[:-1]) & (ids[1:] != ids[:-1])
        if np.any(close):
            k = np.flatnonzero(close)
            T = T_before[k]
            dc = np.maximum(np.abs(colors[k + 1] - colors[k]).max(axis=1), np.abs(depths[k + 1] - depths[k]))
            own[kept_at[k]] = own[kept_at[k + 1]] = True
            weight = max(weight, float(np.max(T * a[k] * a[k + 1])))
            return PixelBand(False, float(np.sum(T * a[k] * a[k + 1] * dc)), own, weight)
    return PixelBand(False, 0.0, own, weight)
