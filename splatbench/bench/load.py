"""The load of *other* processes around a timed section: the one rule that decides
whether timings taken on a shared machine are trusted.

Linux's 1-minute load average counts every runnable thread, the benchmark's own
included: a benchmark that keeps its two threads busy for a minute lifts it by about
2 by itself. So the raw load average cannot tell a quiet machine from a busy one
while the benchmark runs. `Load` samples the load average at the start, optionally
between runs, and at the end, together with the CPU seconds the benchmark's own
processes used, and subtracts the benchmark's own share:

* the load average is an exponential moving average with a 60 s time constant
  (`LOAD_TAU_S`): a process that keeps ``c`` cores busy from the start of the section
  adds ``c * (1 - exp(-t / 60))`` to it after ``t`` seconds;
* ``c`` is the measured own CPU use over the whole section (CPU seconds / wall
  seconds, in cores), taken as constant over it: an approximation, which is why the
  section should start before the benchmark's own processes do (then the load they
  caused before the start is zero);
* the load of others at a sample taken ``t`` seconds in is ``load(t) - c * (1 -
  exp(-t / 60))``, at least 0; `Load.other` is the largest over the samples. The
  sample at the start has no own share, so a busy machine at the start always counts.

A section is ``loaded`` (its timings are not trusted) when the others' load exceeds
`QUIET_SHARE` of the usable cores (half: on the project's 2-core machine, one other
busy thread). Used by the ``raster`` run kind (`splatbench.experiments.raster_kind`)
and by ``splatbench bench ab`` (`splatbench.bench.ab`); docs/benchmarks.md.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass

#: Time constant of Linux's 1-minute load average (seconds).
LOAD_TAU_S = 60.0
#: Timings are trusted while the others' load stays at or below this share of the usable cores.
QUIET_SHARE = 0.5


def usable_cores() -> int:
    """CPU cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def process_cpu_seconds() -> float:
    """User + system CPU seconds of this process so far (all its threads)."""
    return time.process_time()


def load1() -> float:
    """The 1-minute load average now."""
    return os.getloadavg()[0]


@dataclass(frozen=True)
class Load:
    """The machine's load around a timed section (module doc).

    ``cpu`` arguments are the benchmark's own CPU seconds so far (default: this
    process's; a harness with worker processes passes the sum of theirs).
    """

    cpu0: float                 # own CPU seconds at the start
    wall0: float                # wall clock (perf_counter) at the start
    samples: tuple[tuple[float, float], ...]  # (seconds since the start, 1-minute load average)
    own_cpu: float = math.nan   # cores the benchmark kept busy over the section (set by `stop`)

    @classmethod
    def start(cls, cpu: float | None = None) -> Load:
        return cls(process_cpu_seconds() if cpu is None else cpu, time.perf_counter(), ((0.0, load1()),))

    def sample(self) -> Load:
        """This load with one more sample of the load average (between runs)."""
        return dataclasses.replace(self, samples=self.samples + ((time.perf_counter() - self.wall0, load1()),))

    def stop(self, cpu: float | None = None) -> Load:
        """The finished section: a last sample and the own CPU use over the whole section."""
        done = self.sample()
        wall = max(done.samples[-1][0], 1e-9)
        used = (process_cpu_seconds() if cpu is None else cpu) - self.cpu0
        return dataclasses.replace(done, own_cpu=used / wall)

    @property
    def before(self) -> float:
        return self.samples[0][1]

    @property
    def after(self) -> float:
        return self.samples[-1][1]

    @property
    def loads(self) -> list[float]:
        """Every sampled 1-minute load average, rounded to 0.01."""
        return [round(v, 2) for _, v in self.samples]

    @property
    def other(self) -> float:
        """Estimated load of other processes: the largest sample minus the own share at its time."""
        own = 0.0 if math.isnan(self.own_cpu) else self.own_cpu
        return max(0.0, *(v - own * (1.0 - math.exp(-t / LOAD_TAU_S)) for t, v in self.samples))

    def loaded(self, cores: int | None = None) -> bool:
        """Whether the others' load exceeded `QUIET_SHARE` of ``cores`` (default: the usable cores)."""
        return self.other > QUIET_SHARE * (usable_cores() if cores is None else cores)

    def metrics(self) -> dict[str, float | int]:
        """The flat record a report keeps (the raster kind's metric names)."""
        cores = usable_cores()
        return {"load_before": round(self.before, 2), "load_after": round(self.after, 2),
                "own_cpu": round(self.own_cpu, 2), "load_other": round(self.other, 2), "cores": cores,
                "loaded": int(self.loaded(cores))}
