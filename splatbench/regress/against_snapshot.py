"""`check`: a backend now against its snapshot, quantity by quantity, with a verdict for each change.

Per scene and quantity (outputs per pixel, gradients per parameter group; `measure` derives
the tolerances): **unchanged** within the tolerance; otherwise the quantity is measured against
the float64 oracle (matched to the declared conventions; gradients: torch64 on the same loss)
now and in the snapshot, outside the band, in units of the float32 bound:

* **improvement**: now closer to the oracle by more than one bound unit;
* **regression**: farther by more than one bound unit;
* **convention change**: neither (it moved, but no nearer to nor farther from the truth), or the
  backend declares other conventions than when the snapshot was taken (a declaration changed with
  unchanged outputs fails the check too: `CheckReport.declared_changes`).

For every regression and convention change conform runs once on the backend and its diagnosis
(a convention it follows that differs from the declaration) or root cause is named beside the
quantity. A backend that raises (or returns NaN) on a scene fails every quantity of that scene,
with its exception and the last frame of its traceback. Exit status (`CheckReport.exit_code`):
0 when every quantity is unchanged or improved and the declaration is the snapshot's, 1 otherwise;
bad input (no or a damaged snapshot, another scene-set version, a backend that cannot be called)
is an `InputError` (exit 2).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from splatbench.errors import InputError

PASSING = ("unchanged", "improvement")
STATUSES = ("unchanged", "improvement", "regression", "convention change")


@dataclass(frozen=True)
class QuantityResult:
    """One quantity of one scene. difference: largest per-pixel difference outside the band (outputs)
    or relative L2 difference outside the gradient band (gradients) from the snapshot; tolerance: its
    derived bound; oracle_before / oracle_now: distance to the oracle in bound units (None: not measured);
    cause: what conform (or the fault) says."""

    scene: str
    quantity: str
    status: str
    difference: float | None
    tolerance: float | None
    where: str = ""
    band: str = ""
    oracle_before: float | None = None
    oracle_now: float | None = None
    cause: str = ""

    @property
    def passed(self) -> bool:
        return self.status in PASSING

    @property
    def name(self) -> str:
        return f"{self.scene}::{self.quantity}"

    def line(self) -> str:
        """One line: what moved, by how much, where, and toward or away from the oracle."""
        if self.difference is None:
            return f"{self.name}: {self.status}: {self.cause}"
        text = f"{self.name}: {self.status}: {_fmt(self.difference)} (tolerance {_fmt(self.tolerance)}) at {self.where}"
        if self.band:
            text += f"; {self.band}"
        if self.oracle_now is not None and self.oracle_before is not None:
            way = {"improvement": "moved toward the oracle", "regression": "moved away from the oracle"}.get(
                self.status, "no nearer to the oracle nor farther")
            text += f"; {way}: {self.oracle_before:.3g} -> {self.oracle_now:.3g} bound units"
        if self.cause:
            text += f"; {self.cause}"
        return text


def _fmt(x: float | None) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2e}"


@dataclass(frozen=True)
class CheckReport:
    backend: str
    version: str
    against: str
    snapshot_backend: str
    scene_set: str
    results: tuple[QuantityResult, ...]
    seconds: float = 0.0
    notes: tuple[str, ...] = field(default=())
    conform: str = ""  # what conform says of the backend now (run when something regressed), one clause
    declared_changes: tuple[str, ...] = ()  # "AXIS OLD -> NEW" per declared convention changed since the snapshot

    @property
    def changed(self) -> tuple[QuantityResult, ...]:
        return tuple(r for r in self.results if r.status != "unchanged")

    @property
    def passed(self) -> bool:
        """Every quantity unchanged or improved, and the same declared conventions as the snapshot's (a
        changed declaration is a convention change even where no quantity moved)."""
        return all(r.passed for r in self.results) and not self.declared_changes

    @property
    def exit_code(self) -> int:
        return 0 if self.passed else 1

    def counts(self) -> dict[str, int]:
        return {s: sum(r.status == s for r in self.results) for s in STATUSES}

    @property
    def status(self) -> str:
        if not self.passed:  # a failing check with no regression failed on convention changes alone
            return "regressed" if any(r.status == "regression" for r in self.results) else "convention changed"
        return "improved" if any(r.status == "improvement" for r in self.results) else "unchanged"

    def to_dict(self) -> dict:
        return {"backend": self.backend, "version": self.version, "against": self.against,
                "snapshot_backend": self.snapshot_backend, "scene_set": self.scene_set, "status": self.status,
                "conform": self.conform, "declared_changes": list(self.declared_changes),
                "passed": self.passed, "summary": self.counts(), "notes": list(self.notes),
                "seconds": round(self.seconds, 2), "quantities": [asdict(r) for r in self.results]}


def check(backend, against: str | Path, *, device: str = "auto", scenes: tuple[str, ...] | None = None,
          diagnose: bool = True, save_images: str | Path | None = None, progress=None) -> CheckReport:
    """Check ``backend`` (a spec, `Backend` or callable) against the snapshot folder ``against``
    (module doc). ``scenes``: only these scene names (default: all). ``diagnose``: run conform for the
    cause of a regression. ``save_images``: a folder for PNGs of every changed output."""
    from splatbench.backends.registry import get_backend
    from splatbench.verification.calls import Fault, check_signature
    from splatbench.regress.files import backend_record, read_snapshot, resolve_device

    start = time.perf_counter()
    spec = backend if isinstance(backend, str) else getattr(backend, "name", repr(backend))
    backend = get_backend(backend)
    snap = read_snapshot(against)
    device = resolve_device(backend, device)
    try:
        check_signature(backend)
    except Fault as fault:
        raise InputError(f"backend {backend.name!r}: {fault}") from None
    chosen = snap.scenes()
    if scenes:
        unknown = sorted(set(scenes) - {s.name for s in chosen})
        if unknown:
            raise InputError(f"--scene: {unknown[0]!r} is not in the snapshot (its scenes: {', '.join(snap.scene_names)})")
        chosen = [s for s in chosen if s.name in scenes]
    now = backend_record(backend, spec)
    before = snap.manifest["backend"]
    notes = []
    declared_change = {k: (before.get("conventions", {}).get(k), v) for k, v in now["conventions"].items()
                       if before.get("conventions", {}).get(k) != v}
    declared = tuple(f"{k} {a!r} -> {b!r}" for k, (a, b) in declared_change.items())
    if declared:
        notes.append("declared conventions changed since the snapshot: " + ", ".join(declared))
    say = progress or (lambda line: None)
    results: list[QuantityResult] = []
    for scene in chosen:
        arrays = snap.arrays(scene)
        wanted = list(snap.record(scene.name)["quantities"])
        try:
            values = _render(backend, scene, device, arrays)
        except Fault as fault:
            if fault.usage:
                raise InputError(f"backend {backend.name!r} on scene {scene.name!r}: {fault}") from None
            results += [QuantityResult(scene.name, q, "regression", None, None,
                                       cause=f"the backend fails on this scene: {fault}") for q in wanted]
            say(f"{scene.name}: fails ({fault})")
            continue
        results += _judge_scene(backend, scene, arrays, values, wanted, declared_change)
        say(f"{scene.name}: {sum(r.scene == scene.name and r.status != 'unchanged' for r in results)} changed")
    cause = ""
    if diagnose and any(not r.passed and r.difference is not None for r in results):
        cause = _conform_cause(backend, device)
        results = [r if r.passed or r.difference is None else _with_cause(r, cause) for r in results]
    if save_images:
        _save_images(Path(save_images), backend, device, chosen, snap, results)
    from splatbench.conform import backend_version

    return CheckReport(backend.name, backend_version(backend), str(against),
                       f"{before.get('name')} {before.get('version')}", snap.manifest["scene_set"], tuple(results),
                       time.perf_counter() - start, tuple(notes), cause, declared)


def _render(backend, scene, device, arrays):
    from splatbench.regress.files import _deterministic_torch
    from splatbench.regress.measure import render

    with _deterministic_torch():  # as the snapshot rendered: the same code gives the same bits
        return render(backend, scene, device, alpha_for_cotangents=arrays.get("alpha"))


def _with_cause(r: QuantityResult, cause: str) -> QuantityResult:
    import dataclasses

    return dataclasses.replace(r, cause="; ".join(c for c in (r.cause, cause) if c))


def _judge_scene(backend, scene, arrays, values, wanted, declared_change) -> list[QuantityResult]:
    from splatbench.regress.measure import GRAD_PREFIX, Band, gradient_difference, gradient_tolerance, output_difference

    band = Band(*(arrays[k] for k in ("band", "tie_slack", "grad_band", "grad_weight")))
    band = Band(band.band.astype(bool), band.tie_slack, band.grad_band.astype(bool), band.grad_weight)
    z_max = max(1.0, float(np.abs(arrays["depth"]).max(initial=0.0))) if "depth" in arrays else 1.0
    out: list[QuantityResult] = []
    oracle_cache: dict = {}
    for q in wanted:
        if q not in values:
            out.append(QuantityResult(scene.name, q, "regression", None, None,
                                      cause=f"the backend no longer produces {q} (its BackendInfo declares "
                                            f"outputs={list(backend.info.outputs)}, gradients={backend.info.gradients})"))
            continue
        if q.startswith(GRAD_PREFIX):
            rest, inside, where = gradient_difference(q, values[q], arrays[q], band, arrays)
            tol, band_tol = gradient_tolerance(scene, band)
            n_band = int(band.grad_band.sum())
            note = f"gradient band of {n_band} Gaussians: {inside:.2e} (budget {band_tol:g})" if n_band else ""
            changed = rest > tol or inside > band_tol
            result = QuantityResult(scene.name, q, "unchanged", rest, tol, where, note)
        else:
            diff, where, tol, over = output_difference(q, values[q], arrays[q], values.get("alpha"),
                                                       arrays.get("alpha"), z_max, band)
            note = f"{over} band pixels over the tolerance (not judged)" if over else ""
            changed = diff > tol
            result = QuantityResult(scene.name, q, "unchanged", diff, tol, where, note)
        if changed:
            result = _verdict(backend, scene, q, values, arrays, band, z_max, declared_change, oracle_cache, result)
        out.append(result)
    return out


def _verdict(backend, scene, q, values, arrays, band, z_max, declared_change, cache, result) -> QuantityResult:
    """Improvement, regression or convention change of a quantity that moved (module doc)."""
    import dataclasses

    from splatbench.regress.measure import GRAD_PREFIX, gradient_scale, oracle, oracle_gradients, output_excess
    from splatbench.verification.bounds import gradient_bound
    from splatbench.verification.judging import entry_band, relative

    if declared_change:
        return dataclasses.replace(result, status="convention change",
                                   cause="the declared conventions changed since the snapshot (see the notes): "
                                         "take the snapshot again if that is intended")
    if q.startswith(GRAD_PREFIX):
        if "grads" not in cache:
            cache["grads"] = oracle_gradients(backend.info, scene, arrays.get("alpha"))
        ref = cache["grads"]
        if ref is None:
            return dataclasses.replace(result, status="regression",
                                       cause="changed, and no float64 gradient oracle follows these conventions")
        P = scene.camera.width * scene.camera.height
        unit = gradient_bound(P, 0, band.grad_weight)
        outside = ~entry_band(band.grad_band, ref[q].size)
        floor = gradient_scale(q, ref, outside)
        now = relative(values[q].reshape(-1)[outside], ref[q].reshape(-1)[outside], floor) / unit
        before = relative(arrays[q].reshape(-1)[outside], ref[q].reshape(-1)[outside], floor) / unit
    else:
        if "render" not in cache:
            cache["render"] = oracle(backend.info, scene, band=False)
        o = cache["render"]
        ref = {"rgb": o.rgb, "alpha": o.alpha, "depth": o.depth}
        now = output_excess(q, values[q], ref[q], values.get("alpha"), o.alpha, z_max, band)
        before = output_excess(q, arrays[q], ref[q], arrays.get("alpha"), o.alpha, z_max, band)
    status = "improvement" if now < before - 1 else "regression" if now > before + 1 else "convention change"
    return dataclasses.replace(result, status=status, oracle_before=before, oracle_now=now)


def _conform_cause(backend, device) -> str:
    """What conform says of the backend now, in one clause: its diagnosis, else its first root cause."""
    from splatbench.conform import conform

    try:
        report = conform(backend, device=device)
    except InputError as exc:
        return f"conform: {exc}"
    if report.diagnosis:
        return "conform: " + "; ".join(f"{d.axis} is {d.found!r}, not the declared {d.expected!r}"
                                       for d in report.diagnosis)
    if report.defects:
        d = report.defects[0]
        return f"conform: defect {d.probe}: {d.cause}"
    return "conform: every probe passes (the change shows on these scenes only)"


def _save_images(folder: Path, backend, device, chosen, snap, results) -> None:
    """``SCENE_QUANTITY_{now,snapshot,difference}.png`` for every changed output (difference scaled to its
    largest value, printed in the file name)."""
    from splatbench.images import save_png
    from splatbench.regress.measure import GRAD_PREFIX

    changed = {(r.scene, r.quantity) for r in results if r.status != "unchanged" and r.difference is not None
               and not r.quantity.startswith(GRAD_PREFIX)}
    for scene in chosen:
        qs = [q for s, q in changed if s == scene.name]
        if not qs:
            continue
        arrays = snap.arrays(scene)
        values = _render(backend, scene, device, arrays)
        for q in qs:
            a, b = values[q], arrays[q]
            scale = max(float(np.abs(b).max(initial=0.0)), float(np.abs(a).max(initial=0.0)), 1e-12)
            d = np.abs(a - b)
            d = d.max(-1) if d.ndim == 3 else d
            peak = max(float(d.max()), 1e-12)
            save_png(a / scale, folder / f"{scene.name}_{q}_now.png")
            save_png(b / scale, folder / f"{scene.name}_{q}_snapshot.png")
            save_png(d / peak, folder / f"{scene.name}_{q}_difference.png")
