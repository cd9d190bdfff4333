"""The numerical conventions of docs/conventions.md, defined once for every module
outside ``reference/``.

The oracle (``reference/``) and the independent ``torch`` backend keep their own
copies on purpose (neither may share code with the rasterizer);
``tests/test_conventions.py`` pins those copies equal to these.
"""

from __future__ import annotations

#: ``scales = exp(clip(log_scales, -LOG_SCALE_CLIP, LOG_SCALE_CLIP))``: exp(20)^2 * J^2
#: stays finite in float32 for any sane camera.
LOG_SCALE_CLIP = 20.0
#: A Gaussian whose 2D standard deviation exceeds this many image sizes is culled.
BIG_FACTOR = 1e4
#: graphdeco's guard band for the projection's Jacobian (a fraction of the half field of
#: view beyond the image, per side: its 1.3 * tan(fov / 2) limit).
JACOBIAN_GUARD = 0.3
#: Quaternions with max|q_i| below this count as zero (R = I, zero gradient): their
#: gradient ~1/|q| would overflow float32.
QUAT_MIN = 1e-20

#: float32 unit roundoff, 2^-24: the unit of every derived float32 tolerance (compare's bounds,
#: conform's; the oracle's boundary band keeps its own copy, ``reference.band.U``).
U32 = 2.0 ** -24

# Real spherical-harmonics constants and signs of graphdeco-inria 3DGS (utils/sh_utils.py).
#: The degree-0 constant, ``1 / (2 sqrt(pi))``.
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)

__all__ = ["LOG_SCALE_CLIP", "BIG_FACTOR", "JACOBIAN_GUARD", "QUAT_MIN", "U32", "SH_C0", "SH_C1", "SH_C2", "SH_C3"]
