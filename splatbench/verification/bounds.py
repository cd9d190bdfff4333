"""The float32 bound of the verification applications, and the boundary bands' part in it.

The bounds (`FORWARD_ATOL`, `gradient_bound`, `BAND_BUDGET`, ...) are derived in the comments
below: how far a float32 rasterizer may lie from the float64 oracle with the same conventions,
outside the oracle's boundary band and gradient band (`reference.band`). `ImageError` and
`GradError` are one judged measurement each (`splatbench.verification.judging` measures them).
Used by compare (against the oracle), regress (against a snapshot: twice the bound) and the
demo; imports nothing of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from splatbench.conventions import U32  # float32 unit roundoff

# Forward bound, derived in tests/test_raster_parity.py: a pixel sums L <= ~150 terms
# T_i a_i c_i, T_i a product of i factors (relative error <= i u) and a_i c_i ~20 float32
# operations, so |error| <= (2 L + 20) u max|c| ~ 4e-5 for |c| <= 2, and 2e-5 for the
# random-walk sum. A pixel where some contribution lies within float32 error of a discrete
# decision (3-sigma cutoff, alpha_min, early stop) may differ by a whole contribution: the
# oracle computes those pixels, the boundary band (`reference.band`), from worst-case float32
# error bounds of every quantity the decisions read; two contributions whose depths may swap
# widen that pixel's bound by what the swap can change (the tie slack). Outside the band
# the bound holds strictly (`over_bound`).
FORWARD_ATOL = 2e-5
OFF_THRESHOLD = 1e-4        # "share of pixels off by more than 1e-4" (per pixel, max over channels)
DEPTH_ALPHA_MIN = 0.05      # v_depth is kept where the oracle's alpha exceeds this
GRAD_TERM_OPS = 20          # float32 operations per gradient term (forward + backward)


def gradient_bound(pixels: int, outliers: int = 0, grad_weight=None) -> float:
    """Relative L2 bound of a float32 gradient against a float64 one with the same conventions,
    outside the gradient band (`reference.band`).

    One gradient entry sums a term per pixel, each with ~20 float32 operations (relative
    error 20 u); random cotangents make the terms cancel, which amplifies the relative
    error of the sum by at most sqrt(P) (tests/test_raster_grads.py): 20 u sqrt(P). Where
    float32 may take a discrete decision the other way (a band pixel, a depth tie), the
    Gaussians whose own term changes whole are the gradient band, reported apart
    (`splatbench.verification.judging.grad_error`); every other term at that pixel changes by a relative
    ``grad_weight`` [H, W] at most (a_k of a flipped contribution, T at an early stop,
    T a_i a_j for a swap), which among P pixels of comparable terms adds
    sqrt(sum_p w_p^2 / P). Without a gradient band (``grad_weight`` None), ``outliers``
    pixels over the forward bound each change their terms by a whole contribution:
    sqrt(outliers / P).
    """
    extra = math.sqrt(outliers / pixels)
    if grad_weight is not None:
        import numpy as np

        extra = math.sqrt(float(np.square(np.asarray(grad_weight, dtype=np.float64)).sum()) / pixels)
    return GRAD_TERM_OPS * U32 * math.sqrt(pixels) + extra


#: The gradient band's budget: a band Gaussian's gradient may differ from the oracle's by a whole term
#: at each pixel where its decision flips, so the band's error may reach the band's own oracle gradient
#: (relative L2 1) but not exceed it: more says the band's Gaussians are wrong beyond any decision.
BAND_BUDGET = 1.0


def over_bound(per_pixel, band=None, slack=None, atol: float = FORWARD_ATOL) -> tuple[int, int]:
    """(pixels over the bound, those of them outside the band) of a per-pixel error [H, W].

    The bound at a pixel is ``atol`` plus its tie ``slack`` [H, W] (0 where None); ``band``
    [H, W] bool (None: empty) holds the pixels where float32 may take a discrete decision
    the other way (`reference.band`), the only ones allowed over it. NaN counts as over.
    """
    import numpy as np

    per_pixel = np.asarray(per_pixel, dtype=np.float64)
    bound = atol + (0.0 if slack is None else np.asarray(slack, dtype=np.float64))
    over = ~(per_pixel <= bound)
    outside = over if band is None else over & ~np.asarray(band, dtype=bool)
    return int(over.sum()), int(outside.sum())


@dataclass(frozen=True)
class ImageError:
    """One output against one oracle image: max |diff|, PSNR (peak 1), share of pixels off
    by more than 1e-4, pixels over the bound (`FORWARD_ATOL` plus the tie slack: the bound's
    outliers) and how many of those lie outside the boundary band (the verdict: none may)."""

    max_abs: float
    psnr: float
    frac_off: float
    outliers: int
    outside_band: int = 0


@dataclass(frozen=True)
class GradError:
    """One parameter group: relative L2 error |a - b| / |b|, cosine a.b / (|a| |b|), and the
    norms |a| (backend) and |b| (oracle); with a gradient band (`reference.band`), the relative
    L2 error outside it (the verdict's) and inside it (against the band's own oracle norm). Where |b| = 0 (e.g. the quaternions of isotropic
    Gaussians, which a rotation does not change) and |a| > 0 there is no relative error:
    rel_l2 and cosine are NaN and the group is left out of the verdict."""

    rel_l2: float
    cosine: float
    norm: float = math.nan
    oracle_norm: float = math.nan
    rest_rel_l2: float = math.nan   # relative L2 outside the gradient band (the verdict's); NaN: no band known
    band_rel_l2: float = math.nan   # relative L2 of the gradient band's entries against their own oracle norm
    band_gaussians: int = 0         # Gaussians of the gradient band among the compared entries

    @property
    def judged(self) -> float:
        """The error the verdict holds to the bound: outside the gradient band when one is known."""
        return self.rel_l2 if math.isnan(self.rest_rel_l2) else self.rest_rel_l2

    def within(self, bound: float) -> bool:
        """Outside the band within ``bound``, the band within its budget (`BAND_BUDGET`)."""
        band_ok = self.band_gaussians == 0 or math.isnan(self.band_rel_l2) or self.band_rel_l2 <= BAND_BUDGET
        return self.judged <= bound and band_ok
