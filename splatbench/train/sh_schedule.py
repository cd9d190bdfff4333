"""The SH degree schedule: fixed (3DGS) or automatic (keep bands only if they help).

Fixed (``sh_degree = D``): the active degree is ``min(D, step // interval)`` -- one
band more every ``interval`` steps, as graphdeco-inria's ``oneupSHdegree``.

Automatic (``sh_degree = "auto"``): the degree still rises by one every ``interval``
steps, but each raise is a trial. The schedule keeps a *kept* degree (0 at first). At
each boundary (and at the end of the run) a caller-supplied probe measures the
*current* degree ``d`` against the kept degree ``k``: the mean PSNR gain on a fixed
set of views of rendering with degree ``d`` over degree ``k`` (plus, for the record,
the visibility-weighted energy of bands ``k+1..d`` relative to the DC term).

* The trial passes when the gain is at least ``min_gain_db`` **per added band**, i.e.
  ``gain >= min_gain_db * (d - k)``; ``d`` becomes the kept degree and the next band is
  tried, up to degree 3.
* When it fails, the bands on trial are *not* dropped yet: with ``lookahead`` bands of
  look-ahead left (``d - k <= lookahead``) they keep training and band ``d + 1`` is
  added, to be measured (together with them, against ``k``) at the next boundary. A
  band whose own gain is small but which the next band needs is thus not lost.
* The schedule settles when degree 3 was measured or when ``lookahead + 1`` bands in a
  row failed; it then falls back to the kept degree (bands above it are dropped: the
  final model holds only the kept ones). ``lookahead = 0`` is the greedy rule (stop at
  the first band that gains too little); the default 2 always looks up to degree 3.

Why per added band and not in total: ``min_gain_db`` keeps one meaning (dB a band must
earn) whether one band or three are judged at once, the greedy rule is the special case
``d - k = 1``, and three bands (45 extra floats per Gaussian) must earn three times what
one band (9 floats) must. A Lambertian scene thus settles at 0, and a glossy one whose
band 1 alone gains little but bands 1-3 together gain much settles at 3. The chosen
degree and why are in `ShSchedule.reason`; every measurement, with the two degrees it
compared, is in `ShSchedule.decisions`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

MAX_LOOKAHEAD = 2  # bands tried after a failing one; 2 = from band 1 always up to degree 3


class BandMeasure(NamedTuple):
    """What a probe reports about degree ``d`` against a lower degree ``k``."""

    gain_db: float       # mean probe-view PSNR with degree d minus with degree k
    energy_ratio: float  # sqrt(sum_i w_i |c_i,bands k+1..d|^2 / sum_i w_i |c_i,DC|^2), w = opacity x visible views
    views: int           # probe views rendered
    held_out: bool = False  # True: the views were held out of training (an unbiased gain)


class ShDecision(NamedTuple):
    """One automatic-schedule measurement: degree `degree` against degree `baseline`."""

    step: int            # step at which it was measured
    degree: int          # the degree on trial (1..3)
    baseline: int        # the kept degree it was compared with (0..degree-1)
    gain_db: float       # PSNR with `degree` minus with `baseline` (dB)
    needed_db: float     # the bar: min_gain_db x (degree - baseline)
    energy_ratio: float  # relative coefficient energy of bands baseline+1..degree
    kept: bool           # True: `degree` became the kept degree


Probe = Callable[[int, int], BandMeasure]  # (degree d, baseline k) -> d's measured contribution over k


class ShSchedule:
    """Active SH degree per step. Call `update` at the start of every step and `finish`
    after the last one; read `degree`, `reason`, `decisions`."""

    def __init__(self, max_degree: int | str, interval: int, *, min_gain_db: float = 0.1,
                 lookahead: int = MAX_LOOKAHEAD) -> None:
        self.auto = max_degree == "auto"
        self.max_degree = 3 if self.auto else int(max_degree)
        self.interval = interval
        self.min_gain_db = min_gain_db
        self.lookahead = lookahead
        self.degree = 0
        self.kept = 0  # auto: the highest degree whose gain cleared the bar
        self.decisions: list[ShDecision] = []
        self._settled = self.max_degree == 0
        self._last_raise = 0
        self.reason = ("auto: not yet measured" if self.auto else
                       f"fixed: sh_degree={self.max_degree}, raised by one every {interval} steps")

    @property
    def settled(self) -> bool:
        """True once the degree will not change any more (always True for a fixed schedule
        once it reached its maximum; under "auto", once the look-ahead is spent or degree
        3 was measured)."""
        return self._settled or (not self.auto and self.degree == self.max_degree)

    def target(self, step: int) -> int:
        """The fixed schedule's degree at ``step``: ``min(max_degree, step // interval)``."""
        return min(self.max_degree, step // self.interval)

    def update(self, step: int, probe: Probe | None = None) -> int:
        """The degree to use at ``step`` (0-based). Under "auto", ``probe`` measures the
        current degree against the kept one at each interval boundary; it is not called
        otherwise."""
        if not self.auto:
            self.degree = self.target(step)
            return self.degree
        if self._settled or step == 0 or step % self.interval != 0:
            return self.degree
        if self.degree > self.kept:
            self._judge(step, probe)
        if not self._settled:
            self.degree += 1  # judged with degree < max_degree, else _judge settled
            self._last_raise = step
            self.reason = f"auto: trying degree {self.degree} against kept degree {self.kept} from step {step}"
        return self.degree

    def finish(self, step: int, probe: Probe | None = None) -> int:
        """Judge the degree still on trial at the end of the run (``step`` = iterations)
        and settle: the bands above the kept degree are dropped."""
        if self.auto and not self._settled:
            if self.degree == 0:
                self._settle(f"auto: the run ended (step {step}) before band 1 could be tried "
                             f"(sh.interval={self.interval})")
            else:
                self._judge(step, probe, last=True)
        elif not self.auto:
            self.reason = (f"fixed: sh_degree={self.max_degree}, raised by one every {self.interval} steps; "
                           f"degree {self.degree} at the end")
        return self.degree

    # ------------------------------------------------------------------ internals
    def _judge(self, step: int, probe: Probe | None, *, last: bool = False) -> None:
        """Measure the current degree against the kept one; keep it, keep looking, or settle."""
        if probe is None:
            raise ValueError("ShSchedule: sh_degree='auto' needs a probe to measure bands")
        degree, base = self.degree, self.kept
        m = probe(degree, base)
        needed = round(self.min_gain_db * (degree - base), 9)  # 0.1 x 3 is 0.30000000000000004 unrounded
        kept = m.gain_db >= needed
        self.decisions.append(ShDecision(step, degree, base, m.gain_db, needed, m.energy_ratio, kept))
        where = "held-out training views" if m.held_out else "training views"
        what = (f"degree {degree} gained {m.gain_db:.3f} dB over degree {base} "
                f"({'>=' if kept else '<'} {needed:.3g} dB = {self.min_gain_db} dB x {degree - base} "
                f"band{'s' if degree - base > 1 else ''}) on {m.views} {where} "
                f"(relative energy {m.energy_ratio:.3f}) "
                f"after a {step - self._last_raise}-step trial of degree {degree}")
        if kept:
            self.kept = degree
            if degree == self.max_degree or last:
                self._settle(f"auto: {what}; degree {degree} at the end")
            return
        failed = degree - base
        if degree == self.max_degree or failed > self.lookahead or last:
            self.degree = base
            why = (f"degree {degree} reached" if degree == self.max_degree else "the run ended" if last else
                   f"{failed} band(s) in a row failed (sh.auto_lookahead={self.lookahead})")
            self._settle(f"auto: {what}; {why}, bands above {base} dropped; settled at degree {base}")

    def _settle(self, reason: str) -> None:
        self._settled = True
        self.reason = reason


__all__ = ["BandMeasure", "ShDecision", "ShSchedule", "Probe", "MAX_LOOKAHEAD"]
