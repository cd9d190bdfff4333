"""Per-stage wall time of the rasterizer, for benchmarks (never used by tests)."""

from __future__ import annotations

import time
from collections import defaultdict

from splatbench.raster.device import dr

#: Binning is charged as two stages: culling (support boxes, expansion, ellipse-tile
#: test) and sorting (counting sort by tile, ranges); `StageSplit.binning_ms` is their sum.
STAGES = ("preprocess", "binning_cull", "binning_sort", "compositing", "backward_compositing", "backward_preprocess")


class StageTimer:
    """Accumulates seconds per stage. ``mark(stage)`` waits for Dr.Jit's queued work
    to finish, then charges the time since the previous mark to ``stage``."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self._last = time.perf_counter()

    def start(self) -> None:
        dr.sync_thread()
        self._last = time.perf_counter()

    def mark(self, stage: str) -> None:
        dr.sync_thread()
        now = time.perf_counter()
        self.seconds[stage] += now - self._last
        self._last = now
