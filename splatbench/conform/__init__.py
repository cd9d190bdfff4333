"""`splatbench conform`: a conformance suite of small probe scenes for any rasterizer.

    from splatbench.conform import conform
    report = conform("drjit")                   # a Backend, a callable, or a get_backend spec
    report.passed, report.failed                # nothing differs and no defect / probes still failing
    report.diagnosis, report.defects            # conventions found to differ / root causes left
    report.to_dict()                            # {"diagnosis", "defects", "version", "probes": [...], ...}

Each probe (`probes.PROBES`, the basic ones first) renders a tiny scene (`probe_scenes`) with the
backend (float32 torch inputs) and with the float64 oracle (`reference_render`, matched to the
conventions the backend declares in its `BackendInfo`), and gets a status: pass, fail, warn
(a declared approximation not followed, but one of its listed alternatives is) or skip (the
backend lacks the output or gradients the probe needs). Failures are then diagnosed
(`diagnose`): the conventions of the vocabulary that explain them (those probes become
"explained"), and the root causes of the rest. Modules:

    probe_scenes  the probe scenes            probes    what each probe checks, and the likely cause
    oracle        float64 renders, finite differences, derived tolerances (derivation in its docstring)
    calls         calling the backend         judges    pass / fail / warn per kind of probe
    diagnose      fingerprinting, root causes results   ProbeResult, ConformReport
    images        --save-images
"""

from __future__ import annotations

import dataclasses

from splatbench.backends.base import Backend
from splatbench.conform.calls import captured
from splatbench.verification.calls import Fault
from splatbench.conform.diagnose import (FAULT_CAUSE, FAULT_DEFECT, UNDRAWN_CAUSE, Defect, Finding, explained_by, fingerprint,
                                                  root_causes, run_probes)
from splatbench.conform.judges import Context
from splatbench.conform.oracle import conventions_of
from splatbench.conform.probes import PROBES, Probe, probe_names
from splatbench.conform.results import STATUSES, ConformReport, ProbeResult
from splatbench.devices import check_device, torch_device
from splatbench.errors import InputError


class BackendFault(InputError):
    """The backend cannot be checked at all: its signature cannot take conform's call, or it returns other
    than three outputs of the right shapes (the user wired it up wrong; exit 2)."""


def _preflight(backend: Backend, scene, device: str) -> None:
    """Check the backend's signature and call it once on a plain probe scene. What says the user wired
    it up wrong (a signature conform cannot call, other than three outputs of the right shapes) is one
    line (exit 2), not a fault repeated under every probe's cause. A backend that raises or returns NaN
    here is not stopped: that is a finding about the backend, reported as a defect of each probe it
    fails on (with its exception and the last frame of its traceback), while every other probe runs."""
    from splatbench.verification.calls import check_signature, forward

    try:
        check_signature(backend)
        forward(backend, scene, device)
    except Fault as fault:
        if fault.usage:
            raise BackendFault(f"backend {backend.name!r} cannot be checked: {fault} (conform calls "
                               f"fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree, "
                               f"background) -> (rgb [H, W, 3], alpha [H, W], depth [H, W]); see "
                               f"docs/backends.md)") from None


def backend_version(backend: Backend) -> str:
    """The version of what was loaded: the backend's own, else that of the distribution providing the
    module of its function (a user's ``module:function`` installed as a package), else "unknown"."""
    if backend.info.version not in ("", "unknown"):
        return backend.info.version
    from importlib import metadata

    top = (getattr(backend.fn, "__module__", None) or "").partition(".")[0]
    for dist in metadata.packages_distributions().get(top, []):
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return "unknown"


__all__ = ["conform", "BackendFault", "ConformReport", "ProbeResult", "PROBES", "Probe", "STATUSES", "probe_names",
           "Finding", "Defect", "FAULT_CAUSE", "FAULT_DEFECT", "UNDRAWN_CAUSE", "backend_version"]


def conform(backend, *, device: str = "auto", probes: tuple[str, ...] | None = None,
            diagnose: bool = True) -> ConformReport:
    """Run the conformance probes on ``backend``, judge each, and diagnose the failures.

    Args:
        backend: a `Backend`, a callable, or a spec for `get_backend` ("drjit", "mypkg.rast:render", ...).
        device: where the inputs live: "cpu", "cuda" or "auto" (default: CUDA when torch sees a GPU
            and the backend lists "cuda" in its devices, else "cpu", or the backend's only device).
        probes: names of the probes to run (default: all, in `PROBES` order, the basic probes first).
        diagnose: search the convention vocabulary for what explains failing probes (`diagnose`).

    Returns:
        `ConformReport` (``.passed``, ``.failed``, ``.diagnosis``, ``.defects``, ``.results``, ``.to_dict()``).
    """
    from splatbench.backends.registry import get_backend

    with captured() as printed:
        backend = get_backend(backend) if not isinstance(backend, Backend) else backend
    devices = backend.info.devices
    if check_device(device) == "auto":
        device = "cuda" if "cuda" in devices and torch_device("auto") == "cuda" else \
            ("cpu" if "cpu" in devices else devices[0])
    if device == "cuda":
        torch_device("cuda")  # no GPU at all: say that, not that the backend lacks CUDA (its inputs are torch's)
    if device not in devices:
        raise InputError(f"device: backend {backend.name!r} runs on {', '.join(devices)}, not {device!r}")
    selected = PROBES
    if probes:
        known = {p.name: p for p in PROBES}
        unknown = [n for n in probes if n not in known]
        if unknown:
            raise InputError(f"probes: unknown probe {unknown[0]!r} (known: {', '.join(known)})")
        selected = tuple(known[n] for n in probes)
    ctx = Context(backend, conventions_of(backend), device, {})
    with captured() as during:
        _preflight(backend, selected[0].build(), device)
        declared_results = run_probes(selected, ctx)
        conv, findings, results = ctx.conv, [], declared_results
        if diagnose and any(r.status == "fail" for r in results.values()):
            conv, findings, results = fingerprint(selected, ctx, declared_results)
        defects = root_causes(selected, results, dataclasses.replace(ctx, conv=conv))
    why = explained_by(findings)
    cause = {d.probe: d.cause for d in defects}  # a defect's cause as the evidence supports it
    results = {n: dataclasses.replace(r, cause=cause[n]) if n in cause else r for n, r in results.items()}
    final = tuple(dataclasses.replace(declared_results[p.name], status="explained", explained_by=why[p.name])
                  if p.name in why else results[p.name] for p in selected)
    declared = {k: getattr(backend.info, k) for k in backend.info.declared}
    return ConformReport(backend.name, backend.info.description, device, declared, final, tuple(findings),
                         tuple(defects), backend_version(backend), printed.text + during.text)
