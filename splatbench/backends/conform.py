"""`conform`: run the probes of `splatbench.backends.probes` on a backend and judge each one.

    report = conform(get_backend("drjit"))      # or any Backend / module:function spec
    report.failed                               # names of the failing probes
    report.to_dict()                            # {"backend", "passed", "summary", "probes": [...]}

Each probe is rendered by the backend (float32 torch inputs) and by the float64 oracle
(`reference_render`, matched to the conventions the backend declares in its `BackendInfo`),
and gets a status: pass, fail, warn (a declared approximation not followed, but one of its
listed alternatives is) or skip (the backend lacks the output or gradients the probe needs).

Tolerances, derived (u = 2^-24, float32 unit roundoff; every number below is computed per probe):

* Forward. A pixel value is sum_i T_i a_i c_i over L composited terms; T_i carries i roundings
  and each a_i c_i about 20 float32 operations, so |error| <= (2 L + 20) u max|c| (as in
  tests/test_raster_parity.py). The exponent sigma = d^T conic d / 2 comes from a 2x2 inverse
  whose relative error is up to kappa u (kappa: condition number of the 2D covariance), and
  sigma <= ln(255) ~ 6 wherever alpha >= 1/255, adding 6 kappa u. The tolerance is three times
  the sum: atol = 3 ((2 L + 20) max|c| + 6 kappa) u. Depth is compared as depth * alpha (the
  composited sum of T a z) scaled by the largest depth, since depth = sum / alpha amplifies
  alpha's error by 1 / alpha.
* Gradients. The VJP of loss = sum(v . outputs) (v: seeded normal cotangents) sums, for each
  parameter entry i, P = H W per-pixel terms t_pi; float32 summation errs by at most
  (P + 2 L + 20 + 6 kappa) u sum_p |t_pi| (recovering T by division in a backward pass costs one
  rounding per step, no more: the accumulated colour behind a Gaussian is at most T (1 - alpha) max|c|).
  For opacity_logits, sigmoid' = o (1 - o) where 1 - o carries an absolute float32 error u: a
  further relative u / (1 - o). The oracle is central differences of the float64 oracle with half
  step h = 1e-6: truncation ~h^2 = 1e-12 relative, rounding ~u64 sum_p |v_p out_p| / h. The
  per-entry bound is 3 (P + 2 L + 20 + 6 kappa) u S_i (+ 3 u / (1 - o) S_i) plus the rounding term, with S_i = sum_p |t_pi| measured from the difference images; the
  tolerance on the group's relative L2 error is the L2 norm of those bounds over |g_oracle|.

Every probe scene keeps its pixels away from discrete decisions (cutoff, alpha_min, clamp, early
stop), so float32 and float64 never decide a pixel differently (tests/test_conform.py checks this).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from splatbench.backends.base import Backend
from splatbench.backends.probes import GROUPS, PROBES, Probe, ProbeScene
from splatbench.errors import InputError

STATUSES = ("pass", "fail", "warn", "skip")
U32 = 2.0 ** -24
U64 = 2.0 ** -53
FD_H = 1e-6
MARGIN = 3.0
COTANGENT_SEED = 1234
OUTPUT_CHANNELS = {"rgb": slice(0, 3), "alpha": slice(3, 4), "depth": slice(4, 5)}


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


class _Fault(Exception):
    """The backend misbehaved (raised, wrong shape, NaN): the probe fails with this one line."""


# ----------------------------------------------------------------------------
# Oracle
# ----------------------------------------------------------------------------

def conventions_of(backend: Backend) -> dict:
    """`reference_render` keywords for the backend's declared conventions. radius "none" (no cutoff)
    renders as "opacity": that rule cuts exactly where alpha falls below alpha_min, which is skipped anyway."""
    conv = backend.info.reference_options()
    if conv["radius"] == "none":
        conv["radius"] = "opacity"
    return conv


_CACHE: dict = {}


def _key(probe_scene: str, conv: dict, *extra) -> tuple:
    return (probe_scene, tuple(sorted(conv.items())), *extra)


def _stack(out) -> np.ndarray:
    """rgb [H, W, 3], alpha [H, W], depth [H, W] -> [H, W, 5] float64."""
    rgb, alpha, depth = (np.asarray(x, dtype=np.float64) for x in out)
    return np.concatenate([rgb, alpha[..., None], depth[..., None]], axis=-1)


def _oracle_params(s: ProbeScene, conv: dict, params: dict | None = None) -> np.ndarray:
    from splatbench.backends.builtins.reference_backend import reference_render

    p = s.params() if params is None else params
    out = reference_render(conv, *(p[k] for k in GROUPS), s.camera, sh_degree=s.sh_degree, background=s.background)
    return _stack((out.rgb, out.alpha, out.depth))


def oracle(name: str, s: ProbeScene, conv: dict) -> np.ndarray:
    """The float64 oracle's outputs [H, W, 5] (rgb, alpha, depth) of a probe scene (cached)."""
    key = _key(name, conv, "render")
    if key not in _CACHE:
        _CACHE[key] = _oracle_params(s, conv)
    return _CACHE[key]


