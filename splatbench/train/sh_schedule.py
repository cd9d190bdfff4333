"""The SH degree schedule: fixed (3DGS) or automatic (keep a band only if it helps).

Fixed (``sh_degree = D``): the active degree is ``min(D, step // interval)`` -- one
band more every ``interval`` steps, as graphdeco-inria's ``oneupSHdegree``.

Automatic (``sh_degree = "auto"``): the degree still rises by one every ``interval``
steps, but each raise is a trial. At the next boundary (or at the end of the run) the
newest band ``d`` is measured by a caller-supplied probe: the mean PSNR gain on a
fixed set of training views of rendering with degree ``d`` over degree ``d - 1``
(plus, for the record, the visibility-weighted energy of the band's coefficients
relative to the DC term). When the gain is below ``min_gain_db`` the band is dropped
(the degree goes back to ``d - 1``) and the schedule stops raising; otherwise the
band is kept and the next one is tried, up to degree 3. A Lambertian scene thus
settles at 0 and a glossy one keeps the bands its highlights need. The chosen degree
and why are in `ShSchedule.reason`; every measurement is in `ShSchedule.decisions`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple


class BandMeasure(NamedTuple):
    """What a probe reports about band ``d`` (degree d against degree d - 1)."""

    gain_db: float       # mean training-view PSNR with degree d minus with degree d - 1
    energy_ratio: float  # sqrt(sum_i w_i |c_i,band|^2 / sum_i w_i |c_i,DC|^2), w = opacity x visible views
    views: int           # probe views rendered
    held_out: bool = False  # True: the views were held out of training (an unbiased gain)


class ShDecision(NamedTuple):
    """One automatic-schedule measurement."""

    step: int            # step at which band `band` was judged
    band: int            # the SH band measured (1..3)
    gain_db: float       # its PSNR gain (dB)
    energy_ratio: float  # its relative coefficient energy
    kept: bool           # True: kept (and the next band tried); False: dropped, schedule stopped


Probe = Callable[[int], BandMeasure]  # band d -> its measured contribution


class ShSchedule:
    """Active SH degree per step. Call `update` at the start of every step and `finish`
    after the last one; read `degree`, `reason`, `decisions`."""

    def __init__(self, max_degree: int | str, interval: int, *, min_gain_db: float = 0.1) -> None:
        self.auto = max_degree == "auto"
        self.max_degree = 3 if self.auto else int(max_degree)
        self.interval = interval
        self.min_gain_db = min_gain_db
        self.degree = 0
        self.decisions: list[ShDecision] = []
        self._settled = self.max_degree == 0
        self._last_raise = 0
        self.reason = ("auto: not yet measured" if self.auto else
                       f"fixed: sh_degree={self.max_degree}, raised by one every {interval} steps")

    @property
    def settled(self) -> bool:
        """True once the degree will not change any more (always True for a fixed schedule
        once it reached its maximum; under "auto", after a band was dropped or all kept)."""
        return self._settled or (not self.auto and self.degree == self.max_degree)

    def target(self, step: int) -> int:
        """The fixed schedule's degree at ``step``: ``min(max_degree, step // interval)``."""
        return min(self.max_degree, step // self.interval)

    def update(self, step: int, probe: Probe | None = None) -> int:
        """The degree to use at ``step`` (0-based). Under "auto", ``probe`` measures a
        band at each interval boundary; it is not called otherwise."""
        if not self.auto:
            self.degree = self.target(step)
            return self.degree
        if self._settled or step == 0 or step % self.interval != 0:
            return self.degree
        if self.degree >= 1 and not self._judge(step, probe):
            return self.degree
        if self.degree < self.max_degree:
            self.degree += 1
            self._last_raise = step
            self.reason = f"auto: trying band {self.degree} from step {step}"
        else:
            self._settle(f"auto: every band up to {self.max_degree} gained >= {self.min_gain_db} dB")
        return self.degree

    def finish(self, step: int, probe: Probe | None = None) -> int:
        """Judge the band still on trial at the end of the run (``step`` = iterations)."""
        if self.auto and not self._settled:
            if self.degree == 0:
                self._settle(f"auto: the run ended (step {step}) before band 1 could be tried "
                             f"(sh_interval={self.interval})")
            elif self._judge(step, probe):
                self._settle(self._kept_reason())
        elif not self.auto:
            self.reason = (f"fixed: sh_degree={self.max_degree}, raised by one every {self.interval} steps; "
                           f"degree {self.degree} at the end")
        return self.degree

    # ------------------------------------------------------------------ internals
    def _judge(self, step: int, probe: Probe | None) -> bool:
        """Measure the newest band; drop it and settle when it is negligible. True if kept."""
        if probe is None:
            raise ValueError("ShSchedule: sh_degree='auto' needs a probe to measure bands")
        band = self.degree
        m = probe(band)
        kept = m.gain_db >= self.min_gain_db
        self.decisions.append(ShDecision(step, band, m.gain_db, m.energy_ratio, kept))
        if not kept:
            self.degree = band - 1
            where = "held-out training views" if m.held_out else "training views"
            self._settle(f"auto: band {band} gained {m.gain_db:.3f} dB < {self.min_gain_db} dB on {m.views} "
                         f"{where} (relative energy {m.energy_ratio:.3f}) after {step - self._last_raise} "
                         f"steps; settled at degree {self.degree}")
        return kept

    def _kept_reason(self) -> str:
        last = self.decisions[-1]
        return (f"auto: band {last.band} gained {last.gain_db:.3f} dB >= {self.min_gain_db} dB "
                f"(relative energy {last.energy_ratio:.3f}); degree {self.degree} at the end")

    def _settle(self, reason: str) -> None:
        self._settled = True
        self.reason = reason


__all__ = ["BandMeasure", "ShDecision", "ShSchedule", "Probe"]
