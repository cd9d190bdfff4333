"""The pass/fail statements of ``splatbench validate mitsuba`` (`Check`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from splatbench.validate.mitsuba.cases import SweepRow, size_cases
from splatbench.validate.mitsuba.prediction import isotropic_prediction
from splatbench.validate.mitsuba.renderers import compare


@dataclass(frozen=True)
class Check:
    """One pass/fail statement of `splatbench validate mitsuba`."""

    name: str
    passed: bool
    detail: str


#: Largest |(splat - traced) - (predicted splat - predicted traced)| accepted by `check_tight`
#: (float32 in both renderers; the closed form is float64).
PREDICTION_ATOL = 1e-4
#: Smallest screen sigma (px) that `check_trends` orders by size.
MIN_TREND_SIGMA_PX = 0.5


def check_tight(width: int = 128, max_sigma_px: float | None = None) -> list[Check]:
    """The tight regime: small, isotropic, screen-disjoint, depth-separated degree-0 Gaussians.

    For every `size_cases` scene with sigma <= ``max_sigma_px`` (default 2 px at 128,
    scaled with ``width``: an angular sigma of 0.0145 rad): (1) the derived bound (`isotropic_prediction`) guarantees
    >= 40 dB; (2) the measured PSNR and max error are within the bound; (3) the
    measured difference equals the closed-form difference within `PREDICTION_ATOL`
    per pixel (both renderers do exactly what docs/validation.md says).
    """
    limit = 2 * width / 128 if max_sigma_px is None else max_sigma_px
    out = []
    for case in size_cases(width):
        if case.value > limit + 1e-9:
            continue
        c = compare(case.gaussians, case.camera)
        pred = isotropic_prediction(case.gaussians, case.camera)
        residual = float(np.abs((c.splat.astype(np.float64) - c.traced) - (pred.splat - pred.traced)).max())
        tag = f"sigma {case.value:.3g} px"
        out.append(Check(f"tight bound >= 40 dB ({tag})", pred.bound_psnr >= 40.0,
                         f"derived bound {pred.bound_psnr:.1f} dB (rho <= {pred.rho.max():.4f}, "
                         f"{pred.band_pixels} band pixels)"))
        m = c.metrics
        out.append(Check(f"tight PSNR within bound ({tag})", m.psnr >= pred.bound_psnr and
                         m.max_error <= pred.bound_max,
                         f"PSNR {m.psnr:.1f} dB >= {pred.bound_psnr:.1f}; max error {m.max_error:.2e} <= "
                         f"{pred.bound_max:.2e}"))
        out.append(Check(f"closed form predicts both renderers ({tag})", residual <= PREDICTION_ATOL,
                         f"max |measured - predicted difference| {residual:.1e} <= {PREDICTION_ATOL:g}"))
    return out


def check_trends(rows: Sequence[SweepRow], *, tolerance_db: float = 0.5, min_drop_db: float = 10.0) -> list[Check]:
    """Error grows with size (PSNR strictly decreasing, matched options) and with overlap.

    Size: sigma >= `MIN_TREND_SIGMA_PX` only; below half a pixel a handful of pixel
    centres sample each Gaussian and where they fall, not the size, sets the error.
    Overlap: PSNR non-increasing as the depth gap shrinks, within ``tolerance_db``
    (well-separated stacks are equal up to rounding). Both sweeps must lose at least
    ``min_drop_db`` from first to last value.
    """
    out = []
    for sweep, strict in (("size", True), ("overlap", False)):
        psnrs = [r.metrics.psnr for r in rows if r.sweep == sweep and r.options == "matched"
                 and (sweep != "size" or r.value >= MIN_TREND_SIGMA_PX)]
        if len(psnrs) < 2:
            continue
        steps = np.diff(psnrs)
        ok = bool(np.all(steps < 0)) if strict else bool(np.all(steps <= tolerance_db))
        ok &= psnrs[0] - psnrs[-1] >= min_drop_db
        out.append(Check(f"error grows with {sweep}", ok,
                         "PSNR " + (" > " if strict else " >= ").join(f"{x:.1f}" for x in psnrs) + " dB"))
    return out
