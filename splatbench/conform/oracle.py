"""The oracle side of `splatbench conform`: float64 renders, finite differences and derived tolerances.

The oracle is `reference_render` (float64 `reference.render`, matched to the conventions a
backend declares); its gradients are central differences, kept per entry as difference images
so that the tolerance of each entry can be computed from its per-pixel terms. Results are
cached per (scene, conventions): the broken-backend tests share them.

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
  per-entry bound is 3 (P + 2 L + 20 + 6 kappa) u S_i (+ 3 u / (1 - o) S_i) plus the rounding
  term, with S_i = sum_p |t_pi| measured from the difference images; the tolerance on the
  group's relative L2 error is the L2 norm of those bounds over |g_oracle|.

Every probe scene keeps its pixels away from discrete decisions (cutoff, alpha_min, clamp, early
stop), so float32 and float64 never decide a pixel differently (tests/test_conform.py checks this).
"""

from __future__ import annotations

import numpy as np

from splatbench.backends.base import Backend
from splatbench.gaussians import GROUPS
from splatbench.render_inputs import RenderInput
from splatbench.conventions import U32
from splatbench.verification.calls import stack

U64 = 2.0 ** -53
FD_H = 1e-6
MARGIN = 3.0


def conventions_of(backend: Backend) -> dict:
    """`reference_render` keywords for the backend's declared conventions (`BackendInfo.reference_options`)."""
    return backend.info.reference_options()


_CACHE: dict = {}


def _key(probe_scene: str, conv: dict, *extra) -> tuple:
    return (probe_scene, tuple(sorted(conv.items())), *extra)


def _kwargs(s: RenderInput, conv: dict) -> dict:
    from splatbench.backends.builtins.reference_backend import reference_kwargs

    return reference_kwargs(conv, s.camera, "matched", s.sh_degree, s.background)


def _oracle_params(s: RenderInput, conv: dict, params: dict | None = None) -> np.ndarray:
    import reference

    p = s.params() if params is None else params
    kwargs = _kwargs(s, conv)
    if conv.get("sh_view_direction") == "detached":  # the direction from the unperturbed means: no d/dmeans
        kwargs["sh_dir_means"] = s.means
    out = reference.render(*(p[k] for k in GROUPS), **kwargs)
    return stack((out.rgb, out.alpha, out.depth))


#: graphdeco's conventions as a conform conventions mapping.
_GRAPHDECO_CONV: dict = {}


def effective(name: str, s: RenderInput, conv: dict) -> dict:
    """``conv`` with every convention that changes nothing in this scene's render set back to graphdeco's.

    Used as the cache key of the finite differences: a convention that leaves the render bitwise
    unchanged leaves its derivatives unchanged too, since every probe scene keeps its pixels away from
    discrete decisions (clamps, skips, cutoffs), which a step of FD_H cannot cross
    (tests/test_conform.py). "detached" changes gradients only, so it is always kept."""
    if not _GRAPHDECO_CONV:
        from splatbench.backends.base import BackendInfo

        _GRAPHDECO_CONV.update(BackendInfo(name="graphdeco").reference_options())
    key = _key(name, conv, "effective")
    if key not in _CACHE:
        eff, ref = dict(conv), oracle(name, s, conv)
        for k, v in conv.items():
            if k in _GRAPHDECO_CONV and v != _GRAPHDECO_CONV[k] and not (k == "sh_view_direction" and v == "detached"):
                trial = {**eff, k: _GRAPHDECO_CONV[k]}
                if np.array_equal(oracle(name, s, trial), ref):
                    eff = trial
        _CACHE[key] = eff
    return _CACHE[key]


def oracle(name: str, s: RenderInput, conv: dict) -> np.ndarray:
    """The float64 oracle's outputs [H, W, 5] (rgb, alpha, depth) of a probe scene (cached)."""
    key = _key(name, conv, "render")
    if key not in _CACHE:
        _CACHE[key] = _oracle_params(s, conv)
    return _CACHE[key]


def gradient_band(name: str, s: RenderInput, conv: dict) -> tuple[np.ndarray, float]:
    """(the Gaussians of the probe scene's gradient band [N] bool, the relative widening of the other
    entries' bound sqrt(sum_p w_p^2 / P)) (`reference.band`; cached). Every probe scene keeps its pixels
    away from discrete decisions, so both are empty on conform's own scenes; a scene that does not is
    judged outside its band, as compare judges a real model."""
    key = _key(name, conv, "grad_band")
    if key not in _CACHE:
        import reference

        kwargs = _kwargs(s, conv)
        if conv.get("sh_view_direction") == "detached":
            kwargs["sh_dir_means"] = s.means
        out = reference.render(*(s.params()[k] for k in GROUPS), band=True, **kwargs)
        P = s.camera.width * s.camera.height
        _CACHE[key] = (out.grad_band, float(np.sqrt(np.square(out.grad_weight).sum() / P)))
    return _CACHE[key]


