"""A slow, float64, pure-NumPy reference renderer for 3D Gaussian Splatting.

The oracle that ``splatbench.raster`` is tested against. It is written from
``docs/conventions.md`` alone and imports nothing from ``splatbench``, so the two
cannot share a bug. Clarity over speed: one pixel at a time.

    project            mirrors splatbench.raster.project
    eval_sh            mirrors splatbench.raster.eval_sh
    composite          mirrors splatbench.raster.composite
    render             mirrors splatbench.raster.render
    finite_difference_grad   central differences of a loss of `render`
    band               the boundary band: pixels where float32 may take a discrete
                       decision the other way (``render(band=True)``)

Every op takes ``mode="matched"`` (the fast path's rules: cutoffs, clamps, early stop)
or ``mode="exact"`` (the smooth function, for finite differences). ``render`` also takes
keywords for conventions other than graphdeco's (pixel centre, activations, quaternion
order, SH direction / basis / degree, colour clamp, background, sort key, depth, Jacobian
clamp), so other rasterizers' behaviour can be reproduced (docs/conventions.md, last section).
"""

from reference.composite import Composite, composite
from reference.fd import finite_difference_grad
from reference.project import Projection, covariance, project, quat_to_rotmat
from reference.render import RenderOutput, camera_centre, render
from reference.sh import eval_sh, sh_basis

__all__ = [
    "Composite",
    "Projection",
    "RenderOutput",
    "camera_centre",
    "composite",
    "covariance",
    "eval_sh",
    "finite_difference_grad",
    "project",
    "quat_to_rotmat",
    "render",
    "sh_basis",
]
