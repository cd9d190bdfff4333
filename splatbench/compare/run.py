"""Any rasterizers side by side against the float64 oracle (`splatbench compare`).

    run_compare(backends, workloads, settings=CompareSettings(), progress=None) -> CompareResult
    write_compare(result, out) -> report.md        (`splatbench.compare.report`)

Per backend x workload (one `CompareRow`):

1. **Forward error** at the error camera (the workload's camera scaled by
   ``error_scale``: the oracle is float64 NumPy, so large images are measured at a
   reduced resolution, as ``splatbench demo`` does): rgb, alpha and depth against
   `reference_render` in mode "matched" with the backend's declared conventions, and
   in mode "exact" (the exact Gaussian mixture). The verdict: within the float32 bound
   (`FORWARD_ATOL`, widened by depth ties) at every pixel outside the boundary band the
   matched oracle computes (`reference.band`: where float32 may take a discrete decision
   the other way); the band's size is reported. Each oracle image is rendered once per
   workload (per distinct conventions) and reused across backends. Depth is compared
   as depth * alpha / z_max (the composited sum; depth = sum / alpha amplifies alpha's
   error by 1 / alpha), z_max = max(1, largest oracle depth).
2. **Gradients**: the VJP of sum(v . outputs) with random cotangents v over every
   declared output (v_depth kept only where the oracle's alpha > 0.05, for the same
   1 / alpha reason), per parameter group, as relative L2 error and cosine against
   the gradient oracle: ``torch64`` (float64 autograd) built with the backend's
   conventions, or central differences of the oracle on a sample of entries
   (`splatbench.compare.measure.GradOracle`).
3. **Time** at the workload's full resolution: one warm-up forward and forward+backward
   per backend (Dr.Jit compiles then), then ``repeats`` rounds in which the backends
   take turns (ABCABC...); median, quartiles, min and max; load average around it.
   **Peak memory**: one more forward+backward per backend with allocator caches
   flushed and the peak RSS reset first (Linux ``clear_refs``): the rise over the RSS
   before the call (on CUDA: torch's allocator peak).

A backend that raises gets the one-line error in its row; the others go on.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from splatbench.compare.timing import Timing
from splatbench.devices import torch_device
from splatbench.errors import InputError, one_line
from splatbench.metrics.machine import MachineInfo
from splatbench.verification.bounds import GradError, ImageError, gradient_bound
from splatbench.workloads import Workload, WorkloadSpec

MAX_ORACLE_PIXELS = 20_000  # automatic error scale: the largest 1/2^k with W' H' <= this

if TYPE_CHECKING:
    from splatbench.backends.base import Backend


@dataclass(frozen=True)
class CompareSettings:
    """How `run_compare` measures.

    repeats: timed rounds; device: "cpu", "cuda" or "auto" (where the input tensors live;
    auto: CUDA when torch sees a GPU and every backend compared runs there, else the CPU);
    seed: of the random cotangents and the finite-difference sample; error_scale:
    resolution factor of the error measurement (None: `auto_scale`); grad_oracle:
    "auto" (``torch64`` when registered, else "fd"), "fd", "none" or a backend name;
    fd_entries: entries per group differentiated by central differences; max_call_s:
    a backend whose forward at full resolution is predicted to take longer is not timed.
    """

    repeats: int = 5
    device: str = "auto"
    seed: int = 0
    error_scale: float | None = None
    grad_oracle: str = "auto"
    fd_entries: int = 12
    max_call_s: float = 60.0

    def validate(self) -> None:
        if self.repeats < 1:
            raise InputError(f"--repeats: expected a count >= 1, got {self.repeats}")
        torch_device(self.device, "--device")  # unknown, or 'cuda' without a GPU: fails here, before any work
        if self.error_scale is not None and not 0 < self.error_scale <= 1:
            raise InputError(f"--error-scale: expected a factor in (0, 1], got {self.error_scale}")
        if self.fd_entries < 1:
            raise InputError(f"--fd-entries: expected a count >= 1, got {self.fd_entries}")


def _device(device: str, backends: Sequence[Backend]) -> str:
    """``"cpu"`` or ``"cuda"`` for ``device``: "auto" takes CUDA only when torch sees a GPU and every
    backend lists "cuda" in its devices (so one CPU-only backend does not turn into an error row)."""
    resolved = torch_device(device, "--device")
    if device == "auto" and not all("cuda" in b.info.devices for b in backends):
        return "cpu"
    return resolved


@dataclass(frozen=True)
class CompareRow:
    """One backend on one workload (see the module doc). ``error``: "" or one line."""

    backend: str
    version: str
    workload: str
    n: int
    width: int
    height: int
    error_width: int
    error_height: int
    device: str
    error: str
    verdict_mode: str                         # "matched", or "exact" for a backend declaring exact
    matched: dict[str, ImageError] = field(default_factory=dict)
    exact: dict[str, ImageError] = field(default_factory=dict)
    band: int = 0                             # pixels in the boundary band of the verdict's oracle
    grad_band: int = 0                        # Gaussians in its gradient band (reported apart from the rest)
    tie_pixels: int = 0                       # pixels whose bound depth ties widen
    grad_oracle: str = ""
    grads: dict[str, GradError] = field(default_factory=dict)
    grad_bound: float = math.nan
    timing: Timing = Timing()
    loadavg_start: tuple[float, ...] = ()
    loadavg_end: tuple[float, ...] = ()

    @property
    def forward_verdict(self) -> str:
        errors = self.exact if self.verdict_mode == "exact" else self.matched
        if not errors:
            return "n/a"
        return "within bound" if all(e.outside_band == 0 for e in errors.values()) else "outside bound"

    @property
    def grad_verdict(self) -> str:
        judged = [g for g in self.grads.values() if not math.isnan(g.rel_l2)]
        if not judged:
            return "n/a"
        return "within bound" if all(g.within(self.grad_bound) for g in judged) else "outside bound"


@dataclass(frozen=True)
class CompareResult:
    rows: tuple[CompareRow, ...]
    settings: CompareSettings
    machine: MachineInfo
    command: str
    seconds: float
    notes: tuple[str, ...] = ()   # per workload: resolution of the error measurement, oracles


def auto_scale(width: int, height: int) -> float:
    """The largest 1/2^k (k <= 4) with (W H) / 4^k <= `MAX_ORACLE_PIXELS`."""
    scale = 1.0
    while width * height * scale * scale > MAX_ORACLE_PIXELS and scale > 1 / 16:
        scale /= 2
    return scale


def run_compare(backends: Sequence, workloads: Sequence[Workload | WorkloadSpec], settings: CompareSettings = CompareSettings(), *,
                progress: Callable[[str], None] | None = None, command: str = "") -> CompareResult:
    """Compare ``backends`` on ``workloads`` (module doc).

    Args:
        backends: names, ``module:function`` strings, `Backend`s or callables (`get_backend`).
        workloads: `splatbench.workloads.Workload`s, or `splatbench.workloads.WorkloadSpec`s (built here).
        settings: `CompareSettings`. progress: called with one line per step.
        command: the command line, for the report.

    Returns:
        `CompareResult`: one `CompareRow` per backend x workload, workload by workload.
    """
    from splatbench.compare.measure import FLOAT64_ORACLE, GradOracle, OracleImages, time_backends, \
        torch_inputs
    from splatbench.backends.registry import available, get_backend
    from splatbench.metrics.machine import load_average, machine_info

    settings.validate()
    resolved = [get_backend(b) for b in backends]
    if not resolved:
        raise InputError("--backend: give at least one backend")
    settings = replace(settings, device=_device(settings.device, resolved))
    names = [b.name for b in resolved]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"--backend: {twice[0]!r} given twice (each backend is compared once)")
    if not workloads:
        raise InputError("workloads: give at least one (--synthetic N WxH, --workload, --scene)")
    say = progress or (lambda line: None)
    oracle_spec = settings.grad_oracle
    if oracle_spec == "auto":
        oracle_spec = FLOAT64_ORACLE if FLOAT64_ORACLE in available() else "fd"
    elif oracle_spec not in ("fd", "none"):
        try:
            get_backend(oracle_spec)
        except InputError as exc:
            raise InputError(f"--grad-oracle: {exc} (or 'auto', 'fd', 'none')") from None
    machine = machine_info(settings.device)
    t_start = time.perf_counter()
    rows: list[CompareRow] = []
    notes: list[str] = []
    for spec in workloads:
        workload = spec.build() if isinstance(spec, WorkloadSpec) else spec
        label = (spec.label if isinstance(spec, WorkloadSpec) else "") or workload.name
        camera = workload.camera
        scale = settings.error_scale or auto_scale(camera.width, camera.height)
        err_camera = camera if scale == 1 else camera.scaled(scale)
        images = OracleImages(workload, err_camera)
        t0 = time.perf_counter()
        images.exact  # noqa: B018 - render the exact-mixture oracle once, up front
        say(f"{label}: float64 oracle (exact mixture) at {err_camera.width}x{err_camera.height} in "
            f"{time.perf_counter() - t0:.1f} s")
        notes.append(f"{label}: {len(workload.gaussians):,} Gaussians at {camera.width}x{camera.height}; errors and "
                     f"gradients at {err_camera.width}x{err_camera.height} (scale {scale:g}), times at full "
                     f"resolution")
        params = torch_inputs(workload, settings.device)
        grads = None if oracle_spec == "none" else GradOracle(oracle_spec, images, params, seed=settings.seed,
                                                               entries=settings.fd_entries)
        measured = {b.name: _accuracy(b, images, params, grads, settings, scale, say, label) for b in resolved}
        timeable = [b for b in resolved if not measured[b.name].error
                    and measured[b.name].predicted_s <= settings.max_call_s]
        load_start = tuple(load_average())
        say(f"{label}: timing {', '.join(b.name for b in timeable) or 'nothing'} ({settings.repeats} rounds)")
        timings = time_backends(timeable, params, camera, settings.device, settings.repeats, seed=settings.seed,
                                progress=lambda line: say(f"{label}: {line}"))
        load_end = tuple(load_average())
        for b in resolved:
            m = measured[b.name]
            band, ties, grad_band = _band_size(images, b.info)
            timing = timings.get(b.name, Timing(note=m.untimed))
            errors = [m.error] if m.error else []
            if isinstance(timing, str):
                errors.append(timing)
                timing = Timing()
            rows.append(CompareRow(
                backend=b.name, version=b.info.version, workload=label, n=len(workload.gaussians),
                width=camera.width, height=camera.height, error_width=err_camera.width,
                error_height=err_camera.height, device=settings.device, error="; ".join(errors),
                verdict_mode="exact" if b.info.exact else "matched", matched=m.matched, exact=m.exact,
                band=band, tie_pixels=ties, grad_band=grad_band,
                grad_oracle=m.grad_oracle, grads=m.grads, grad_bound=m.grad_bound, timing=timing,
                loadavg_start=load_start, loadavg_end=load_end))
    machine.loadavg_end = load_average()
    return CompareResult(tuple(rows), settings, machine, command, round(time.perf_counter() - t_start, 1),
                         tuple(notes))


def _band_size(images, info) -> tuple[int, int, int]:
    """(boundary band pixels, pixels with a tie slack, Gaussians in the gradient band) of the oracle
    ``info``'s verdict is against (zeros for the exact oracle, or when the oracle could not render)."""
    if info.exact:
        return 0, 0, 0
    try:
        oracle = images.matched(info)
    except Exception:  # noqa: BLE001 - the row already says why the oracle failed
        return 0, 0, 0
    band, slack = getattr(oracle, "band", None), getattr(oracle, "tie_slack", None)
    gb = getattr(oracle, "grad_band", None)
    return ((0 if band is None else int(band.sum())), (0 if slack is None else int((slack > 0).sum())),
            (0 if gb is None else int(gb.sum())))