def fd_jacobian(name: str, s: RenderInput, conv: dict, group: str) -> np.ndarray:
    """d outputs / d each entry of ``group`` by central differences: [n_entries, H, W, 5] (cached)."""
    conv = effective(name, s, conv)
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


PROJECT_KEYWORDS = ("eps2d", "near", "far", "radius", "alpha_min", "antialiased", "quat_order", "scale_activation",
                    "opacity_activation", "jacobian_guard")


def projection(s: RenderInput, conv: dict, params: dict | None = None):
    import reference

    p = s.params() if params is None else params
    c = s.camera
    kwargs = _kwargs(s, conv)
    return reference.project(p["means"], p["log_scales"], p["quats"], p["opacity_logits"], c.K, c.world_to_camera,
                             c.width, c.height, **{k: kwargs[k] for k in PROJECT_KEYWORDS})


def _scene_constants(s: RenderInput, conv: dict) -> tuple[int, float, float]:
    """L (Gaussians drawn), kappa (largest 2D condition number), a bound on max|colour|."""
    proj = projection(s, conv)
    A, B, C = proj.conics[proj.visible].T
    mean, dev = (A + C) / 2, np.sqrt(((A - C) / 2) ** 2 + B ** 2)
    kappa = float(np.max((mean + dev) / (mean - dev), initial=1.0))
    out_max = max(1.0, *(abs(b) for b in (s.background or (0.0,))))
    colour_bound = 0.5 + 1.1 * float(np.abs(s.sh).sum(axis=1).max())  # every SH basis value is <= 1.1

    return int(proj.visible.sum()), kappa, max(out_max, colour_bound)


def forward_tolerance(s: RenderInput, conv: dict) -> tuple[float, str]:
    L, kappa, c_max = _scene_constants(s, conv)
    atol = MARGIN * ((2 * L + 20) * c_max + 6 * kappa) * U32
    return atol, (f"3 ((2 L + 20) max|c| + 6 kappa) u with L={L}, max|c|={c_max:.2g}, kappa={kappa:.3g}, "
                  f"u=2^-24 (float32 compositing and 2x2 inverse bounds)")



def gradient_gamma(s: RenderInput, conv: dict) -> tuple[float, str]:
    L, kappa, _ = _scene_constants(s, conv)
    P = s.camera.width * s.camera.height
    gamma = MARGIN * (P + 2 * L + 20 + 6 * kappa) * U32
    return gamma, (f"L2 over entries of [3 (P + 2 L + 20 + 6 kappa) u sum_p |v_p dout_p| (+ 3 u / (1 - o) "
                   f"sum_p |...| for opacity_logits) + FD rounding] / |g_oracle|, P={P}, L={L}, kappa={kappa:.3g}")


def oracle_grad(name: str, s: RenderInput, conv: dict, group: str, v: np.ndarray, gamma: float):
    """The oracle's gradient of sum(v . outputs) for ``group`` [n] and the per-entry error bound [n]."""
    J = fd_jacobian(name, s, conv, group)
    terms = (J * v[None]).reshape(J.shape[0], -1)
    rounding = U64 * float(np.abs(v * oracle(name, s, conv)).sum()) / FD_H
    rel = np.full(J.shape[0], gamma)
    if group == "opacity_logits":  # sigmoid' = o (1 - o): 1 - o carries an absolute float32 error u
        o = 1.0 / (1.0 + np.exp(-s.opacity_logits))
        rel = rel + MARGIN * U32 / (1.0 - o)
    return terms.sum(1), rel * np.abs(terms).sum(1) + rounding


def conic_jacobian(name: str, s: RenderInput, conv: dict) -> np.ndarray:
    """d (A, B, C) / d (log_scales, quats) per Gaussian: [N, 3, 7], central differences (cached)."""
    conv = effective(name, s, conv)
    key = _key(name, conv, "conic")
    if key not in _CACHE:
        n = s.means.shape[0]
        out = np.zeros((n, 3, 7))
        for j, (group, col) in enumerate([("log_scales", c) for c in range(3)] + [("quats", c) for c in range(4)]):
            cols = []
            for sign in (1.0, -1.0):
                params = {k: np.array(x) for k, x in s.params().items()}
                params[group][:, col] += sign * FD_H
                cols.append(projection(s, conv, params).conics)
            out[:, :, j] = (cols[0] - cols[1]) / (2 * FD_H)
        _CACHE[key] = out
    return _CACHE[key]


