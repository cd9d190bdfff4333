"""How `splatbench conform` judges each kind of probe (see `probes` for the kinds)."""

from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np

from splatbench.backends.base import Backend
from splatbench.conform.oracle import (conic_jacobian, forward_tolerance, gradient_band, gradient_gamma, oracle,
                                                oracle_grad)
from splatbench.conform.probes import Probe
from splatbench.conform.results import ProbeResult
from splatbench.render_inputs import RenderInput
from splatbench.verification.calls import finite_gradients, forward, param_tensors, vjp
from splatbench.verification.cotangents import OUTPUT_CHANNELS, Cotangents

#: Seed of conform's cotangents (one draw per probe scene, shared by its gradient probes).
COTANGENT_SEED = 1234


@dataclass(frozen=True)
class Context:
    backend: Backend
    conv: dict
    device: str
    vjps: dict  # scene name -> gradients of the shared cotangent loss (one backward per scene)
    outs: dict = field(default_factory=dict)  # scene name -> the backend's outputs [H, W, 5] (one render per scene)


def _backend_outputs(s: RenderInput, name: str, ctx: Context) -> np.ndarray:
    if name not in ctx.outs:
        ctx.outs[name] = forward(ctx.backend, s, ctx.device)
    return ctx.outs[name]


def _pixel_diff(got: np.ndarray, ref: np.ndarray, outputs: tuple[str, ...]) -> np.ndarray:
    """Per-pixel largest difference [H, W] over the compared outputs (depth as depth * alpha / max depth)."""
    parts = []
    if "rgb" in outputs:
        parts.append(np.abs(got[..., :3] - ref[..., :3]).max(-1))
    if "alpha" in outputs:
        parts.append(np.abs(got[..., 3] - ref[..., 3]))
    if "depth" in outputs:  # weighted by the backend's alpha, or the oracle's when it has none
        z_max = max(1.0, float(np.abs(ref[..., 4]).max()))
        a = got[..., 3] if "alpha" in outputs else ref[..., 3]
        parts.append(np.abs(got[..., 4] * a - ref[..., 4] * ref[..., 3]) / z_max)
    return np.max(parts, axis=0)


def _worst(got: np.ndarray, ref: np.ndarray, outputs: tuple[str, ...]) -> str:
    """Where the largest difference (as `_pixel_diff` measures it) is, in words."""
    best = (-1.0, "")
    z_max = max(1.0, float(np.abs(ref[..., 4]).max()))
    for name, sl in OUTPUT_CHANNELS.items():
        if name not in outputs:
            continue
        d = np.abs(got[..., sl] - ref[..., sl])
        if name == "depth":
            a = got[..., 3:4] if "alpha" in outputs else ref[..., 3:4]
            d = np.abs(got[..., 4:5] * a - ref[..., 4:5] * ref[..., 3:4]) / z_max
        i, j, c = np.unravel_index(int(np.argmax(d)), d.shape)
        if d[i, j, c] > best[0]:
            label = f"{name}[{'rgb'[c]}]" if name == "rgb" else name
            best = (float(d[i, j, c]), f"{label} at pixel (row {i}, col {j}): backend {got[i, j, sl][c]:.6g}, "
                                       f"oracle {ref[i, j, sl][c]:.6g}")
    return best[1]


def _psnr(got: np.ndarray, ref: np.ndarray, outputs: tuple[str, ...]) -> str:
    """", rgb PSNR x dB against the oracle" (peak 1), or "" when rgb is not compared."""
    if "rgb" not in outputs:
        return ""
    from splatbench.metrics.image import psnr

    value = psnr(got[..., :3], ref[..., :3], clamp=False)
    return f", rgb PSNR {value:.1f} dB against the oracle" if math.isfinite(value) else ""


