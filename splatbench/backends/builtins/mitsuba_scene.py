"""Gaussians as a Mitsuba scene: one ``ellipsoids`` shape ray-traced by ``volprim_rf_basic``
or its dedup subclass (``volprim_rf_dedup``, `_volprim_dedup`).

Used by the ``mitsuba`` backend (`mitsuba_backend`) and by the validation against
Mitsuba's ray tracer (`splatbench.validate.mitsuba`, docs/validation.md).
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.gaussians import Gaussians
from splatbench.mitsuba_loader import mitsuba

#: The extent of Mitsuba's ellipsoid shells in sigma; the rasterizer's ``radius="3sigma"``.
ELLIPSOID_EXTENT = 3.0


def mitsuba_volprim() -> ModuleType:
    """`splatbench.mitsuba_loader.mitsuba` (variant ``llvm_ad_rgb``) with ``volprim_rf_dedup`` registered."""
    mi = mitsuba()
    _register_dedup(mi)
    return mi


_REGISTERED: set[str] = set()


def _register_dedup(mi: ModuleType) -> None:
    """Register ``volprim_rf_dedup`` (`_volprim_dedup`) for the current variant, once."""
    if mi.variant() in _REGISTERED:
        return
    from splatbench.backends.builtins._volprim_dedup import DedupVolprim  # late: needs a JIT variant set first

    mi.register_integrator("volprim_rf_dedup", lambda props: DedupVolprim(props))
    _REGISTERED.add(mi.variant())


def _quats_xyzw(g: Gaussians) -> np.ndarray:
    """[N, 4] unit quaternions in Dr.Jit's order (x, y, z, w); zero quaternions become identity."""
    q = g.rotations.astype(np.float32)
    zero = ~np.any(q != 0, axis=1)
    q[zero] = (1.0, 0.0, 0.0, 0.0)
    return np.ascontiguousarray(np.concatenate([q[:, 1:], q[:, :1]], axis=1))


def mitsuba_scene(gaussians: Gaussians, camera: Camera, *, integrator: str = "volprim_rf_dedup"):
    """An ``mi.Scene``: one ``ellipsoids`` shape holding ``gaussians``, seen by ``camera``.

    ``ellipsoids.data`` [N, 10] = centre, scale (the standard deviations), rotation as
    (x, y, z, w); attributes ``opacities`` [N, 1] (after the sigmoid) and ``sh_coeffs``
    [N, 3K] (basis-major, RGB-minor: ``sh.reshape(N, -1)``). ``integrator``:
    ``"volprim_rf_dedup"`` or the shipped ``"volprim_rf_basic"``; either with
    ``max_depth = -1`` (no limit on primitives per ray) and ``srgb_primitives = False``.
    The sensor shoots one ray through each pixel centre.
    """
    if integrator not in ("volprim_rf_dedup", "volprim_rf_basic"):
        raise InputError(f"integrator: expected 'volprim_rf_dedup' or 'volprim_rf_basic', got {integrator!r}")
    if len(gaussians) == 0:
        raise InputError("gaussians: the ellipsoids shape needs at least one Gaussian, got N=0")
    mi = mitsuba_volprim()
    n = len(gaussians)
    data = np.concatenate([gaussians.means, gaussians.scales, _quats_xyzw(gaussians)], axis=1).astype(np.float32)
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": -1, "srgb_primitives": False},
        "sensor": {**camera.to_mitsuba(), "sampler": {"type": "stratified", "sample_count": 1, "jitter": False}},
        "gaussians": {
            "type": "ellipsoids",
            "extent": ELLIPSOID_EXTENT,
            "data": mi.TensorXf(np.ascontiguousarray(data)),
            "opacities": mi.TensorXf(np.ascontiguousarray(gaussians.opacities.reshape(n, 1), dtype=np.float32)),
            "sh_coeffs": mi.TensorXf(np.ascontiguousarray(gaussians.sh.reshape(n, -1), dtype=np.float32)),
        },
    })


__all__ = ["ELLIPSOID_EXTENT", "mitsuba_volprim", "mitsuba_scene"]