@dataclass
class _Accuracy:
    """What `_accuracy` measured of one backend on one workload (filled in step by step)."""

    error: str = ""
    matched: dict = field(default_factory=dict)
    exact: dict = field(default_factory=dict)
    grads: dict = field(default_factory=dict)
    grad_oracle: str = ""
    grad_bound: float = math.nan
    predicted_s: float = math.inf   # predicted seconds of one forward at full resolution
    untimed: str = ""               # why it is not timed ("" = it is)


def _accuracy(backend, images, params, grads, settings: CompareSettings, scale: float, say,
              label: str) -> _Accuracy:
    """Forward errors, gradient errors and the predicted full-resolution forward time of one backend."""
    import torch

    from splatbench.compare.measure import compare_grads, image_errors
    from splatbench.verification.calls import vjp
    from splatbench.metrics.timing import device_sync

    info, camera = backend.info, images.camera
    m = _Accuracy()
    if settings.device not in info.devices:
        m.error = f"device: {backend.name} runs on {', '.join(info.devices)} only (--device {settings.device})"
        return m
    try:
        oracle_matched = images.matched(info)
    except Exception as exc:  # noqa: BLE001 - conventions the oracle cannot reproduce
        m.error = f"oracle: {one_line(exc)}"
        return m
    try:
        seconds = math.inf
        for _ in range(2):  # a second call only when the first (compiling, maybe) predicts too slow a backend
            t0 = time.perf_counter()
            with torch.no_grad():
                out = backend(*params, camera)
            device_sync(settings.device)()
            seconds = min(seconds, time.perf_counter() - t0)
            if seconds / scale ** 2 <= settings.max_call_s:
                break
        m.matched = image_errors(out, oracle_matched, info.outputs)
        m.exact = image_errors(out, images.exact, info.outputs)
    except Exception as exc:  # noqa: BLE001 - one backend's failure never stops the others
        m.error = f"forward: {one_line(exc)}"
        return m
    m.predicted_s = seconds / scale ** 2
    if m.predicted_s > settings.max_call_s:
        m.untimed = (f"not timed: one forward would take ~{m.predicted_s:.0f} s (measured {seconds:.1f} s at "
                     f"scale {scale:g}; limit {settings.max_call_s:g} s)")
    say(f"{label}: {backend.name} forward compared")
    if not info.gradients or info.slow_gradients:
        m.grad_oracle = "not compared: " + ("no gradients" if not info.gradients
                                            else "slow gradients (finite differences)")
        return m
    if grads is None:
        m.grad_oracle = "not compared: --grad-oracle none"
        return m
    try:
        m.grad_oracle, v, ref = grads.reference(info)
    except Exception as exc:  # noqa: BLE001
        m.grad_oracle = f"not compared: gradient oracle failed ({one_line(exc)})"
        return m
    matched = None if info.exact else images.matched(info)
    grad_band = getattr(matched, "grad_band", None)
    try:
        m.grads = compare_grads(vjp(backend, params, camera, v), ref, grad_band)
    except Exception as exc:  # noqa: BLE001
        m.error = f"gradient: {one_line(exc)}"
        return m
    verdict = m.exact if info.exact else m.matched
    band, _, _ = _band_size(images, info)
    m.grad_bound = gradient_bound(camera.width * camera.height, min(band, max(e.outliers for e in verdict.values())),
                                  getattr(matched, "grad_weight", None))
    say(f"{label}: {backend.name} gradients compared ({m.grad_oracle.split(' (')[0]})")
    return m
