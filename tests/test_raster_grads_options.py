"""Gradients of two documented rasterizer features against float64 finite differences.

* ``antialiased=True`` (Mip-Splatting opacity compensation ``o *= sqrt(det Σ2D_raw /
  det Σ2D)``, docs/conventions.md): the compensation depends on the scales, the
  rotation and the mean through Σ2D, so every group's gradient changes.
* The EWA Jacobian clamp (graphdeco's ``1.3 tan(fov/2)`` limit, `reference.project`
  ``JACOBIAN_GUARD``): a Gaussian whose centre lies beyond the limit has its Jacobian
  evaluated at the clamped point, so ``d Σ2D / d mean`` loses the clamped coordinate's
  term; the hand-written backward must drop it too.

Both compare `splatbench.rasterize` with the ``reference`` backend (`reference.render`
in ``mode="matched"`` with the same options, differentiated by central differences)
on small scenes with every *discontinuous* threshold switched off (`SMOOTH`): the
clamp is continuous, and the compensation smooth, so the oracle is differentiable at
these inputs.

Tolerances: those of tests/test_raster_grads.py and for the same reason -- one
gradient entry sums ~H W pixel terms of ~20 float32 operations each, and random
cotangents amplify the relative error of the sum by ~sqrt(H W): 20 u sqrt(320) ~ 2e-5
< 1e-4 (relative L2); the float64 central differences (step 1e-6) are accurate to
~1e-10 and do not count. Forward: 1e-5 absolute, as there.
"""

from __future__ import annotations

import numpy as np
import torch

from reference.project import JACOBIAN_GUARD
from splatbench import Camera, Gaussians
from splatbench.backends.builtins.reference_backend import make_reference_backend
from splatbench.workloads import Workload, random_unit_quats
from tests.compare import assert_grads_agree
from tests.gradcheck import GROUPS, Cotangents, fast_vjp
from tests.scenes import smooth_scene
from tests.test_raster_grads import COSINE, REL_L2, SMOOTH

FORWARD_ATOL = 1e-5


def matched_fd(workload: Workload, v: Cotangents, **options) -> dict[str, np.ndarray]:
    """Every group's VJP by central differences of `reference.render(mode="matched", **options)`."""
    backend = make_reference_backend("matched", **options)
    g = workload.gaussians
    params = [torch.tensor(getattr(g, k), dtype=torch.float64, requires_grad=True) for k in GROUPS]
    v.loss(*backend(*params, workload.camera)).backward()
    return {k: p.grad.numpy() for k, p in zip(GROUPS, params)}


def _check(workload: Workload, seed: int, **options) -> tuple:
    c = workload.camera
    v = Cotangents.standard_normal(seed, c.height, c.width)
    backend = make_reference_backend("matched", **options)
    g = workload.gaussians
    ref = [t.detach().numpy() for t in backend(*(torch.tensor(getattr(g, k), dtype=torch.float64) for k in GROUPS),
                                                   c)]
    # depth = sum / alpha: only weighted where splats cover the pixel (as in test_raster_grads)
    v = Cotangents(v.rgb, v.alpha, v.depth * (ref[1] > 0.05))
    fast = fast_vjp(workload, v, **options)
    np.testing.assert_allclose(fast.rgb, ref[0], atol=FORWARD_ATOL)
    np.testing.assert_allclose(fast.alpha, ref[1], atol=FORWARD_ATOL)
    fd = matched_fd(workload, v, **options)
    for k in GROUPS:
        assert_grads_agree(f"{workload.name} {k}", fast.grads[k], fd[k], rel_l2=REL_L2, cosine=COSINE)
    return fast, fd


def test_antialiased_gradients_match_finite_differences():
    workload = smooth_scene(0)  # one scene: central differences cost ~15 s on 2 loaded cores
    options = {**SMOOTH, "antialiased": True}
    fast, _ = _check(workload, 300, **options)
    # the compensation is active: without it the image is not the same
    plain = fast_vjp(workload, Cotangents.standard_normal(300, workload.camera.height, workload.camera.width), **SMOOTH)
    assert np.abs(plain.rgb - fast.rgb).max() > 100 * FORWARD_ATOL


def clamp_scene() -> tuple[Workload, int]:
    """Three Gaussians inside a 20x16 view and one (the last) whose centre lies beyond the
    Jacobian clamp limit on the right, large enough that its footprint reaches the image."""
    rng = np.random.default_rng(7)
    W, H = 20, 16
    fx = fy = 1.2 * W
    cx, cy = W / 2, H / 2
    z = np.array([4.0, 4.5, 5.0, 3.6])  # distinct depths: a tie would make the sort order (and FD) jump
    u = np.array([6.0, 11.0, 14.0, W + 7.0])  # the last: 7 px right of the image
    v = np.array([6.0, 10.0, 7.0, 8.5])
    sigma_px = np.array([2.0, 2.5, 2.0, 4.0])
    cam_pts = np.stack([(u - cx) * z / fx, (v - cy) * z / fy, z], axis=1)
    n = len(z)
    log_scales = np.log(sigma_px * z / fx)[:, None] + 0.2 * rng.standard_normal((n, 3))
    sh = np.concatenate([rng.uniform(0.6, 1.2, (n, 1, 3)), 0.1 * rng.standard_normal((n, 15, 3))], 1)
    gaussians = Gaussians(cam_pts, log_scales, random_unit_quats(rng, n), rng.uniform(-1.0, 0.5, n), sh)
    return Workload("clamp", gaussians, Camera(W, H, fx, fy, cx, cy, np.eye(4))), n - 1


def test_jacobian_clamp_gradients_match_finite_differences():
    workload, k = clamp_scene()
    c, mean = workload.camera, workload.gaussians.means[k]  # world = camera axes here
    limit = (c.width - c.cx) / c.fx + JACOBIAN_GUARD * (c.width / 2) / c.fx
    assert mean[0] / mean[2] > 1.2 * limit  # well beyond the clamp, not at its kink
    fast, fd = _check(workload, 400, **SMOOTH)
    # the clamped Gaussian contributes: its gradient is not zero (so its terms were compared)
    assert np.abs(fd["means"][k]).max() > 1e-3 and np.abs(fast.grads["means"][k]).max() > 1e-3