def fd_jacobian(name: str, s: ProbeScene, conv: dict, group: str) -> np.ndarray:
    """d outputs / d each entry of ``group`` by central differences: [n_entries, H, W, 5] (cached)."""
    key = _key(name, conv, "fd", group)
    if key not in _CACHE:
        params = {k: np.array(v) for k, v in s.params().items()}
        flat = params[group].reshape(-1)
        images = []
        for i in range(flat.size):
            x = flat[i]
            flat[i] = x + FD_H
            plus, x_plus = _oracle_params(s, conv, params), flat[i]
            flat[i] = x - FD_H
            minus, x_minus = _oracle_params(s, conv, params), flat[i]
            flat[i] = x
            images.append((plus - minus) / (x_plus - x_minus))
        _CACHE[key] = np.stack(images)
    return _CACHE[key]


def _projection(s: ProbeScene, conv: dict, params: dict | None = None):
    import reference

    p = s.params() if params is None else params
    c = s.camera
    return reference.project(p["means"], p["log_scales"], p["quats"], p["opacity_logits"], c.K, c.world_to_camera,
                             c.width, c.height, eps2d=conv["eps2d"], near=conv.get("near", c.near),
                             far=conv.get("far", c.far), radius=conv["radius"], alpha_min=conv["alpha_min"],
                             antialiased=conv["antialiased"])


def _scene_constants(s: ProbeScene, conv: dict) -> tuple[int, float, float]:
    """L (Gaussians drawn), kappa (largest 2D condition number), a bound on max|colour|."""
    proj = _projection(s, conv)
    A, B, C = proj.conics[proj.visible].T
    mean, dev = (A + C) / 2, np.sqrt(((A - C) / 2) ** 2 + B ** 2)
    kappa = float(np.max((mean + dev) / (mean - dev), initial=1.0))
    out_max = max(1.0, *(abs(b) for b in (s.background or (0.0,))))
    colour_bound = 0.5 + 1.1 * float(np.abs(s.sh).sum(axis=1).max())  # every SH basis value is <= 1.1

    return int(proj.visible.sum()), kappa, max(out_max, colour_bound)


def forward_tolerance(s: ProbeScene, conv: dict) -> tuple[float, str]:
    L, kappa, c_max = _scene_constants(s, conv)
    atol = MARGIN * ((2 * L + 20) * c_max + 6 * kappa) * U32
    return atol, (f"3 ((2 L + 20) max|c| + 6 kappa) u with L={L}, max|c|={c_max:.2g}, kappa={kappa:.3g}, "
                  f"u=2^-24 (float32 compositing and 2x2 inverse bounds)")


# ----------------------------------------------------------------------------
# Backend side
# ----------------------------------------------------------------------------

def _tensors(s: ProbeScene, device: str, grad: bool) -> list:
    import torch

    return [torch.tensor(getattr(s, k), dtype=torch.float32, device=device, requires_grad=grad) for k in GROUPS]


