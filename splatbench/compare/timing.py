"""`Timing`: what `splatbench compare` measured of one backend's speed and memory (`measure.time_backends`)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Timing:
    """Milliseconds of every timed forward and forward+backward run (empty: not timed),
    why not, and the peak memory rise of one forward+backward (MB, 10^6 bytes)."""

    fwd_ms: tuple[float, ...] = ()
    fwd_bwd_ms: tuple[float, ...] = ()
    note: str = ""
    peak_mb: float = math.nan
    memory_kind: str = ""
