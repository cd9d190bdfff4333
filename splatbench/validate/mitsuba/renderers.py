"""Both renderers on the same Gaussians: Mitsuba's ray-traced ``ellipsoids`` and the rasterizer.

`splatbench.backends.builtins.mitsuba_scene` builds the ``mi.Scene`` (the ``mitsuba``
backend's too), `render_traced` and `render_splat` render it,
`compare` puts the two side by side (`Comparison`). Why they differ, and by how much,
is in the package docstring (`splatbench.validate.mitsuba`) and docs/validation.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from splatbench.backends.builtins.mitsuba_scene import mitsuba_scene, mitsuba_volprim
from splatbench.cameras import Camera
from splatbench.gaussians import Gaussians
from splatbench.metrics.image import psnr
from splatbench.raster import render
from splatbench.raster.options import RasterOptions

#: Rasterizer options that match ``volprim_rf_basic`` wherever the two definitions allow.
MATCHED_OPTIONS = {"eps2d": 0.0, "alpha_min": 1e-7, "alpha_max": 0.9999, "transmittance_min": 0.0,
                   "radius": "3sigma"}
#: The rasterizer's defaults (graphdeco-inria 3DGS), for the "3dgs" rows of the size sweep.
DEFAULT_OPTIONS: dict = {}
OPTION_SETS = {"matched": MATCHED_OPTIONS, "3dgs": DEFAULT_OPTIONS}
#: Opacity of every Gaussian in the sweeps (below Mitsuba's 0.9999 clamp).
SWEEP_OPACITY = 0.8


def render_traced(gaussians: Gaussians, camera: Camera, *, shipped: bool = False) -> np.ndarray:
    """[H, W, 3] float32: Mitsuba's ray-traced Gaussians, one ray per pixel centre, no transfer curve.

    ``shipped=True`` uses ``volprim_rf_basic`` as shipped (which may composite a
    small Gaussian twice; see the module docstring); the default its dedup subclass.
    """
    mi = mitsuba_volprim()
    scene = mitsuba_scene(gaussians, camera, integrator="volprim_rf_basic" if shipped else "volprim_rf_dedup")
    image = np.asarray(mi.render(scene, spp=1), dtype=np.float32)
    return np.ascontiguousarray(image[..., :3])


def render_splat(gaussians: Gaussians, camera: Camera, options: dict | None = None) -> np.ndarray:
    """[H, W, 3] float32 from `splatbench.render` (black background); ``options`` default `MATCHED_OPTIONS`."""
    opts = MATCHED_OPTIONS if options is None else options
    options = RasterOptions.from_kwargs(device="cpu", **opts)
    return render(gaussians, camera, background=(0.0, 0.0, 0.0), options=options).rgb



@dataclass(frozen=True)
class ComparisonMetrics:
    """How far apart the rasterizer and Mitsuba are on one scene (a `Comparison`'s numbers,
    and a `SweepRow`'s columns after the case's).

    psnr, max_error, mean_error: splat vs traced (``volprim_rf_dedup``); PSNR with peak 1.
    psnr_shipped, max_error_shipped: splat vs ``volprim_rf_basic`` as shipped.
    rehit_pixels: pixels where the shipped integrator composited a primitive twice
    (where the two Mitsuba images differ by more than 1e-6).
    """

    psnr: float
    max_error: float
    mean_error: float
    psnr_shipped: float
    max_error_shipped: float
    rehit_pixels: int


@dataclass(frozen=True)
class Comparison:
    """The same Gaussians rendered by the rasterizer and by Mitsuba, and how far apart they are.

    splat, traced, traced_shipped: [H, W, 3] float32 (linear, black background).
    metrics: `ComparisonMetrics` of splat against the two traced images.
    """

    splat: np.ndarray
    traced: np.ndarray
    traced_shipped: np.ndarray
    metrics: ComparisonMetrics


def compare(gaussians: Gaussians, camera: Camera, options: dict | None = None) -> Comparison:
    """Render ``gaussians`` from ``camera`` with both renderers and compare (see `Comparison`)."""
    splat = render_splat(gaussians, camera, options)
    traced = render_traced(gaussians, camera)
    shipped = render_traced(gaussians, camera, shipped=True)
    err = np.abs(splat.astype(np.float64) - traced)
    rehits = int(np.count_nonzero(np.abs(shipped.astype(np.float64) - traced).max(axis=-1) > 1e-6))
    # linear radiance, unclipped, in float64 (the one PSNR of splatbench, peak 1)
    splat64 = splat.astype(np.float64)
    metrics = ComparisonMetrics(psnr(splat64, traced.astype(np.float64), clamp=False), float(err.max()),
                                float(err.mean()), psnr(splat64, shipped.astype(np.float64), clamp=False),
                                float(np.abs(splat64 - shipped).max()), rehits)
    return Comparison(splat, traced, shipped, metrics)

