"""Seeding Gaussians from a point cloud (e.g. COLMAP's SfM points), as graphdeco-inria does."""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np

from splatbench.errors import InputError
from splatbench.gaussians import SH_BASES, SH_C0, Gaussians
from splatbench.validate import as_float_array, check_shape

#: Lower bound on the mean squared neighbour distance (graphdeco's ``clamp_min(dist2, 1e-7)``).
MIN_DIST2 = 1e-7


def knn_mean_sq_dist(points: np.ndarray, k: int = 3) -> np.ndarray:
    """[M] float64 mean squared distance from each point to its ``k`` nearest *other* points.

    Duplicated points count as neighbours at distance 0. With fewer than ``k + 1``
    points, all the other points are used.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    m = len(pts)
    k_eff = min(k, m - 1)
    if k_eff < 1:
        raise InputError(f"points: need at least 2 points for neighbour distances, got {m}")
    dist, _ = cKDTree(pts).query(pts, k=k_eff + 1)
    # column 0 is a zero distance (the point itself, or an exact duplicate of it):
    # dropping it removes exactly one zero, which is the point itself.
    return np.mean(dist[:, 1:] ** 2, axis=1)


def from_points(points: Any, colors: Any, *, sh_degree: int = 3, opacity: float = 0.1) -> Gaussians:
    """Seed one isotropic Gaussian per point, as graphdeco-inria's ``create_from_pcd``.

    Args:
        points: [M, 3] positions (M >= 2).
        colors: [M, 3] RGB, uint8 in 0..255 or float in [0, 1].
        sh_degree: SH degree 0..3 of the result; bands above 0 start at zero.
        opacity: initial opacity in (0, 1); stored as its logit.

    Returns:
        `Gaussians` with ``means = points``, ``sh[:, 0] = (rgb - 0.5) / C0`` (so the
        degree-0 colour ``C0·sh0 + 0.5`` is ``rgb``), ``log_scales = log(sqrt(d2))``
        on all three axes, where ``d2 = max(mean squared distance to the 3 nearest
        other points, 1e-7)`` (graphdeco clamps the mean *squared* distance), identity
        quaternions (1, 0, 0, 0) and ``opacity_logits = logit(opacity)``.
    """
    sizes: dict[str, int] = {}
    pts = as_float_array("points", points, ("M", 3), sizes, dtype=np.float64)
    col = np.asarray(colors)
    check_shape("colors", col.shape, ("M", 3), sizes)
    if col.dtype == np.uint8:
        rgb = col.astype(np.float64) / 255.0
    elif np.issubdtype(col.dtype, np.floating):
        rgb = as_float_array("colors", col, ("M", 3), sizes, dtype=np.float64)
        bad = (rgb < 0) | (rgb > 1)
        if bad.any():
            where = np.unravel_index(int(np.argmax(bad)), bad.shape)
            raise InputError(f"colors: float colours must be in [0, 1], got {rgb[where]!r} "
                             f"at index {[int(i) for i in where]}")
    else:
        raise InputError(f"colors: expected uint8 or float in [0, 1], got dtype {col.dtype}")
    try:
        degree = operator.index(sh_degree)
    except TypeError:
        raise InputError(f"sh_degree: expected an int in 0..3, got {sh_degree!r}") from None
    if not 0 <= degree <= 3:
        raise InputError(f"sh_degree: expected an int in 0..3, got {degree}")
    o = float(opacity) if isinstance(opacity, (int, float, np.floating, np.integer)) else math.nan
    if not 0 < o < 1:
        raise InputError(f"opacity: expected a number in (0, 1), got {opacity!r}")

    m = len(pts)
    dist2 = np.maximum(knn_mean_sq_dist(pts), MIN_DIST2)
    log_scales = np.repeat(np.log(np.sqrt(dist2))[:, None], 3, axis=1)
    sh = np.zeros((m, SH_BASES[degree], 3), dtype=np.float64)
    sh[:, 0, :] = (rgb - 0.5) / SH_C0
    quats = np.zeros((m, 4))
    quats[:, 0] = 1.0
    return Gaussians(
        means=pts,
        log_scales=log_scales,
        quats=quats,
        opacity_logits=np.full(m, math.log(o / (1 - o))),
        sh=sh,
    )
