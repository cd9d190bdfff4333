"""One comparison helper for every fast-vs-reference test (pytorch3d's `_compare_impls` idea).

Reports the largest absolute difference and where it happens; on failure, writes
the fast image, the reference image and their difference as PNGs to a named folder.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ARTIFACTS = Path(os.environ.get("SPLATBENCH_TEST_ARTIFACTS", Path(__file__).parent / "_artifacts"))
EPS32 = float(np.finfo(np.float32).eps)  # 1.19e-7: float32 unit roundoff is EPS32 / 2


def _save_pngs(tag: str, fast: np.ndarray, ref: np.ndarray) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image as mpimg

    folder = ARTIFACTS / tag
    folder.mkdir(parents=True, exist_ok=True)
    diff = np.abs(fast.astype(np.float64) - ref)
    scale = max(float(diff.max()), 1e-12)
    lo, hi = float(min(fast.min(), ref.min())), float(max(fast.max(), ref.max()))
    norm = lambda x: np.clip((x - lo) / max(hi - lo, 1e-12), 0, 1)  # noqa: E731
    for name, img in (("fast", norm(fast)), ("reference", norm(ref)), ("difference", diff / scale)):
        mpimg.imsave(folder / f"{name}.png", img if img.ndim == 3 else img, cmap=None if img.ndim == 3 else "magma")
    return folder


def assert_images_close(tag: str, fast: np.ndarray, ref: np.ndarray, atol: float, *,
                        band: np.ndarray | None = None, slack: np.ndarray | None = None) -> None:
    """Assert |fast - ref| <= atol + slack at every pixel outside ``band``.

    ``band`` [H, W] bool is the boundary band the oracle derives (`reference.band`): pixels
    where some contribution lies within float32 error of a discrete decision (the radius
    cutoff, alpha_min, the early stop) and float32 may add or drop a whole contribution.
    ``slack`` [H, W] widens a pixel's bound by what a depth tie there can change.
    Both None: |fast - ref| <= atol everywhere. Uses `splatbench.verification.bounds.over_bound`.
    """
    from splatbench.verification.bounds import over_bound

    fast = np.asarray(fast, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    assert fast.shape == ref.shape, f"{tag}: shape {fast.shape} != {ref.shape}"
    assert np.isfinite(fast).all(), f"{tag}: fast output has non-finite values"
    err = np.abs(fast - ref)
    per_pixel = err.reshape(err.shape[0], err.shape[1], -1).max(-1) if err.ndim >= 2 else err
    outliers, outside = over_bound(per_pixel, band, slack, atol)
    if outside:
        where = np.unravel_index(int(np.argmax(err)), err.shape)
        folder = _save_pngs(tag, fast.astype(np.float32), ref)
        size = 0 if band is None else int(np.sum(band))
        raise AssertionError(
            f"{tag}: {outside} pixels exceed atol={atol:.2e} outside the boundary band ({outliers} in all; band "
            f"{size} pixels); max |diff| "
            f"{err.max():.3e} at {tuple(int(i) for i in where)} (fast {fast[where]:.6g}, ref {ref[where]:.6g}); "
            f"images written to {folder}")


def assert_render_close(tag: str, rgb, alpha, depth, ref, atol: float) -> None:
    """`assert_images_close` on rgb, alpha and depth * alpha against ``ref`` (a `reference.RenderOutput`
    rendered with ``band=True``): |error| <= atol (+ the tie slack) outside the boundary band.

    Depth is compared as depth * alpha (the composited sum of T a z, the quantity the
    rasterizer computes) scaled by the largest depth in the scene, because depth = sum / alpha
    amplifies alpha's absolute error by 1 / alpha; the tie slack is in those units already.
    """
    assert ref.band is not None, f"{tag}: render the reference with band=True"
    assert_images_close(f"{tag}-rgb", rgb, ref.rgb, atol, band=ref.band, slack=ref.tie_slack)
    assert_images_close(f"{tag}-alpha", alpha, ref.alpha, atol, band=ref.band, slack=ref.tie_slack)
    z_max = max(1.0, float(np.abs(ref.depth).max()))
    assert_images_close(f"{tag}-depth", np.asarray(depth) * np.asarray(alpha), ref.depth * ref.alpha, atol * z_max,
                        band=ref.band, slack=ref.tie_slack)


@dataclass(frozen=True)
class GradAgreement:
    rel_l2: float   # |a - b| / |b|
    cosine: float   # a.b / (|a| |b|)


def grad_agreement(a: np.ndarray, b: np.ndarray) -> GradAgreement:
    a = np.asarray(a, dtype=np.float64).ravel()
    b = np.asarray(b, dtype=np.float64).ravel()
    nb = np.linalg.norm(b)
    na = np.linalg.norm(a)
    if nb == 0.0:
        return GradAgreement(0.0 if na == 0.0 else np.inf, 1.0 if na == 0.0 else 0.0)
    cos = float(a @ b / (na * nb)) if na > 0 else 0.0
    return GradAgreement(float(np.linalg.norm(a - b) / nb), cos)


def assert_grads_agree(tag: str, a: np.ndarray, b: np.ndarray, *, rel_l2: float, cosine: float) -> GradAgreement:
    """Assert relative L2 error <= ``rel_l2`` and cosine similarity >= ``cosine``."""
    assert np.isfinite(a).all(), f"{tag}: non-finite gradient"
    g = grad_agreement(a, b)
    assert g.rel_l2 <= rel_l2 and g.cosine >= cosine, (
        f"{tag}: relative L2 {g.rel_l2:.3e} (max {rel_l2:.1e}), cosine {g.cosine:.8f} (min {cosine})")
    return g
