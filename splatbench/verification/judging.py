"""Judging a gradient against a reference, with the gradient band measured apart.

`relative` is the one relative L2 error of the checks; `entry_band` spreads the gradient band
(`reference.band`: the Gaussians whose own term float32 may compute under another discrete
decision) from Gaussians to a group's entries; `grad_error` measures a gradient against the
oracle's (`GradError`, judged against `splatbench.verification.bounds.gradient_bound`).
"""

from __future__ import annotations

import math

import numpy as np

from splatbench.verification.bounds import GradError


def relative(a: np.ndarray, b: np.ndarray, floor: float = 0.0) -> float:
    """|a - b| / max(|b|, floor) (L2 norms); 0 when both are 0, inf when only the denominator is."""
    num, den = float(np.linalg.norm(a - b)), max(float(np.linalg.norm(b)), floor)
    return num / den if den > 0 else (0.0 if num == 0 else math.inf)


def entry_band(grad_band: np.ndarray | None, size: int, idx: np.ndarray | None = None) -> np.ndarray | None:
    """The gradient band per entry of a group of ``size`` entries (``idx``: only those flat entries),
    from the band per Gaussian [N] (None: no band)."""
    if grad_band is None:
        return None
    per = size // len(grad_band)
    flat = np.repeat(np.asarray(grad_band, dtype=bool), per)
    return flat if idx is None else flat[idx]


def grad_error(a: np.ndarray, b: np.ndarray, band: np.ndarray | None = None) -> GradError:
    """`GradError` of gradient ``a`` against the oracle's ``b`` (any shapes with the same size);
    ``band``: [same size] bool, the entries of the gradient band (`reference.band`), measured apart."""
    a, b = np.ravel(a).astype(np.float64), np.ravel(b).astype(np.float64)
    if not np.isfinite(a).all():
        return GradError(math.inf, math.nan, math.inf, float(np.linalg.norm(b)), math.inf, math.inf,
                         0 if band is None else int(np.count_nonzero(band)))
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if nb == 0.0:
        return GradError(0.0, 1.0, na, nb) if na == 0.0 else GradError(math.nan, math.nan, na, nb)
    cosine = float(a @ b) / (na * nb) if na > 0 else 0.0
    rest = band_rel = math.nan
    if band is not None:
        band = np.ravel(band).astype(bool)
        out, inside = ~band, band
        rest = relative(a[out], b[out])
        band_rel = relative(a[inside], b[inside]) if inside.any() else 0.0
    return GradError(float(np.linalg.norm(a - b)) / nb, cosine, na, nb, rest, band_rel,
                     0 if band is None else int(np.count_nonzero(band)))
