"""The verification core (`splatbench.verification`): one draw of cotangents, one checked way to take a
backend's VJP, shared by compare, conform, regress and stress."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from splatbench.backends import Backend, BackendInfo
from splatbench.verification.calls import Fault, param_tensors, vjp
from splatbench.verification.cotangents import Cotangents

PACKAGE = Path(__file__).resolve().parent.parent / "splatbench"


def test_cotangents_are_drawn_in_one_place():
    """Every verification application takes its cotangents from `Cotangents`: no other module of the
    package defines a cotangent draw."""
    found = [f"{p.relative_to(PACKAGE)}: {m.group(0)}" for p in PACKAGE.rglob("*.py")
             for m in re.finditer(r"^[ \t]*(class \w*Cotangent\w*|def \w*cotangent\w*)", p.read_text(), re.M)
             if "raster" not in p.parts]  # the rasterizer's backward pass moves cotangents, it draws none
    assert found == ["verification/cotangents.py: class Cotangents"], found


def test_the_draw_is_stress_s_and_compare_s():
    """Seeded rgb, alpha, depth from one generator: exactly what stress drew per output before it used
    `Cotangents` (``default_rng([seed, 1])``, outputs in order), so its cases keep their numbers."""
    rng = np.random.default_rng([7, 1])
    old = [rng.standard_normal(s) for s in ((5, 4, 3), (5, 4), (5, 4))]
    v = Cotangents.standard_normal([7, 1], 5, 4)
    for a, b in zip(old, (v.rgb, v.alpha, v.depth)):
        assert np.array_equal(a, b)
    masked = Cotangents.random(7, 5, 4, ("rgb", "depth"), alpha=np.full((5, 4), 0.04))
    assert not masked.alpha.any() and not masked.depth.any() and masked.rgb.any()  # undeclared; alpha <= 0.05


def _scene():
    from splatbench.regress.snapshot_scenes import scene_set

    return next(s for s in scene_set("small") if s.name == "probe-gradients")


def test_a_backend_without_an_autograd_graph_is_one_line_everywhere():
    """Before the core, regress summed an empty loss and reported "backward raised AttributeError: 'int'
    object has no attribute 'backward'"; conform said what was wrong. Both now say it one way."""
    from splatbench.regress.measure import render

    def detached(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        H, W = camera.height, camera.width
        return torch.full((H, W, 3), 0.5), torch.full((H, W), 0.5), torch.ones(H, W)

    backend = Backend(detached, BackendInfo("detached", gradients=True))
    s = _scene()
    with pytest.raises(Fault, match=r"^outputs carry no autograd graph \(declare gradients=False"):
        render(backend, s)
    with pytest.raises(Fault, match="^outputs carry no autograd graph"):
        vjp(backend, param_tensors(s, "cpu"), s.camera, Cotangents.random(0, s.camera.height, s.camera.width))


def test_vjp_gradients_are_the_cotangent_weighted_sum():
    """vjp of a backend that returns its colour DC term broadcast: the gradient is sum(v) per entry."""
    s = _scene()

    def flat(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        H, W = camera.height, camera.width
        c = sh[0, 0]
        return c.expand(H, W, 3), torch.zeros(H, W), torch.zeros(H, W)

    v = Cotangents.random(3, s.camera.height, s.camera.width)
    g = vjp(Backend(flat, BackendInfo("flat")), param_tensors(s, "cpu"), s.camera, v)
    want = v.rgb.astype(np.float32).astype(np.float64).sum((0, 1))  # v reaches a float32 backend as float32
    np.testing.assert_allclose(g["sh"][0, 0], want, rtol=1e-5)
    assert not g["sh"][1:].any() and not g["means"].any()
