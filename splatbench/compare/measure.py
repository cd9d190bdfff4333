"""The measurements of `splatbench.compare.run`: oracle images, image errors, the gradient
oracle, and interleaved timing (the cotangents, a backend's VJP, the float32 bound and the
gradient judgement are the verification core's: `splatbench.verification`).

All images are numpy float64 on the host; backends get float32 torch tensors on the
compare device.
"""

from __future__ import annotations

import gc
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from splatbench.backends.base import GROUPS, OUTPUTS, Backend, as_numpy
from splatbench.compare.timing import Timing
from splatbench.errors import InputError, one_line
from splatbench.metrics.image import psnr
from splatbench.metrics.timing import device_sync
from splatbench.verification.bounds import OFF_THRESHOLD, GradError, ImageError, over_bound
from splatbench.verification.calls import vjp
from splatbench.verification.cotangents import Cotangents
from splatbench.verification.judging import entry_band, grad_error


# ----------------------------------------------------------------------------- oracle
class OracleImages:
    """The float64 renders of one workload at its error camera, each rendered once."""

    def __init__(self, workload, camera):
        self.workload, self.camera = workload, camera
        self._matched: dict[tuple, object] = {}
        self._exact = None

    def _render(self, conventions, mode: str):
        from splatbench.backends.builtins.reference_backend import reference_render

        g = self.workload.gaussians
        return reference_render(conventions, g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, self.camera,
                                mode=mode, band=mode == "matched")

    def matched(self, info):
        """The render with ``info``'s conventions (the exact one for a backend declaring ``exact``),
        with its boundary band and tie slack (`reference.band`; none for the exact one, which
        takes no discrete decisions)."""
        if info.exact:
            return self.exact
        key = tuple(sorted(info.reference_options().items()))
        if key not in self._matched:
            self._matched[key] = self._render(info, "matched")
        return self._matched[key]

    @property
    def exact(self):
        if self._exact is None:
            self._exact = self._render(None, "exact")
        return self._exact


def _composited(out, z_max: float) -> dict[str, np.ndarray]:
    """rgb, alpha and depth * alpha / z_max of a (rgb, alpha, depth) triple."""
    rgb, alpha, depth = (as_numpy(x) for x in out)
    return {"rgb": rgb, "alpha": alpha, "depth": depth * alpha / z_max}


def image_errors(out, oracle, outputs: Sequence[str]) -> dict[str, ImageError]:
    """`ImageError` per declared output of ``out`` (rgb, alpha, depth) against ``oracle`` (a
    `reference.RenderOutput`; its band and tie slack, where it has them, set the bound)."""
    z_max = max(1.0, float(np.abs(oracle.depth).max(initial=0.0)))
    mine = _composited(out, z_max)
    ref = _composited((oracle.rgb, oracle.alpha, oracle.depth), z_max)
    errors = {}
    for name in outputs:
        if mine[name].shape != ref[name].shape:
            raise InputError(f"{name}: shape {list(mine[name].shape)}, expected {list(ref[name].shape)}")
        err = np.abs(mine[name] - ref[name])
        err[~np.isfinite(err)] = np.inf  # a NaN pixel is off by everything
        per_pixel = err.reshape(err.shape[0], err.shape[1], -1).max(-1)
        value = psnr(err, np.zeros_like(err), clamp=False)  # -inf when a pixel is non-finite
        # The tie slack is in the outputs' units (depth * alpha in camera z; / z_max >= 1 only shrinks it).
        over, outside = over_bound(per_pixel, getattr(oracle, "band", None), getattr(oracle, "tie_slack", None))
        errors[name] = ImageError(float(err.max()), value, float(np.mean(per_pixel > OFF_THRESHOLD)), over, outside)
    return errors


def torch_inputs(workload, device: str) -> tuple:
    """The five parameter groups as float32 torch tensors on ``device``."""
    from splatbench.metrics.timing import torch_params

    return tuple(p.to(device) for p in torch_params(workload.gaussians))


# ----------------------------------------------------------------------------- gradient oracle
#: The built-in float64 gradient oracle, used by grad_oracle="auto" when it is registered.
FLOAT64_ORACLE = "torch64"