def _render(backend: Backend, s: ProbeScene, params: list):
    """The backend's (rgb, alpha, depth) as given, after checks of shape and values."""
    try:
        out = backend(*params, s.camera, sh_degree=s.sh_degree, background=s.background)
    except Exception as exc:  # noqa: BLE001 - any failure of user code is a probe failure, reported in one line
        first = (str(exc).strip().splitlines() or [""])[0]
        raise _Fault(f"backend raised {type(exc).__name__}: {first}") from None
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        raise _Fault(f"backend returned {type(out).__name__}, expected a tuple (rgb, alpha, depth)")
    H, W = s.camera.height, s.camera.width
    for name, x, shape in zip(("rgb", "alpha", "depth"), out, ((H, W, 3), (H, W), (H, W))):
        got = tuple(getattr(x, "shape", ()))
        if got != shape:
            raise _Fault(f"{name}: shape {list(got)}, expected {list(shape)} (H={H}, W={W})")
    return out


def _numpy(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().double().numpy()
    return np.asarray(x, dtype=np.float64)


def _outputs(backend: Backend, s: ProbeScene, device: str) -> np.ndarray:
    import torch

    with torch.no_grad():
        out = _stack([_numpy(x) for x in _render(backend, s, _tensors(s, device, False))])
    bad = ~np.isfinite(out)
    if bad.any():
        i, j, c = (int(k) for k in np.argwhere(bad)[0])
        raise _Fault(f"non-finite {_channel_name(c)} at pixel (row {i}, col {j})")
    return out


def _channel_name(c: int) -> str:
    return ("rgb", "rgb", "rgb", "alpha", "depth")[c]


def _cotangents(s: ProbeScene, outputs: tuple[str, ...]) -> np.ndarray:
    """Seeded normal cotangents [H, W, 5]; zero for outputs the backend does not produce."""
    v = np.random.default_rng(COTANGENT_SEED).standard_normal((s.camera.height, s.camera.width, 5))
    for name, sl in OUTPUT_CHANNELS.items():
        if name not in outputs:
            v[..., sl] = 0.0
    return v


def _vjp(backend: Backend, s: ProbeScene, v: np.ndarray, device: str) -> dict[str, np.ndarray]:
    import torch

    params = _tensors(s, device, True)
    out = _render(backend, s, params)
    if not all(isinstance(x, torch.Tensor) for x in out) or not any(x.requires_grad for x in out):
        raise _Fault("outputs carry no autograd graph (declare gradients=False if the backend has none)")
    loss = sum((x.double() * torch.as_tensor(v[..., sl].reshape(x.shape), device=x.device)).sum()
               for x, sl in zip(out, OUTPUT_CHANNELS.values()) if x.requires_grad)
    try:
        loss.backward()
    except Exception as exc:  # noqa: BLE001
        raise _Fault(f"backward raised {type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}") from None
    grads = {k: np.zeros(p.shape) if p.grad is None else _numpy(p.grad) for k, p in zip(GROUPS, params)}
    for k, g in grads.items():
        if not np.isfinite(g).all():
            raise _Fault(f"non-finite gradient of {k}")
    return grads


# ----------------------------------------------------------------------------
# Judges
# ----------------------------------------------------------------------------

@dataclass(frozen=True)
class _Context:
    backend: Backend
    conv: dict
    device: str
    vjps: dict  # scene name -> gradients of the shared cotangent loss (one backward per scene)


def _pixel_diff(got: np.ndarray, ref: np.ndarray, outputs: tuple[str, ...]) -> np.ndarray:
    """Per-pixel largest difference [H, W] over the compared outputs (depth as depth * alpha / max depth)."""
    parts = []
    if "rgb" in outputs:
        parts.append(np.abs(got[..., :3] - ref[..., :3]).max(-1))
    if "alpha" in outputs:
        parts.append(np.abs(got[..., 3] - ref[..., 3]))
    if "depth" in outputs:
        z_max = max(1.0, float(np.abs(ref[..., 4]).max()))
        parts.append(np.abs(got[..., 4] * got[..., 3] - ref[..., 4] * ref[..., 3]) / z_max)
    return np.max(parts, axis=0)


def _worst(got: np.ndarray, ref: np.ndarray, outputs: tuple[str, ...]) -> str:
    """Where the largest difference is, in words."""
    best = (-1.0, "")
    for name, sl in OUTPUT_CHANNELS.items():
        if name not in outputs:
            continue
        d = np.abs(got[..., sl] - ref[..., sl])
        i, j, c = np.unravel_index(int(np.argmax(d)), d.shape)
        if d[i, j, c] > best[0]:
            label = f"{name}[{'rgb'[c]}]" if name == "rgb" else name
            best = (float(d[i, j, c]), f"{label} at pixel (row {i}, col {j}): backend {got[i, j, sl][c]:.6g}, "
                                       f"oracle {ref[i, j, sl][c]:.6g}")
    return best[1]


def _compared(probe: Probe, ctx: _Context) -> tuple[str, ...]:
    return tuple(o for o in probe.outputs if o in ctx.backend.info.outputs)


def _judge_forward(probe: Probe, s: ProbeScene, ctx: _Context) -> ProbeResult:
    outputs = _compared(probe, ctx)
    if not outputs:
        return _skip(probe, f"the backend does not produce {', '.join(probe.outputs)}")
    atol, source = forward_tolerance(s, ctx.conv)
    ref = oracle(probe.build.__name__, s, ctx.conv)
    got = _outputs(ctx.backend, s, ctx.device)
    diff = _pixel_diff(got, ref, outputs)
    dev = float(diff.max())
    ok = dev <= atol
    detail = (f"{outputs} within tolerance" if ok else
              f"{int((diff > atol).sum())} of {diff.size} pixels differ; largest: {_worst(got, ref, outputs)}")
    return ProbeResult(probe.name, probe.kind, "pass" if ok else "fail", probe.checks, dev, atol, source, detail,
                       None if ok else probe.cause)


def _judge_approximation(probe: Probe, s: ProbeScene, ctx: _Context) -> ProbeResult:
    outputs = _compared(probe, ctx)
    atol, source = forward_tolerance(s, ctx.conv)
    got = _outputs(ctx.backend, s, ctx.device)
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


def _gamma(s: ProbeScene, conv: dict) -> tuple[float, str]:
    L, kappa, _ = _scene_constants(s, conv)
    P = s.camera.width * s.camera.height
    gamma = MARGIN * (P + 2 * L + 20 + 6 * kappa) * U32
    return gamma, (f"L2 over entries of [3 (P + 2 L + 20 + 6 kappa) u sum_p |v_p dout_p| (+ 3 u / (1 - o) "
                   f"sum_p |...| for opacity_logits) + FD rounding] / |g_oracle|, P={P}, L={L}, kappa={kappa:.3g}")


def _oracle_grad(name: str, s: ProbeScene, ctx: _Context, group: str, v: np.ndarray, gamma: float):
    """The oracle's gradient of sum(v . outputs) for ``group`` [n] and the per-entry error bound [n]."""
    J = fd_jacobian(name, s, ctx.conv, group)
    terms = (J * v[None]).reshape(J.shape[0], -1)
    rounding = U64 * float(np.abs(v * oracle(name, s, ctx.conv)).sum()) / FD_H
    rel = np.full(J.shape[0], gamma)
    if group == "opacity_logits":  # sigmoid' = o (1 - o): 1 - o carries an absolute float32 error u
        o = 1.0 / (1.0 + np.exp(-s.opacity_logits))
        rel = rel + MARGIN * U32 / (1.0 - o)
    return terms.sum(1), rel * np.abs(terms).sum(1) + rounding


def _rel(got: np.ndarray, want: np.ndarray, bound: np.ndarray) -> tuple[float, float]:
    """(relative L2 error, its tolerance); absolute when the oracle's gradient is zero."""
    scale = float(np.linalg.norm(want)) or 1.0
    return float(np.linalg.norm(got - want)) / scale, float(np.linalg.norm(bound)) / scale


def _backend_grads(probe: Probe, s: ProbeScene, ctx: _Context, v: np.ndarray) -> dict[str, np.ndarray]:
    key = probe.build.__name__
    if key not in ctx.vjps:
        ctx.vjps[key] = _vjp(ctx.backend, s, v, ctx.device)
    return ctx.vjps[key]


def _judge_gradient(probe: Probe, s: ProbeScene, ctx: _Context) -> ProbeResult:
    if not ctx.backend.info.gradients:
        return _skip(probe, "the backend declares no gradients")
    v = _cotangents(s, ctx.backend.info.outputs)
    grads = _backend_grads(probe, s, ctx, v)
    gamma, source = _gamma(s, ctx.conv)
    worst, parts, failed = (0.0, 0.0), [], False
    for g in probe.groups:
        want, bound = _oracle_grad(probe.build.__name__, s, ctx, g, v, gamma)
        dev, tol = _rel(grads[g].reshape(-1), want, bound)
        parts.append(f"{g} {dev:.2e} (tol {tol:.1e})")
        failed |= dev > tol
        if dev / tol > worst[0] / max(worst[1], 1e-300) or not worst[1]:
            worst = (dev, tol)
    return ProbeResult(probe.name, probe.kind, "fail" if failed else "pass", probe.checks, worst[0], worst[1],
                       source, "relative L2: " + ", ".join(parts), probe.cause if failed else None)


def conic_jacobian(name: str, s: ProbeScene, conv: dict) -> np.ndarray:
    """d (A, B, C) / d (log_scales, quats) per Gaussian: [N, 3, 7], central differences (cached)."""
    key = _key(name, conv, "conic")
    if key not in _CACHE:
        n = s.means.shape[0]
        out = np.zeros((n, 3, 7))
        for j, (group, col) in enumerate([("log_scales", c) for c in range(3)] + [("quats", c) for c in range(4)]):
            cols = []
            for sign in (1.0, -1.0):
                params = {k: np.array(x) for k, x in s.params().items()}
                params[group][:, col] += sign * FD_H
                cols.append(_projection(s, conv, params).conics)
            out[:, :, j] = (cols[0] - cols[1]) / (2 * FD_H)
        _CACHE[key] = out
    return _CACHE[key]


def _judge_direction(probe: Probe, s: ProbeScene, ctx: _Context) -> ProbeResult:
    if not ctx.backend.info.gradients:
        return _skip(probe, "the backend declares no gradients")
    name, n = probe.build.__name__, s.means.shape[0]
    v = _cotangents(s, ctx.backend.info.outputs)
    grads = _backend_grads(probe, s, ctx, v)
    gamma, source = _gamma(s, ctx.conv)
    ls, ls_bound = _oracle_grad(name, s, ctx, "log_scales", v, gamma)
    q, q_bound = _oracle_grad(name, s, ctx, "quats", v, gamma)
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


# ----------------------------------------------------------------------------
# Entry point
# ----------------------------------------------------------------------------

def conform(backend, *, device: str | None = None, probes: tuple[str, ...] | None = None) -> ConformReport:
    """Run the conformance probes on ``backend`` and judge each.

    Args:
        backend: a `Backend`, a callable, or a spec for `get_backend` ("drjit", "mypkg.rast:render", ...).
        device: where the inputs live ("cpu", "cuda"); default "cpu" when the backend runs there.
        probes: names of the probes to run (default: all, in `PROBES` order).

    Returns:
        `ConformReport` (``.passed``, ``.failed``, ``.results``, ``.to_dict()``).
    """
    from splatbench.backends.registry import get_backend

    backend = get_backend(backend) if not isinstance(backend, Backend) else backend
    devices = backend.info.devices
    device = device or ("cpu" if "cpu" in devices else devices[0])
    if device not in devices:
        raise InputError(f"device: backend {backend.name!r} runs on {', '.join(devices)}, not {device!r}")
    selected = PROBES
    if probes:
        known = {p.name: p for p in PROBES}
        unknown = [n for n in probes if n not in known]
        if unknown:
            raise InputError(f"probes: unknown probe {unknown[0]!r} (known: {', '.join(known)})")
        selected = tuple(known[n] for n in probes)
    ctx = _Context(backend, conventions_of(backend), device, {})
    results = []
    for probe in selected:
        s = probe.build()
        try:
            results.append(JUDGES[probe.kind](probe, s, ctx))
        except _Fault as fault:
            results.append(ProbeResult(probe.name, probe.kind, "fail", probe.checks, None, None, "", str(fault),
                                       probe.cause))
    declared = {k: getattr(backend.info, k) for k in backend.info.declared}
    return ConformReport(backend.name, backend.info.description, device, declared, tuple(results))
