"""A frozen parameter group costs no work in the compositing backward (issue #13, from #12).

The compositing op records which per-pair gradient terms its backward pass accumulates
(`CompositeState.grad_keys`, from `compositing.needed_keys`); terms left out are neither
computed per pixel nor scattered nor reduced. The gradients of the groups that stay
trainable must be **bit-for-bit** those of a backward pass with every group on: the walk
computes each remaining term by the same expressions in the same order, so any difference
is a bug, not rounding (hence exact equality, no tolerance).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

import splatbench
from splatbench.raster.compositing import GRAD_KEYS
from splatbench.raster.options import RasterOptions
from tests.gradcheck import GROUPS, Cotangents
from tests.scenes import parity_scene

ALL = GRAD_KEYS[:-2]  # every term but AbsGS's
GEOMETRY = ("mx", "my", "ca", "cb", "cc")
# trainable groups -> terms accumulated (antialiasing off: the opacity depends on its logit only)
CASES = [
    (("sh",), ("r", "g", "b")),
    (("opacity_logits",), ("o",)),
    (("opacity_logits", "sh"), ("o", "r", "g", "b")),
    (("log_scales", "quats"), ("ca", "cb", "cc")),
    # the means reach the screen mean, the conic (through the Jacobian), the depth and, with SH
    # degree >= 1, the colour (through the view direction): at most the opacity term is saved
    (("means",), (*GEOMETRY, "r", "g", "b", "z")),
    (GROUPS, ALL),
]


def vjp(workload, v: Cotangents, trainable, antialiased: bool = False, **kwargs):
    """``kwargs``: `splatbench.rasterize`'s (``background``, ``absgrad``)."""
    g = workload.gaussians
    params = [torch.tensor(getattr(g, k), requires_grad=k in trainable) for k in GROUPS]
    options = RasterOptions(device="cpu", antialiased=antialiased)
    rgb, alpha, depth, info = splatbench.rasterize(*params, workload.camera, options=options, **kwargs)
    v.loss(rgb, alpha, depth).backward()
    grads = {k: None if p.grad is None else p.grad.numpy().copy() for k, p in zip(GROUPS, params)}
    return grads, info


@pytest.mark.parametrize("seed", [2, 4, 7])  # SH degrees 2, 0, 3
def test_frozen_groups_skip_their_terms_and_keep_the_rest_bit_identical(seed):
    workload, background = parity_scene(seed)
    v = Cotangents.standard_normal(seed, workload.camera.height, workload.camera.width)
    full, _ = vjp(workload, v, GROUPS, background=background)
    view_dependent = workload.gaussians.sh.shape[1] > 1
    for trainable, keys in CASES:
        if trainable == ("means",) and not view_dependent:  # degree 0: the colour ignores the view
            keys = tuple(k for k in keys if k not in ("r", "g", "b"))
        grads, info = vjp(workload, v, trainable, background=background)
        assert info._frame.state.grad_keys == keys, trainable
        for k in GROUPS:
            if k in trainable:
                np.testing.assert_array_equal(grads[k], full[k], err_msg=f"{trainable}: {k}")
            else:
                assert grads[k] is None
        assert (info.means2d_grad is None) == ("mx" not in keys)


def test_antialiasing_ties_the_opacity_to_the_geometry():
    workload, _ = parity_scene(4)
    v = Cotangents.standard_normal(0, workload.camera.height, workload.camera.width)
    _, info = vjp(workload, v, ("log_scales",), antialiased=True)
    assert info._frame.state.grad_keys == ("ca", "cb", "cc", "o")


def test_absgrad_keeps_the_screen_mean_terms_with_frozen_means():
    workload, _ = parity_scene(4)
    v = Cotangents.standard_normal(0, workload.camera.height, workload.camera.width)
    grads, info = vjp(workload, v, ("sh",), absgrad=True)
    full, full_info = vjp(workload, v, GROUPS, absgrad=True)
    assert info._frame.state.grad_keys == ("mx", "my", "r", "g", "b", "ax", "ay")
    np.testing.assert_array_equal(grads["sh"], full["sh"])
    np.testing.assert_array_equal(info.means2d_absgrad.numpy(), full_info.means2d_absgrad.numpy())
    np.testing.assert_array_equal(info.means2d_grad.numpy(), full_info.means2d_grad.numpy())
