"""The splat rasterizer against Gaussians ray-traced by Mitsuba 3 (``volprim_rf_basic``).

Mitsuba 3.9 ships an ``ellipsoids`` shape (one primitive per Gaussian: centre, scale,
rotation, plus per-primitive attributes) and the ``volprim_rf_basic`` integrator,
which ray-traces them in the radiance-field style of "3D Gaussian Ray Tracing". Both
renderers composite ``alpha_k = min(o_k G_k, alpha_max)`` front to back with the same
degree-3 SH basis; what differs is exactly the splatting approximation
(docs/validation.md derives it):

* **Kernel.** Mitsuba evaluates the 3D Gaussian at its maximum along the pixel's ray,
  ``G = exp(-m_ray^2 / 2)`` with ``m_ray`` the ray's smallest Mahalanobis distance to
  the centre. The rasterizer evaluates the EWA projection: the 2D Gaussian of
  ``J Sigma J^T`` with the Jacobian ``J`` of the perspective map linearised at the mean.
  For an isotropic Gaussian ``m_ray^2 = m_affine^2 * (1 + |m|^2) / (1 + |a|^2)``, with
  ``a`` and ``m`` the normalised image coordinates of the ray and of the mean (exact;
  `isotropic_prediction` uses it).
* **Truncation.** Mitsuba's rays see a primitive only inside its ``extent = 3`` sigma
  ellipsoid (``m_ray <= 3``); the rasterizer cuts at ``m_affine <= 3`` (``radius="3sigma"``).
* **Order.** Mitsuba composites in the order the ray *enters* the 3-sigma shells,
  per pixel; the rasterizer sorts once per Gaussian by the camera depth of its centre.
* **Colour.** Mitsuba evaluates SH at the pixel's ray direction; the rasterizer at the
  direction from the camera to the Gaussian's centre.

Everything else is matched (`MATCHED_OPTIONS`): no ``eps2d`` dilation, ``alpha_max =
0.9999`` (Mitsuba's clamp), ``alpha_min = 1e-7`` (Mitsuba has no skip), no early stop
on our side (Mitsuba stops once the throughput is <= 0.01: the scenes keep it above
that), SH coefficients in linear space (``srgb_primitives = False``), black background,
one ray through each pixel centre (``stratified`` sampler without jitter, box filter),
so the ray tracer is deterministic and one sample per pixel is exact.

One defect of the shipped integrator is worked around, not hidden: in float32 the
first intersection with a small, distant ellipsoid can land up to ~5e-4 before its
shell, and the integrator's fixed 1e-4 nudge then re-enters the *same* primitive,
compositing it twice. `render_traced` uses ``volprim_rf_dedup``, a subclass that
reuses the shipped kernel (``eval_transmission``, ``eval_sh_emission``) and differs only
in skipping an immediate re-hit of the primitive just composited (a ray enters a
convex shell once); the shipped integrator's numbers are reported beside it.

Scale: Mitsuba's ray-ellipsoid test (Embree user geometry, LLVM and scalar variants
alike) misjudges hit/miss for ellipsoids that are small in absolute world units
(sigma ~0.01: 2 % of rays wrong at distance 100 sigma, 16 % at 300 sigma;
`intersection_probe` measures it). Both renderers are invariant to scaling the scene
and camera together, so the sweep scenes sit 400 units from the camera (sigma >= ~1.5),
where the probe finds no wrong decision up to 300 sigma.

Layout (one job per module): `renderers` (both renders, `compare`; the ``mi.Scene`` itself is
`splatbench.backends.builtins.mitsuba_scene`, shared with the ``mitsuba`` backend),
`prediction` (the isotropic closed form), `cases` (the sweeps), `probe` (Mitsuba's
intersection test), `checks` (pass/fail statements), `report` (CSV, markdown, plot).
Mitsuba itself comes from `splatbench.mitsuba_loader` (one loader, one variant rule).

Example::

    import splatbench
    from splatbench.validate import mitsuba as vm
    g, cam = vm.size_cases(64)[0].gaussians, vm.size_cases(64)[0].camera
    c = vm.compare(g, cam)
    c.metrics.psnr, c.metrics.max_error, c.metrics.rehit_pixels
"""

from splatbench.mitsuba_loader import MITSUBA_VARIANT
from splatbench.validate.mitsuba.cases import (SWEEPS, Case, SweepRow, angle_cases, anisotropy_cases,
                                               overlap_cases, run_case, run_sweeps, sh_cases, size_cases)
from splatbench.validate.mitsuba.checks import (MIN_TREND_SIGMA_PX, PREDICTION_ATOL, Check, check_tight,
                                                check_trends)
from splatbench.validate.mitsuba.prediction import IsotropicPrediction, isotropic_prediction
from splatbench.validate.mitsuba.probe import ProbeRow, intersection_probe
from splatbench.validate.mitsuba.renderers import (DEFAULT_OPTIONS, MATCHED_OPTIONS, OPTION_SETS, SWEEP_OPACITY,
                                                   Comparison, ComparisonMetrics, compare, render_splat,
                                                   render_traced)
from splatbench.validate.mitsuba.report import (DEFAULT_OUT, ReportPaths, probe_markdown, sweep_markdown,
                                                write_report)

__all__ = ["MITSUBA_VARIANT", "SWEEPS", "Case", "SweepRow", "angle_cases", "anisotropy_cases", "overlap_cases",
           "run_case", "run_sweeps", "sh_cases", "size_cases", "MIN_TREND_SIGMA_PX", "PREDICTION_ATOL", "Check",
           "check_tight", "check_trends", "IsotropicPrediction", "isotropic_prediction", "ProbeRow",
           "intersection_probe", "DEFAULT_OUT", "ReportPaths", "sweep_markdown", "probe_markdown", "write_report",
           "DEFAULT_OPTIONS", "MATCHED_OPTIONS", "OPTION_SETS", "SWEEP_OPACITY", "Comparison", "ComparisonMetrics",
           "compare", "render_splat", "render_traced"]