class GradOracle:
    """The reference gradients of one workload, computed once per conventions and reused.

    ``spec``: "fd", or a float64 backend's name (``torch64``) whose gradients are taken
    as exact where its conventions equal the compared backend's (else, or when it
    fails: "fd"). "fd": central differences (`reference.finite_difference_grad`, float64,
    mode "matched" with the backend's conventions) at ``entries`` random entries per
    group, drawn from the Gaussians the oracle draws.
    """

    def __init__(self, spec: str, images: OracleImages, params: tuple, *, seed: int, entries: int):
        # the oracle runs on the CPU whatever device the compared backends use (``torch64``
        # declares the CPU alone; on CUDA it fell back to finite differences, minutes per backend),
        # on float64 copies of the same float32 values, so its gradients are float64 throughout
        import torch

        params = tuple(p.detach().to("cpu", torch.float64) for p in params)
        self.spec, self.images, self.params, self.seed, self.entries = spec, images, params, seed, entries
        self._cache: dict[tuple, tuple[str, Cotangents, dict]] = {}
        self._backend: Backend | None = None
        self._backend_error = ""
        if spec != "fd":
            from splatbench.backends.registry import get_backend

            try:
                self._backend = get_backend(spec)
            except Exception as exc:  # noqa: BLE001 - fall back to finite differences, and say so
                self._backend_error = f"{spec} unavailable ({one_line(exc)})"

    def reference(self, info) -> tuple[str, Cotangents, dict[str, tuple[np.ndarray | None, np.ndarray]]]:
        """(label, cotangents, group -> (flat indices or None for all, reference values))."""
        key = (info.exact, tuple(sorted(info.reference_options().items())), tuple(info.outputs))
        if key not in self._cache:
            matched = self.images.matched(info)
            v = Cotangents.random(self.seed, *matched.alpha.shape, info.outputs, alpha=matched.alpha)
            self._cache[key] = self._compute(info, v, matched)
        return self._cache[key]

    def _oracle_backend(self, info) -> tuple[Backend | None, str]:
        """The float64 backend with ``info``'s conventions, or None and why not."""
        if self._backend is None:
            return None, self._backend_error
        mine = (self._backend.info.exact, self._backend.info.reference_options())
        if mine == (info.exact, info.reference_options()):
            return self._backend, ""
        if self.spec == FLOAT64_ORACLE and not info.exact:
            from splatbench.backends.builtins.torch_backend import make_torch_matching

            try:
                return make_torch_matching(info), ""
            except Exception as exc:  # noqa: BLE001 - conventions torch64 cannot follow
                return None, one_line(exc)
        return None, f"{self._backend.name} follows other conventions"

    def _compute(self, info, v: Cotangents, matched):
        oracle, why = self._oracle_backend(info)
        if oracle is not None:
            try:
                grads = vjp(oracle, self.params, self.images.camera, v)
                same = oracle is self._backend
                label = f"{oracle.name} (float64, every entry{'' if same else ', ' + info.name + ' conventions'})"
                return label, v, {k: (None, g) for k, g in grads.items()}
            except Exception as exc:  # noqa: BLE001
                why = f"{oracle.name} failed: {one_line(exc)}"
        label = f"fd (float64 reference, central differences, {self.entries} entries per group)"
        return (f"{label}; {why}" if why else label), v, self._finite_differences(info, v, matched.visible)

    def _finite_differences(self, info, v: Cotangents, visible: np.ndarray) -> dict:
        import reference
        from splatbench.backends.builtins.reference_backend import FD_EPS, reference_kwargs

        g = self.images.workload.gaussians
        arrays = [np.asarray(getattr(g, k), dtype=np.float64) for k in GROUPS]
        kwargs = reference_kwargs(info, self.images.camera, "exact" if info.exact else "matched", None, None)
        drawn = np.flatnonzero(visible) if np.any(visible) else np.arange(len(g))
        rng = np.random.default_rng(self.seed)
        out = {}
        for k, array in zip(GROUPS, arrays):
            per = array[0].size  # entries per Gaussian
            picks = rng.choice(drawn, min(self.entries, drawn.size), replace=drawn.size < self.entries)
            idx = np.unique(picks * per + rng.integers(0, per, picks.size))
            values = reference.finite_difference_grad(lambda o: v.loss(o.rgb, o.alpha, o.depth), *arrays, wrt=k,
                                                      indices=idx, eps=FD_EPS, **kwargs)
            out[k] = (idx, values)
        return out