def _nothing_drawn(got: np.ndarray, ref: np.ndarray, outputs: tuple[str, ...]) -> str:
    """"the backend drew nothing ...; " when its alpha is zero everywhere and the oracle's is not, else "".

    An empty image fails every probe whatever the probe isolates (a cull outside the convention
    vocabulary, e.g. of Gaussians wider than the image): said first, so no probe's cause is read
    as the reason."""
    if "alpha" not in outputs or got[..., 3].any() or not ref[..., 3].any():
        return ""
    return f"the backend drew nothing (alpha 0 everywhere; the oracle covers {int((ref[..., 3] > 0).sum())} pixels); "


def _compared(probe: Probe, ctx: Context) -> tuple[str, ...]:
    return tuple(o for o in probe.outputs if o in ctx.backend.info.outputs)


def _judge_forward(probe: Probe, s: RenderInput, ctx: Context) -> ProbeResult:
    outputs = _compared(probe, ctx)
    if not outputs:
        return _skip(probe, f"the backend does not produce {', '.join(probe.outputs)}")
    atol, source = forward_tolerance(s, ctx.conv)
    ref = oracle(probe.build.__name__, s, ctx.conv)
    got = _backend_outputs(s, probe.build.__name__, ctx)
    diff = _pixel_diff(got, ref, outputs)
    dev = float(diff.max())
    ok = dev <= atol
    detail = (f"{', '.join(outputs)} within tolerance" if ok else
              f"{_nothing_drawn(got, ref, outputs)}{int((diff > atol).sum())} of {diff.size} pixels differ"
              f"{_psnr(got, ref, outputs)}; largest: {_worst(got, ref, outputs)}")
    return ProbeResult(probe.name, probe.kind, "pass" if ok else "fail", probe.checks, dev, atol, source, detail,
                       None if ok else probe.cause)


def _judge_approximation(probe: Probe, s: RenderInput, ctx: Context) -> ProbeResult:
    outputs = _compared(probe, ctx)
    atol, source = forward_tolerance(s, ctx.conv)
    got = _backend_outputs(s, probe.build.__name__, ctx)
    ref = oracle(probe.build.__name__, s, ctx.conv)
    diff = _pixel_diff(got, ref, outputs)
    dev = float(diff.max())
    if dev <= atol:
        return ProbeResult(probe.name, probe.kind, "pass", probe.checks, dev, atol, source,
                           "follows the declared " + _declared(probe, ctx.conv), None)
    ok = diff <= atol
    matched = []
    for alt in probe.alternatives:
        conv = {**ctx.conv, **alt}
        if conv == ctx.conv:
            continue
        alt_ref = oracle(probe.build.__name__, s, conv)
        here = _pixel_diff(got, alt_ref, outputs) <= atol
        if (here & ~ok).any():
            effect = float(_pixel_diff(alt_ref, ref, outputs).max())
            matched.append(f"{_fmt(alt)} at {int((here & ~ok).sum())} pixels (effect {effect:.3g})")
        ok |= here
    where = f"{int((diff > atol).sum())} of {diff.size} pixels differ from the declared {_declared(probe, ctx.conv)}"
    if ok.all():
        return ProbeResult(probe.name, probe.kind, "warn", probe.checks, dev, atol, source,
                           f"{where}; they match {'; '.join(matched)}", probe.cause)
    return ProbeResult(probe.name, probe.kind, "fail", probe.checks, dev, atol, source,
                       f"{where} and from every alternative; largest: {_worst(got, ref, outputs)}", probe.cause)


def _declared(probe: Probe, conv: dict) -> str:
    keys = sorted({k for alt in probe.alternatives for k in alt})
    return _fmt({k: conv[k] for k in keys})


def _fmt(d: dict) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in d.items())


def _rel(got: np.ndarray, want: np.ndarray, bound: np.ndarray) -> tuple[float, float]:
    """(relative L2 error, its tolerance); absolute when the oracle's gradient is zero."""
    scale = float(np.linalg.norm(want)) or 1.0
    return float(np.linalg.norm(got - want)) / scale, float(np.linalg.norm(bound)) / scale


