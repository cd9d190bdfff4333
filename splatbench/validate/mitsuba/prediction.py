"""The isotropic closed form: what each renderer computes for disjoint isotropic Gaussians.

`isotropic_prediction` predicts both images and bounds their difference (derivation in
docs/validation.md); `checks.check_tight` holds the measured images to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from splatbench.backends.builtins.mitsuba_scene import ELLIPSOID_EXTENT
from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.gaussians import SH_C0, Gaussians

_EPS32 = float(np.finfo(np.float32).eps)


@dataclass(frozen=True)
class IsotropicPrediction:
    """What each renderer computes for disjoint isotropic degree-0 Gaussians, in closed form.

    splat, traced: [H, W, 3] float64 predicted images (`isotropic_prediction`).
    bound_max: per-pixel bound on |splat - traced| (affine term + truncation band +
    float32 allowance); bound_psnr: the PSNR that the bound guarantees.
    rho: [N] ``max |r - 1|`` over each Gaussian's footprint, ``r = m_ray^2 / m_affine^2``.
    band_pixels: pixels where one renderer may truncate and the other not.
    """

    splat: np.ndarray
    traced: np.ndarray
    bound_max: float
    bound_psnr: float
    rho: np.ndarray
    band_pixels: int


def isotropic_prediction(gaussians: Gaussians, camera: Camera) -> IsotropicPrediction:
    """Closed-form images and error bound for isotropic, degree-0, screen-disjoint Gaussians.

    For an isotropic Gaussian (sigma, mean at camera coordinates (x, y, z), ``m = (x/z,
    y/z)``) and the ray of a pixel with normalised coordinates ``a = ((u-cx)/fx,
    (v-cy)/fy)``, the EWA splat's Mahalanobis distance is
    ``m_a^2 = (z/sigma)^2 (|a-m|^2 + ((a-m) x m)^2) / (1 + |m|^2)`` and the ray's is
    ``m_e^2 = (z/sigma)^2 (|a-m|^2 + ((a-m) x m)^2) / (1 + |a|^2)`` (Lagrange's identity;
    docs/validation.md), so ``m_e^2 = r m_a^2`` with ``r = (1+|m|^2)/(1+|a|^2)``. With
    ``rho = max |r - 1|`` over the footprint, where both keep the Gaussian
    ``|o c (e^{-m_a^2/2} - e^{-r m_a^2/2})| <= o c rho / ((1 - rho) e)``; in the band
    ``9/(1+rho) < m_a^2 <= 9/(1-rho)`` one of them may cut it, costing at most
    ``o c e^{-9(1-rho)/2}``. A float32 allowance ``o c e^{-1/2} 8 eps32 D/sigma`` (the
    ray's peak point is computed in float32 at distance D) is added. Requires
    footprints (``m_a^2 <= 18``) that no two Gaussians share; `InputError` otherwise.
    """
    n = len(gaussians)
    scales = gaussians.scales.astype(np.float64)
    if n == 0 or not np.allclose(scales, scales[:, :1], rtol=1e-6):
        raise InputError("gaussians: isotropic_prediction needs N >= 1 isotropic Gaussians (equal scales)")
    if gaussians.sh_degree != 0:
        raise InputError(f"gaussians: isotropic_prediction needs SH degree 0, got {gaussians.sh_degree}")
    sigma = scales[:, 0]
    w2c = camera.world_to_camera
    cam_pts = gaussians.means.astype(np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
    z = cam_pts[:, 2]
    if not np.all(z > 6 * sigma):
        raise InputError("gaussians: isotropic_prediction needs every Gaussian's 3-sigma ball in front of the camera")
    m = cam_pts[:, :2] / z[:, None]
    opac = gaussians.opacities.astype(np.float64)
    colour = np.maximum(SH_C0 * gaussians.sh[:, 0, :].astype(np.float64) + 0.5, 0.0)  # [N, 3]
    jj, ii = np.meshgrid(np.arange(camera.width) + 0.5, np.arange(camera.height) + 0.5)
    a = np.stack([(jj - camera.cx) / camera.fx, (ii - camera.cy) / camera.fy], axis=-1)  # [H, W, 2]
    a2 = np.sum(a * a, axis=-1)
    splat = np.zeros((camera.height, camera.width, 3))
    traced = np.zeros_like(splat)
    bound = np.zeros((camera.height, camera.width))
    owner = np.full((camera.height, camera.width), -1)
    rho = np.zeros(n)
    band_pixels = 0
    for k in range(n):
        d = a - m[k]
        cross = d[..., 0] * m[k, 1] - d[..., 1] * m[k, 0]
        common = (z[k] / sigma[k]) ** 2 * (np.sum(d * d, axis=-1) + cross * cross)
        m2_affine = common / (1.0 + m[k] @ m[k])
        m2_ray = common / (1.0 + a2)
        near = m2_affine <= 18.0
        if np.any(owner[near] >= 0):
            raise InputError(f"gaussians: footprints of Gaussians {int(owner[near].max())} and {k} overlap; "
                             f"isotropic_prediction needs screen-disjoint Gaussians")
        owner[near] = k
        r = m2_ray[near] / np.where(m2_affine[near] > 0, m2_affine[near], 1.0)
        r = np.where(m2_affine[near] > 0, r, 1.0)
        rho[k] = float(np.max(np.abs(r - 1.0))) if r.size else 0.0
        if rho[k] >= 0.5:
            raise InputError(f"gaussians: Gaussian {k} is too large for the bound (rho = {rho[k]:.3f} >= 0.5)")
        keep_a = m2_affine <= ELLIPSOID_EXTENT ** 2
        keep_e = m2_ray <= ELLIPSOID_EXTENT ** 2
        splat += (opac[k] * np.exp(-0.5 * m2_affine) * keep_a)[..., None] * colour[k]
        traced += (opac[k] * np.exp(-0.5 * m2_ray) * keep_e)[..., None] * colour[k]
        peak = opac[k] * float(colour[k].max())
        dist = float(np.linalg.norm(cam_pts[k]))
        f32 = peak * math.exp(-0.5) * 8 * _EPS32 * dist / sigma[k]
        inside = m2_affine <= 9.0 / (1.0 + rho[k])
        band = (m2_affine > 9.0 / (1.0 + rho[k])) & (m2_affine <= 9.0 / (1.0 - rho[k]))
        bound[inside] = peak * rho[k] / ((1.0 - rho[k]) * math.e) + f32
        bound[band] = peak * math.exp(-4.5 * (1.0 - rho[k])) + f32
        band_pixels += int(band.sum())
    mse_bound = float(np.mean(bound ** 2))  # every channel's error is at most the pixel's bound
    bound_psnr = math.inf if mse_bound == 0 else -10.0 * math.log10(mse_bound)
    return IsotropicPrediction(splat, traced, float(bound.max()), bound_psnr, rho, band_pixels)

