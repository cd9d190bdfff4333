"""What `splatbench conform` reports: one `ProbeResult` per probe, gathered in a `ConformReport`."""

from __future__ import annotations

from dataclasses import asdict, dataclass

STATUSES = ("pass", "fail", "warn", "skip")


@dataclass(frozen=True)
class ProbeResult:
    """One probe's verdict. deviation and tolerance: max |difference| (forward, approximation)
    or relative L2 error (gradient, direction); None when not measured (skip, a fault)."""

    name: str
    kind: str
    status: str
    checks: str
    deviation: float | None
    tolerance: float | None
    tolerance_source: str
    detail: str
    cause: str | None  # the most likely cause, for fail and warn


@dataclass(frozen=True)
class ConformReport:
    backend: str
    description: str
    device: str
    declared: dict
    results: tuple[ProbeResult, ...]

    @property
    def failed(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.results if r.status == "fail")

    @property
    def passed(self) -> bool:
        return not self.failed

    def counts(self) -> dict[str, int]:
        return {s: sum(r.status == s for r in self.results) for s in STATUSES}

    def to_dict(self) -> dict:
        return {"backend": self.backend, "description": self.description, "device": self.device,
                "declared": self.declared, "passed": self.passed, "summary": self.counts(),
                "probes": [asdict(r) for r in self.results]}
