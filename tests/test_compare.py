"""The comparison helper itself: it must fail on a real mismatch, tolerate only the
allowed boundary band, and leave the three PNGs where its message says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import tests.compare as compare


def test_mismatch_writes_pngs_and_names_the_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(compare, "ARTIFACTS", tmp_path)
    ref = np.zeros((8, 6, 3))
    fast = ref.copy()
    fast[2, 3, 1] = 0.5
    with pytest.raises(AssertionError) as info:
        compare.assert_images_close("demo", fast, ref, atol=1e-5)
    message = str(info.value)
    assert "at (2, 3, 1)" in message and "1 pixels exceed" in message
    folder = Path(re.search(r"images written to (\S+)", message).group(1))
    assert {p.name for p in folder.iterdir()} == {"fast.png", "reference.png", "difference.png"}


def test_only_the_boundary_band_may_exceed_the_bound():
    ref = np.zeros((8, 6))
    fast = ref.copy()
    fast[0, 0] = fast[1, 1] = 1.0
    band = np.zeros((8, 6), dtype=bool)
    band[0, 0] = band[1, 1] = True
    compare.assert_images_close("band", fast, ref, atol=1e-5, band=band)
    band[1, 1] = False  # one pixel over the bound outside the band
    with pytest.raises(AssertionError, match="1 pixels exceed atol=1.00e-05 outside the boundary band"):
        compare.assert_images_close("band", fast, ref, atol=1e-5, band=band)
    slack = np.zeros((8, 6))
    slack[1, 1] = 1.0  # ... unless a depth tie there widens its bound by the difference
    compare.assert_images_close("band", fast, ref, atol=1e-5, band=band, slack=slack)


def test_grad_agreement_detects_scale_and_direction():
    b = np.array([1.0, -2.0, 3.0])
    assert compare.grad_agreement(b, b).rel_l2 == 0.0
    assert compare.grad_agreement(1.1 * b, b).rel_l2 == pytest.approx(0.1)
    assert compare.grad_agreement(-b, b).cosine == pytest.approx(-1.0)


def test_the_gradient_oracle_runs_on_float64_cpu_copies():
    """compare's float64 oracle takes CPU float64 copies of the parameters whatever device the
    compared backends use (on CUDA, ``torch64`` refused CUDA tensors and compare fell back to
    finite differences): the copies hold the same values, and ``torch64``'s gradients on them
    equal its gradients on the float32 originals to float32 rounding."""
    import torch

    from splatbench.backends.registry import get_backend
    from splatbench.compare.measure import GradOracle, OracleImages, torch_inputs
    from splatbench.verification.calls import vjp
    from splatbench.verification.cotangents import Cotangents
    from splatbench.workloads import synthetic

    workload = synthetic(200, 32, 32, 0)
    params = torch_inputs(workload, "cpu")
    images = OracleImages(workload, workload.camera)
    oracle = GradOracle("torch64", images, params, seed=0, entries=8)
    assert all(p.device.type == "cpu" and p.dtype == torch.float64 for p in oracle.params)
    assert all(torch.equal(a.double(), b) for a, b in zip(params, oracle.params))
    backend = get_backend("torch64")
    v = Cotangents.random(0, 32, 32, ("rgb", "alpha", "depth"))
    on_copies = vjp(backend, oracle.params, workload.camera, v)
    on_originals = vjp(backend, params, workload.camera, v)
    for name in on_copies:
        np.testing.assert_allclose(on_copies[name], on_originals[name], rtol=1e-5, atol=1e-7)


def test_parameter_device_follows_the_rasterizer_and_torch():
    """Training keeps its tensors where the rasterizer runs when torch can hold them there."""
    import torch

    from splatbench.raster.torch_bridge import parameter_device

    assert parameter_device("cpu") == torch.device("cpu")
    expected = "cuda" if (torch.cuda.is_available() and __import__("splatbench.raster.device", fromlist=["x"])
                          .cuda_available()) else "cpu"
    assert parameter_device("auto").type == expected
