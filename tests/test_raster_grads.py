"""Gradients of the Dr.Jit rasterizer, by random-cotangent VJP on every output.

(a) The hand-written backward (a CustomOp walking back to front) against Dr.Jit's
    own AD through the compositing loop, on the parity scenes.
(b) Against float64 central differences of `reference.render(mode="exact")` on
    smooth scenes, rendered with every threshold switched off.
Each parameter group is reported as relative L2 error and cosine similarity.

Tolerances. float32 has unit roundoff u ~ 6e-8; one gradient entry is a sum over
the H W pixels of terms each carrying ~20 u of relative error from the forward
and backward arithmetic (and the transmittance recovered by division). Random
cotangents make the terms cancel, which amplifies the relative error of the sum
by about sqrt(H W) ~ 20-60 for our images: 20 u * 60 ~ 7e-5. Hence relative L2
<= 1e-4, and cosine >= 1 - 1e-8 (cosine ~ 1 - rel^2 / 2). The float64 central
differences (step 1e-6) are accurate to ~1e-10 and do not count.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from splatbench.backends import get_backend, reference_render
from splatbench.raster.hooks import Hooks
from tests.compare import assert_grads_agree
from tests.gradcheck import GROUPS, Cotangents, fast_vjp
from tests.scenes import parity_scene, smooth_scene

REL_L2 = 1e-4
COSINE = 1 - 1e-8
# Switches off every threshold of the matched rasterizer: no early stop, contributions
# down to 1e-9 kept, and the cutoff radius that alpha_min implies (6.4 sigma).
SMOOTH = {"alpha_min": 1e-9, "radius": "opacity", "transmittance_min": 0.0}


@pytest.mark.parametrize("seed", [0, 2, 4, 6, 9, 13])
def test_custom_backward_matches_loop_ad(seed, device):
    workload, background = parity_scene(seed)
    c = workload.camera
    v = Cotangents.standard_normal(seed, c.height, c.width)
    custom = fast_vjp(workload, v, background=background, device=device)
    loop = fast_vjp(workload, v, Hooks(loop_ad=True), background=background, device=device)
    np.testing.assert_array_equal(custom.rgb, loop.rgb)  # one forward implementation
    for k in GROUPS:
        assert_grads_agree(f"{workload.name} {k}", custom.grads[k], loop.grads[k], rel_l2=REL_L2, cosine=COSINE)


def reference_fd(workload, v: Cotangents) -> dict[str, np.ndarray]:
    """Every group's VJP by central differences of the exact reference (the reference-exact backend)."""
    g = workload.gaussians
    params = [torch.tensor(getattr(g, k), dtype=torch.float64, requires_grad=True) for k in GROUPS]
    v.loss(*get_backend("reference-exact")(*params, workload.camera)).backward()
    return {k: p.grad.numpy() for k, p in zip(GROUPS, params)}


@pytest.mark.parametrize("seed", range(3))
def test_gradients_match_finite_differences(seed):
    workload = smooth_scene(seed)
    g, c = workload.gaussians, workload.camera
    v = Cotangents.standard_normal(100 + seed, c.height, c.width)
    exact = reference_render(None, g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, c, mode="exact")
    # depth = sum / alpha: where alpha is tiny the fast path (which drops alpha < 1e-9)
    # and the exact function legitimately differ, so depth is only weighted where
    # splats actually cover the pixel.
    v = Cotangents(v.rgb, v.alpha, v.depth * (exact.alpha > 0.05))
    fast = fast_vjp(workload, v, **SMOOTH)
    np.testing.assert_allclose(fast.rgb, exact.rgb, atol=1e-5)  # the same smooth function
    fd = reference_fd(workload, v)
    for k in GROUPS:
        assert_grads_agree(f"{workload.name} {k}", fast.grads[k], fd[k], rel_l2=REL_L2, cosine=COSINE)


def test_frozen_groups_get_no_gradient():
    """A group without requires_grad is not differentiated (no gradient work)."""
    import torch

    import splatbench

    workload, _ = parity_scene(0)
    g = workload.gaussians
    means = torch.tensor(g.means, requires_grad=True)
    frozen = [torch.tensor(x) for x in (g.log_scales, g.quats, g.opacity_logits, g.sh)]
    rgb, _, _, info = splatbench.rasterize(means, *frozen, workload.camera)
    rgb.sum().backward()
    assert means.grad is not None and torch.isfinite(means.grad).all()
    assert all(t.grad is None for t in frozen)
    assert info.means2d_grad is not None and info.means2d_grad.shape == (len(g), 2)
