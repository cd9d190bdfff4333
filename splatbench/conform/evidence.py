"""What a backend's render of a probe scene does differently from the oracle's, in words: how much of
the oracle's footprint it covers, and where a defect has no cause the evidence supports, how its image
differs (coverage, centroid, orientation and size of the footprint, a mirror image).

Both work on the alpha channel (the footprint) where the backend produces one, else on the rgb sum.
"""

from __future__ import annotations

import math

import numpy as np

#: A pixel is drawn where alpha reaches this (1/20: well above any float32 error, far below an
#: opaque footprint's core).
DRAWN_ALPHA = 0.05
#: A scene is "(nearly) undrawn" when the backend draws under this fraction of the pixels the oracle
#: draws: a cull or a zero opacity, not a shifted or reshaped footprint (which keeps most of them).
UNDRAWN = 0.25
#: ... judged only on scenes where the oracle draws at least this many pixels (a footprint of one or
#: two pixels drops out under a half-pixel shift alone).
UNDRAWN_MIN_PIXELS = 10
_ANGLE_DEG = 3.0    # orientations closer than this are the same
_SHIFT_PX = 0.1     # centroid shifts below this are not reported
_RATIO = 1.1        # mass or size ratios within this of 1 are not reported
_ELONGATED = 1.2    # an ellipse's orientation is defined when its axes differ by this ratio


def footprint(out: np.ndarray, has_alpha: bool) -> np.ndarray:
    """[H, W] non-negative weight of a render [H, W, 5]: alpha, or the rgb sum without alpha."""
    return np.clip(out[..., 3] if has_alpha else out[..., :3].sum(-1), 0, None)


def coverage(got: np.ndarray, ref: np.ndarray, has_alpha: bool) -> tuple[int, int]:
    """(pixels the oracle draws, how many of them the backend draws too) on one scene [H, W, 5]."""
    drawn_ref = footprint(ref, has_alpha) >= DRAWN_ALPHA
    drawn_got = footprint(got, has_alpha) >= DRAWN_ALPHA
    return int(drawn_ref.sum()), int((drawn_ref & drawn_got).sum())


def undrawn(got: np.ndarray, ref: np.ndarray, has_alpha: bool) -> bool:
    """Whether the backend draws (nearly) nothing where the oracle draws (module constants)."""
    want, have = coverage(got, ref, has_alpha)
    return want >= UNDRAWN_MIN_PIXELS and have < UNDRAWN * want


def _moments(w: np.ndarray):
    m = float(w.sum())
    if m <= 0:
        return None
    ii, jj = np.mgrid[:w.shape[0], :w.shape[1]] + 0.5
    cx, cy = float((w * jj).sum() / m), float((w * ii).sum() / m)
    cxx = float((w * (jj - cx) ** 2).sum() / m)
    cyy = float((w * (ii - cy) ** 2).sum() / m)
    cxy = float((w * (jj - cx) * (ii - cy)).sum() / m)
    angle = math.degrees(0.5 * math.atan2(2 * cxy, cxx - cyy))
    lo, hi = np.sqrt(np.clip(np.linalg.eigvalsh([[cxx, cxy], [cxy, cyy]]), 0, None))
    return m, cx, cy, angle, float(lo), float(hi)


def _angle_gap(a: float, b: float) -> float:
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


def describe(got: np.ndarray, ref: np.ndarray, has_alpha: bool) -> str:
    """How the backend's render [H, W, 5] differs from the oracle's, in a few words ("" when the
    footprints agree and only the colour or depth differs: said so)."""
    g, r = footprint(got, has_alpha), footprint(ref, has_alpha)
    mg, mr = _moments(g), _moments(r)
    what = "alpha" if has_alpha else "rgb"
    if mr is None and mg is None:
        return "the footprints agree (both empty); colour or depth differs"
    if mg is None:
        return "the backend draws nothing where the oracle draws"
    if mr is None:
        return "the backend draws where the oracle draws nothing"
    parts = []
    err = float(np.abs(g - r).max())
    for axis, label in ((0, "top to bottom"), (1, "left to right")):
        if err > 0 and float(np.abs(g - np.flip(r, axis)).max()) < 0.5 * err:
            parts.append(f"the image is mirrored {label} (it matches the oracle's flipped)")
    if mg[0] / mr[0] > _RATIO or mr[0] / mg[0] > _RATIO:
        parts.append(f"{what} sums to {mg[0] / mr[0]:.3g}x the oracle's")
    dx, dy = mg[1] - mr[1], mg[2] - mr[2]
    if math.hypot(dx, dy) > _SHIFT_PX:
        parts.append(f"footprint centroid shifted by ({dx:+.2f}, {dy:+.2f}) px")
    if mg[5] > _ELONGATED * mg[4] and mr[5] > _ELONGATED * mr[4] and _angle_gap(mg[3], mr[3]) > _ANGLE_DEG:
        mirrored = _angle_gap(mg[3], -mr[3]) <= _ANGLE_DEG
        parts.append(f"footprint orientation {mg[3]:.0f} deg, oracle {mr[3]:.0f} deg"
                     + (" (mirrored)" if mirrored else ""))
    size = math.sqrt(max(mg[4] * mg[5], 1e-12) / max(mr[4] * mr[5], 1e-12))
    if size > _RATIO or 1 / size > _RATIO:
        parts.append(f"footprint {size:.3g}x the oracle's width")
    return "; ".join(parts) or "the footprints agree; colour or depth differs"


__all__ = ["coverage", "undrawn", "describe", "footprint", "DRAWN_ALPHA", "UNDRAWN"]