def _backend_grads(probe: Probe, s: RenderInput, ctx: Context, v: Cotangents) -> dict[str, np.ndarray]:
    key = probe.build.__name__
    if key not in ctx.vjps:
        ctx.vjps[key] = finite_gradients(vjp(ctx.backend, param_tensors(s, ctx.device), s.camera, v,
                                             sh_degree=s.sh_degree, background=s.background))
    return ctx.vjps[key]


def _judge_gradient(probe: Probe, s: RenderInput, ctx: Context) -> ProbeResult:
    if not ctx.backend.info.gradients:
        return _skip(probe, "the backend declares no gradients")
    v = Cotangents.random(COTANGENT_SEED, s.camera.height, s.camera.width, ctx.backend.info.outputs)
    grads = _backend_grads(probe, s, ctx, v)
    gamma, source = gradient_gamma(s, ctx.conv)
    band, widen = gradient_band(probe.build.__name__, s, ctx.conv)
    measured = []  # (deviation, tolerance, group)
    for g in probe.groups:
        want, bound = oracle_grad(probe.build.__name__, s, ctx.conv, g, v.stacked(), gamma)
        out = ~np.repeat(band, want.size // band.size)  # judged outside the gradient band (reference.band)
        dev, tol = _rel(grads[g].reshape(-1)[out], want[out], bound[out])
        measured.append((dev, tol + widen, g))
    dev, tol, _ = max(measured, key=lambda m: m[0] / m[1] if m[1] > 0 else np.inf)
    failed = any(d > t for d, t, _ in measured)
    detail = "relative L2: " + ", ".join(f"{g} {d:.2e} (tol {t:.1e})" for d, t, g in measured)
    if band.any():
        detail += f" (outside the gradient band of {int(band.sum())} Gaussians)"
    return ProbeResult(probe.name, probe.kind, "fail" if failed else "pass", probe.checks, dev, tol, source,
                       detail, probe.cause if failed else None)


def _judge_direction(probe: Probe, s: RenderInput, ctx: Context) -> ProbeResult:
    if not ctx.backend.info.gradients:
        return _skip(probe, "the backend declares no gradients")
    name, n = probe.build.__name__, s.means.shape[0]
    v = Cotangents.random(COTANGENT_SEED, s.camera.height, s.camera.width, ctx.backend.info.outputs)
    grads = _backend_grads(probe, s, ctx, v)
    gamma, source = gradient_gamma(s, ctx.conv)
    ls, ls_bound = oracle_grad(name, s, ctx.conv, "log_scales", v.stacked(), gamma)
    q, q_bound = oracle_grad(name, s, ctx.conv, "quats", v.stacked(), gamma)
    want_all = np.concatenate([ls.reshape(n, 3), q.reshape(n, 4)], 1)
    bound_all = np.concatenate([ls_bound.reshape(n, 3), q_bound.reshape(n, 4)], 1)
    got_all = np.concatenate([grads["log_scales"].reshape(n, 3), grads["quats"].reshape(n, 4)], 1)
    deltas = np.linalg.pinv(conic_jacobian(name, s, ctx.conv))[:, :, probe.conic_term]  # [N, 7]
    deltas /= np.linalg.norm(deltas, axis=1, keepdims=True)
    got, want = (got_all * deltas).sum(1), (want_all * deltas).sum(1)
    dev, tol = _rel(got, want, (bound_all * np.abs(deltas)).sum(1))
    ok = dev <= tol
    return ProbeResult(probe.name, probe.kind, "pass" if ok else "fail", probe.checks, dev, tol,
                       source.replace("entries", "Gaussians' directional derivatives"),
                       f"directional derivatives: backend {np.array2string(got, precision=5)}, "
                       f"oracle {np.array2string(want, precision=5)}", None if ok else probe.cause)


def _skip(probe: Probe, why: str) -> ProbeResult:
    return ProbeResult(probe.name, probe.kind, "skip", probe.checks, None, None, "", why, None)


JUDGES = {"forward": _judge_forward, "approximation": _judge_approximation, "gradient": _judge_gradient,
          "direction": _judge_direction}
