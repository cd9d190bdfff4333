"""Rendering a regression scene, and the tolerances of a check (derived, never observed).

Quantities per scene: ``rgb`` [H, W, 3], ``alpha`` [H, W], ``depth`` [H, W] (the backend's
declared outputs) and ``grad_<group>`` (the gradient of sum(v . outputs) for seeded standard
normal cotangents v (`splatbench.verification.cotangents`), v_depth kept where the snapshot's
alpha > 0.05, as compare does).

Tolerances of "the same quantity, now against the snapshot". Both are float32 computations of
the same maths, each within the float32 bound of the float64 oracle outside the oracle's band,
so they differ by at most twice that bound (triangle inequality):

* outputs, per pixel (rgb: the largest channel; depth as depth * alpha / z_max, as compare):
  2 (FORWARD_ATOL + tie slack) at every pixel outside the boundary band; band pixels, where
  float32 may add or drop a whole contribution, are counted and not judged;
* gradients, per group: the relative L2 difference outside the gradient band at most
  2 `gradient_bound` (20 u sqrt(P) + sqrt(sum_p w_p^2 / P)); inside it at most 2 `BAND_BUDGET`
  (a band Gaussian may differ by up to its whole gradient from the oracle, each way).

The band (`reference.band`) is the oracle's, under the conventions the backend declared when
the snapshot was taken, stored with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from splatbench.backends.base import GROUPS, OUTPUTS, Backend
from splatbench.regress.snapshot_scenes import Scene
from splatbench.verification.bounds import BAND_BUDGET, FORWARD_ATOL, gradient_bound
from splatbench.verification.calls import finite_gradients, forward, param_tensors, vjp
from splatbench.verification.cotangents import Cotangents
from splatbench.verification.judging import entry_band, relative

GRAD_PREFIX = "grad_"


def quantities(backend: Backend) -> tuple[str, ...]:
    """The quantities a snapshot of ``backend`` holds: its declared outputs, then its gradients."""
    outs = tuple(o for o in OUTPUTS if o in backend.info.outputs)
    grads = tuple(GRAD_PREFIX + g for g in GROUPS) if backend.info.gradients else ()
    return outs + grads


def render(backend: Backend, scene: Scene, device: str = "cpu", alpha_for_cotangents: np.ndarray | None = None
           ) -> dict[str, np.ndarray]:
    """Every quantity of ``backend`` on ``scene`` (float64 numpy), through the verification core's
    `forward` and `vjp` with the scene's seeded `Cotangents` (v_depth kept where alpha > 0.05).
    ``alpha_for_cotangents``: the alpha that masks v_depth (the snapshot's at check time; None: the
    backend's own, at snapshot time). A backend that raises or returns NaN raises
    `splatbench.verification.calls.Fault` (one line, with the last frame of its traceback)."""
    want = quantities(backend)
    outs = tuple(o for o in OUTPUTS if o in want)
    out = forward(backend, scene, device, outs)  # [H, W, 5]
    result = {name: x for name, x in (("rgb", out[..., :3]), ("alpha", out[..., 3]), ("depth", out[..., 4]))
              if name in outs}
    if not any(q.startswith(GRAD_PREFIX) for q in want):
        return result
    H, W = scene.camera.height, scene.camera.width
    alpha = result.get("alpha") if alpha_for_cotangents is None else alpha_for_cotangents
    v = Cotangents.random(scene.seed, H, W, outs, alpha=alpha)
    grads = finite_gradients(vjp(backend, param_tensors(scene, device), scene.camera, v, sh_degree=scene.sh_degree,
                                 background=scene.background))
    return {**result, **{GRAD_PREFIX + k: g for k, g in grads.items()}}


@dataclass(frozen=True)
class Band:
    """The oracle's bands of one scene (`reference.band`): band [H, W] bool, tie_slack [H, W],
    grad_band [N] bool, grad_weight [H, W]."""

    band: np.ndarray
    tie_slack: np.ndarray
    grad_band: np.ndarray
    grad_weight: np.ndarray


def oracle(backend_info, scene: Scene, band: bool = True):
    """The float64 oracle's render of ``scene`` under ``backend_info``'s declared conventions (with its
    bands unless the backend declares ``exact``)."""
    from splatbench.backends.builtins.reference_backend import reference_render

    mode = "exact" if backend_info.exact else "matched"
    return reference_render(backend_info, *scene.params().values(), scene.camera, mode=mode,
                            sh_degree=scene.sh_degree, background=scene.background, band=band and mode == "matched")


def bands(backend_info, scene: Scene) -> Band:
    out = oracle(backend_info, scene)
    H, W = scene.camera.height, scene.camera.width
    if out.band is None:  # the exact oracle takes no decisions: no band
        return Band(np.zeros((H, W), bool), np.zeros((H, W)), np.zeros(scene.n, bool), np.zeros((H, W)))
    return Band(out.band, out.tie_slack, out.grad_band, out.grad_weight)


def oracle_gradients(backend_info, scene: Scene, alpha: np.ndarray) -> dict[str, np.ndarray] | None:
    """The float64 gradients of the same loss (torch64 matched to the declared conventions), or None
    where torch64 cannot follow them (an exact or antialiased backend)."""
    from splatbench.backends.builtins.torch_backend import make_torch_matching

    try:
        oracle64 = make_torch_matching(backend_info)
    except Exception:  # noqa: BLE001 - conventions torch64 cannot follow: no gradient oracle
        return None
    import dataclasses

    wide = dataclasses.replace(oracle64.info, outputs=backend_info.outputs, gradients=True)
    return render(Backend(oracle64.fn, wide), scene, "cpu", alpha_for_cotangents=alpha)


def per_pixel(name: str, x: np.ndarray, alpha: np.ndarray | None, z_max: float) -> np.ndarray:
    """The per-pixel value a difference is taken of: rgb as is ([H, W, 3]), depth as depth * alpha / z_max."""
    if name == "depth":
        return x * (1.0 if alpha is None else alpha) / z_max
    return x


def output_difference(name: str, got: np.ndarray, ref: np.ndarray, got_alpha, ref_alpha, z_max: float,
                      band: Band) -> tuple[float, str, float, int]:
    """(largest difference outside the band, where, its tolerance (at that pixel), band pixels over it)."""
    d = np.abs(per_pixel(name, got, got_alpha, z_max) - per_pixel(name, ref, ref_alpha, z_max))
    d = d.max(-1) if d.ndim == 3 else d
    bound = 2 * (FORWARD_ATOL + band.tie_slack)
    outside = np.where(band.band, 0.0, d)
    i, j = np.unravel_index(int(np.argmax(outside / bound)), outside.shape)
    return float(outside[i, j]), f"pixel (row {i}, col {j})", float(bound[i, j]), int((band.band & (d > bound)).sum())


def output_excess(name, got, ref, got_alpha, ref_alpha, z_max, band: Band) -> float:
    """How far one image is from another outside the band: the largest per-pixel difference over its bound
    (used for "closer to the oracle"): the same measure as `output_difference`, as a ratio."""
    d = np.abs(per_pixel(name, got, got_alpha, z_max) - per_pixel(name, ref, ref_alpha, z_max))
    d = d.max(-1) if d.ndim == 3 else d
    return float(np.where(band.band, 0.0, d / (FORWARD_ATOL + band.tie_slack)).max())


def gradient_scale(q: str, ref: dict[str, np.ndarray], outside: np.ndarray | None = None) -> float:
    """The floor of a gradient group's relative error denominator: for quats, the norm of the log_scales
    gradient. An isotropic Gaussian's rotation gradient is exactly 0 by symmetry, and float32 leaves
    rounding noise of the covariance's scale there (which log_scales' gradient carries); measured against
    its own vanishing norm that noise would read as a 100 % change. 0 for the other groups."""
    if q != GRAD_PREFIX + "quats" or GRAD_PREFIX + "log_scales" not in ref:
        return 0.0
    g = ref[GRAD_PREFIX + "log_scales"].reshape(-1)
    if outside is not None:
        g = g[np.repeat(outside.reshape(-1)[::4], 3)]
    return float(np.linalg.norm(g))


def gradient_difference(q: str, got: np.ndarray, ref: np.ndarray, band: Band, ref_all: dict[str, np.ndarray]
                        ) -> tuple[float, float, str]:
    """(relative L2 difference of quantity ``q`` outside the gradient band, inside it, where the largest
    entry difference outside it is: Gaussian and component); ``ref_all``: every reference quantity, for
    the denominator's floor (`gradient_scale`)."""
    a, b = got.reshape(-1), ref.reshape(-1)
    inside = entry_band(band.grad_band, a.size)
    rest = relative(a[~inside], b[~inside], gradient_scale(q, ref_all, ~inside))
    in_band = relative(a[inside], b[inside], gradient_scale(q, ref_all, inside)) if inside.any() else 0.0
    diff = np.where(inside, 0.0, np.abs(a - b))
    k = int(np.argmax(diff))
    per = a.size // max(1, band.grad_band.size)
    return rest, in_band, f"Gaussian {k // per}, component {k % per}"


def gradient_tolerance(scene: Scene, band: Band) -> tuple[float, float]:
    """(outside the gradient band, inside it): 2 `gradient_bound`, 2 `BAND_BUDGET` (module doc)."""
    P = scene.camera.width * scene.camera.height
    return 2 * gradient_bound(P, 0, band.grad_weight), 2 * BAND_BUDGET
