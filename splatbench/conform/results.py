"""What `splatbench conform` reports: one `ProbeResult` per probe, gathered in a `ConformReport`."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

STATUSES = ("pass", "fail", "warn", "skip", "explained")


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
    explained_by: str | None = None  # for "explained": the diagnosed axis that accounts for the failure


@dataclass(frozen=True)
class ConformReport:
    """What conform found. results: every probe, judged under the diagnosed conventions (a probe that
    failed under the declared ones and passes under them is "explained"). diagnosis: the conventions
    found to differ from the declaration (`diagnose.Finding`); defects: the root causes of what
    still fails (`diagnose.Defect`); version: the backend's version as loaded."""

    backend: str
    description: str
    device: str
    declared: dict
    results: tuple[ProbeResult, ...]
    diagnosis: tuple = ()
    defects: tuple = ()
    version: str = "unknown"
    output: str = field(default="", repr=False)  # what the backend printed, captured

    @property
    def failed(self) -> tuple[str, ...]:
        """Probes that fail under the diagnosed conventions (explained ones excluded)."""
        return tuple(r.name for r in self.results if r.status == "fail")

    @property
    def passed(self) -> bool:
        """Nothing differs from the declaration and no defect remains."""
        return not self.failed and not self.diagnosis

    def counts(self) -> dict[str, int]:
        return {s: sum(r.status == s for r in self.results) for s in STATUSES}

    def to_dict(self) -> dict:
        return {"backend": self.backend, "version": self.version, "description": self.description,
                "device": self.device, "declared": self.declared, "passed": self.passed,
                "diagnosis": [{"axis": d.axis, "expected": d.expected, "found": d.found, "explains": list(d.explains),
                               "alike": list(d.alike)}
                              for d in self.diagnosis],
                "defects": [{"probe": d.probe, "cause": d.cause, "deviation": d.deviation, "tolerance": d.tolerance,
                             "follows": list(d.follows)} for d in self.defects],
                "summary": self.counts(), "probes": [asdict(r) for r in self.results],
                "backend_output": self.output}
