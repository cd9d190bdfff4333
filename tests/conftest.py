"""Shared fixtures: the rasterizer's Dr.Jit backends, skipped where unavailable
(Mitsuba's `variants_all_ad_rgb` idea)."""

from __future__ import annotations

import pytest

import splatbench  # noqa: F401 - configures libLLVM before drjit loads
from splatbench.raster.device import cuda_available


@pytest.fixture(params=["cpu", "cuda"], ids=["drjit-llvm", "drjit-cuda"])
def device(request) -> str:
    """A rasterizer device: "cpu" (LLVM) always, "cuda" where a GPU is present."""
    if request.param == "cuda" and not cuda_available():
        pytest.skip("no CUDA device")
    return request.param
