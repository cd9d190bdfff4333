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
* what the process did *before* the section counts too: a raster run's warm-up and
  the previous run's error renders in the same worker lift the load average at the
  start by up to ~1 on a quiet machine. `own_share` follows this process's own
  contribution as the kernel does, an exponential moving average of its CPU use
  (cores), updated at every call from the CPU seconds since the previous one (taken
  as a constant rate in between) and started at import from the process's age and
  CPU time; `Load.start` stores it as ``own_before``, which decays as ``exp(-t / 60)``.
  A harness whose own processes start after the section (``cpu=`` given, as ``bench
  ab``) has ``own_before = 0``;
* the load of others at a sample taken ``t`` seconds in is ``load(t) - own_before *
  exp(-t / 60) - c * (1 - exp(-t / 60))``, at least 0; `Load.other` is the largest
  over the samples.

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


def _process_age_s() -> float | None:
    """Seconds since this process started (Linux ``/proc``), None where unknown."""
    try:
        with open("/proc/self/stat") as fh:
            start_ticks = float(fh.read().rsplit(")", 1)[1].split()[19])  # field 22: starttime
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        return max(uptime - start_ticks / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError):
        return None


class OwnShare:
    """This process's share of the 1-minute load average: an exponential moving average
    (time constant `LOAD_TAU_S`) of its CPU use in cores, as the kernel averages runnable
    threads. ``clock`` and ``cpu`` are injectable for tests."""

    def __init__(self, clock=time.perf_counter, cpu=process_cpu_seconds, age_s: float | None = None,
                 ) -> None:
        self._clock, self._cpu = clock, cpu
        self.t, self.c = clock(), cpu()
        # before the first call: the CPU time so far spread evenly over the process's life
        self.share = (self.c / age_s) * (1.0 - math.exp(-age_s / LOAD_TAU_S)) if age_s else 0.0

    def __call__(self) -> float:
        """The share now (cores), after folding in the CPU used since the last call."""
        t, c = self._clock(), self._cpu()
        dt = t - self.t
        if dt > 0:
            decay = math.exp(-dt / LOAD_TAU_S)
            self.share = self.share * decay + ((c - self.c) / dt) * (1.0 - decay)
            self.t, self.c = t, c
        return self.share


#: This process's share of the load average (`OwnShare`), started at import.
own_share = OwnShare(age_s=_process_age_s())


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
    own_before: float = 0.0     # the process's own share of the load average at the start (`own_share`)

    @classmethod
    def start(cls, cpu: float | None = None) -> Load:
        """Start a section; ``cpu`` given: the own processes start after it (own share 0 now)."""
        if cpu is None:
            return cls(process_cpu_seconds(), time.perf_counter(), ((0.0, load1()),), own_before=own_share())
        return cls(cpu, time.perf_counter(), ((0.0, load1()),))

    def sample(self) -> Load:
        """This load with one more sample of the load average (between runs)."""
        return dataclasses.replace(self, samples=self.samples + ((time.perf_counter() - self.wall0, load1()),))

    def stop(self, cpu: float | None = None) -> Load:
        """The finished section: a last sample and the own CPU use over the whole section."""
        done = self.sample()
        if cpu is None:
            own_share()  # a checkpoint: the tracker's next interval starts at the section's end
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
        return max(0.0, *(v - self.own_before * math.exp(-t / LOAD_TAU_S) - own * (1.0 - math.exp(-t / LOAD_TAU_S))
                          for t, v in self.samples))

    def loaded(self, cores: int | None = None) -> bool:
        """Whether the others' load exceeded `QUIET_SHARE` of ``cores`` (default: the usable cores)."""
        return self.other > QUIET_SHARE * (usable_cores() if cores is None else cores)

    def metrics(self) -> dict[str, float | int]:
        """The flat record a report keeps (the raster kind's metric names)."""
        cores = usable_cores()
        return {"load_before": round(self.before, 2), "load_after": round(self.after, 2),
                "own_cpu": round(self.own_cpu, 2), "own_before": round(self.own_before, 2), "load_other": round(self.other, 2), "cores": cores,
                "loaded": int(self.loaded(cores))}