def compare_grads(grads: dict[str, np.ndarray], ref: dict, grad_band: np.ndarray | None = None) -> dict[str, GradError]:
    """`GradError` per group of a backend's gradients against `GradOracle.reference` values;
    ``grad_band`` [N] bool: the Gaussians of the gradient band, measured apart."""
    import dataclasses

    out = {}
    for k, (idx, values) in ref.items():
        band = entry_band(grad_band, grads[k].size, idx)
        e = grad_error(grads[k].ravel() if idx is None else grads[k].ravel()[idx], values, band)
        if band is not None:  # counted in Gaussians, not entries
            per = grads[k].size // len(grad_band)
            drawn = np.unique((np.arange(grads[k].size) if idx is None else np.asarray(idx))[band] // per)
            e = dataclasses.replace(e, band_gaussians=int(drawn.size))
        out[k] = e
    return out


# ----------------------------------------------------------------------------- timing
@dataclass
class _Timed:
    backend: Backend
    forward: Callable[[], None]
    forward_backward: Callable[[], None] | None
    fwd_ms: list
    fwd_bwd_ms: list


def _closures(backend: Backend, params: tuple, camera, v: Cotangents, device: str):
    import torch

    inputs = tuple(p.detach() for p in params)
    leaves = tuple(p.detach().clone().requires_grad_(True) for p in params)
    sync = device_sync(device)

    def forward() -> None:
        with torch.no_grad():
            backend(*inputs, camera)
        sync()

    def forward_backward() -> None:
        v.loss(*backend(*leaves, camera)).backward()
        sync()
        for p in leaves:
            p.grad = None  # as an optimizer's zero_grad(set_to_none=True) would

    fast_grads = backend.info.gradients and not backend.info.slow_gradients
    return forward, (forward_backward if fast_grads else None)


def _ms(fn: Callable[[], None]) -> float:
    t0 = time.perf_counter()
    fn()
    return round((time.perf_counter() - t0) * 1e3, 3)


def _release_caches() -> None:
    """Hand cached free memory back to the OS (Dr.Jit's allocator cache, glibc's free lists),
    so that the RSS before a call is what is live and the rise is what the call needs."""
    import ctypes
    import sys

    if "drjit" in sys.modules:
        flush = getattr(sys.modules["drjit"], "flush_malloc_cache", None)
        if flush is not None:
            flush()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def peak_rise(fn: Callable[[], None], device: str) -> tuple[float, str]:
    """(MB, what it is) of the memory one call of ``fn`` needs above what is held before it."""
    from splatbench.metrics.memory import current_rss_mb, peak_rss_mb, reset_peak_rss

    gc.collect()
    if device == "cuda":
        import torch

        torch.cuda.reset_peak_memory_stats()
        before = torch.cuda.memory_allocated()
        fn()
        return (torch.cuda.max_memory_allocated() - before) / 1e6, \
            "torch CUDA allocator peak rise (Dr.Jit's own CUDA memory not seen)"
    _release_caches()
    before = current_rss_mb()
    if not reset_peak_rss():
        return math.nan, "not measured (no /proc/self/clear_refs to reset the peak RSS)"
    fn()
    rise = max(0.0, peak_rss_mb() - before)
    return rise, "peak RSS rise over the RSS before the call (allocator caches flushed first)"


def time_backends(backends: Sequence[Backend], params: tuple, camera, device: str, repeats: int, *,
                  seed: int = 0, progress: Callable[[str], None] | None = None) -> dict[str, Timing | str]:
    """Interleaved timing (module doc of `splatbench.compare.run`): name -> `Timing`,
    or a one-line error for a backend that raised."""
    v = Cotangents.random(seed, camera.height, camera.width, OUTPUTS)
    results: dict[str, Timing | str] = {}
    timed: list[_Timed] = []
    for b in backends:
        fwd, fwd_bwd = _closures(b, params, camera, v, device)
        try:  # warm-up, untimed: Dr.Jit compiles (or loads its kernel cache) here
            warm = [_ms(fwd)] + ([_ms(fwd_bwd)] if fwd_bwd is not None else [])
        except Exception as exc:  # noqa: BLE001 - one backend's failure never stops the others
            results[b.name] = f"timing warm-up: {one_line(exc)}"
            continue
        if progress:
            progress(f"{b.name}: warm-up " + " and ".join(f"{ms / 1e3:.1f} s" for ms in warm))
        timed.append(_Timed(b, fwd, fwd_bwd, [], []))
    for _ in range(repeats):
        for stage in ("forward", "forward_backward"):
            for t in list(timed):
                fn = getattr(t, stage)
                if fn is None:
                    continue
                try:
                    (t.fwd_ms if stage == "forward" else t.fwd_bwd_ms).append(_ms(fn))
                except Exception as exc:  # noqa: BLE001
                    results[t.backend.name] = f"timing: {one_line(exc)}"
                    timed.remove(t)
    for t in timed:
        try:
            peak, kind = peak_rise(t.forward_backward or t.forward, device)
        except Exception as exc:  # noqa: BLE001
            results[t.backend.name] = f"memory: {one_line(exc)}"
            continue
        note = "" if t.forward_backward else "forward+backward not timed (gradients by finite differences)"
        results[t.backend.name] = Timing(tuple(t.fwd_ms), tuple(t.fwd_bwd_ms), note, round(peak, 1),
                                         kind + ("" if t.forward_backward else ", forward only"))
    return results


def spread(runs: Sequence[float]) -> dict[str, float]:
    """median, quartiles (q1, q3), min and max of ``runs`` (NaN when empty)."""
    if not runs:
        return {k: math.nan for k in ("median", "q1", "q3", "min", "max")}
    q1, _, q3 = statistics.quantiles(runs, n=4, method="inclusive") if len(runs) > 1 else (runs[0],) * 3
    return {"median": statistics.median(runs), "q1": q1, "q3": q3, "min": min(runs), "max": max(runs)}
