"""Per-Gaussian preprocessing: activation, 3D covariance, EWA projection, culling.

Plain vectorized Dr.Jit code, differentiated by Dr.Jit's AD. Mirrors
`reference.project` op by op (docs/conventions.md, "project"): the same constant names
and the same numbered steps 1-10 as reference/project.py.

Every division and square root below takes a *safe* operand (selected before the
operation) so that culled Gaussians never put Inf or NaN into the AD graph: a
masked-out NaN still poisons gradients (0 * Inf = NaN), so masking afterwards is
not enough.
"""

from __future__ import annotations

import math
import sys
from typing import Any, NamedTuple

import numpy as np

from splatbench.conventions import BIG_FACTOR, JACOBIAN_GUARD, LOG_SCALE_CLIP, QUAT_MIN
from splatbench.raster.device import dr
from splatbench.raster.options import RasterOptions

#: The rasterizer's defaults: one source, `RasterOptions` (graphdeco's values).
DEFAULTS = RasterOptions()



#: A Dr.Jit array of the device's backend (``drjit.llvm.ad`` or ``drjit.cuda.ad``: `array_namespace`):
#: a field's comment gives its type there and its shape.
DrArray = Any


class Projection(NamedTuple):
    """Screen-space Gaussians: Dr.Jit arrays of one module (``drjit.llvm.ad`` or ``drjit.cuda.ad``:
    `DrArray`), all of width N, a field [N, 2] being an ``Array2f`` of two [N] columns. Gradients
    flow to the first four fields; the others are detached.
    """

    means2d: DrArray    # Array2f, [N, 2] float32: pixel coordinates (origin at the image's top-left corner)
    conics: DrArray     # Array3f, [N, 3] float32: (A, B, C) = (xx, xy, yy) of the inverse 2D covariance
    depths: DrArray     # Float, [N] float32: camera z
    opacities: DrArray  # Float, [N] float32: after the antialiasing compensation
    cutoff_sq: DrArray  # Float, [N] float32: R^2 in Mahalanobis units (detached)
    extents: DrArray    # Array2f, [N, 2] float32: (rx, ry) of the cutoff ellipse's bounding box, pixels (detached)
    radii: DrArray      # Int32, [N] int32: 0 when culled
    visible: DrArray    # Bool, [N] bool


def array_namespace(x):
    """The Dr.Jit module (e.g. ``drjit.llvm.ad``) that array ``x`` belongs to."""
    return sys.modules[type(x).__module__]


def columns(tensor, count: int, *, permute: bool = False):
    """Split a [N, count] Dr.Jit tensor into ``count`` flat arrays (differentiable).

    ``permute=True`` declares that this is the only read of each entry in the whole
    AD graph, so the reverse-mode derivative becomes a plain scatter instead of an
    atomic scatter-add. Only then: a second gather of the same tensor declared a
    permutation would *overwrite* the first one's gradient instead of adding to it.
    """
    m = array_namespace(tensor.array)
    n = tensor.shape[0]
    idx = dr.arange(m.UInt32, n) * count
    mode = dr.ReduceMode.Permute if permute else dr.ReduceMode.Auto
    return [dr.gather(m.Float, tensor.array, idx + c, mode=mode) for c in range(count)]


def sigmoid(x):
    """Logistic function without overflow in the value or its derivative."""
    # exp(-|x|) written as a select: d|x|/dx is 0 at x = 0 in Dr.Jit, which lost the
    # derivative (1/4) at a logit of exactly 0 (opacity 0.5); found by `splatbench conform`.
    e = dr.exp(dr.select(x >= 0, -x, x))  # in (0, 1]
    return dr.select(x >= 0, 1.0 / (1.0 + e), e / (1.0 + e))


def quat_to_rotmat(w, x, y, z):
    """Rotation matrix of the normalised quaternion (w, x, y, z); a zero quaternion gives I.

    Normalised as q / max|q_i| first so that components up to float32's maximum do
    not overflow when squared. The prescale is detached: q / |q| does not depend on
    it, and differentiating 1 / max|q_i| would overflow for tiny quaternions. A
    quaternion with max|q_i| < QUAT_MIN counts as zero (R = I, zero gradient): its
    true gradient, ~1 / |q|, would not fit in float32 (docs/conventions.md).
    """
    big = dr.maximum(dr.maximum(dr.abs(w), dr.abs(x)), dr.maximum(dr.abs(y), dr.abs(z)))
    nonzero = dr.detach(big) >= QUAT_MIN
    inv_big = dr.detach(1.0 / dr.select(nonzero, big, 1.0))
    w, x, y, z = w * inv_big, x * inv_big, y * inv_big, z * inv_big
    norm = dr.safe_sqrt(w * w + x * x + y * y + z * z)
    inv = dr.select(nonzero, 1.0 / dr.select(nonzero, norm, 1.0), 0.0)
    w, x, y, z = w * inv, x * inv, y * inv, z * inv
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def normalize(x, y, z):
    """Unit vectors along (x, y, z) (Dr.Jit arrays [N]); zero vectors stay zero. Mirrors the
    oracle's ``_normalize`` (reference/render.py): scaled by 1 / max|component| first, so
    that components up to float32's maximum do not overflow when squared. The prescale is
    detached: the unit vector does not depend on it (as in `quat_to_rotmat`)."""
    big = dr.maximum(dr.maximum(dr.abs(x), dr.abs(y)), dr.abs(z))
    nonzero = dr.detach(big) > 0
    inv_big = dr.detach(1.0 / dr.select(nonzero, big, 1.0))
    x, y, z = x * inv_big, y * inv_big, z * inv_big
    length = dr.safe_sqrt(x * x + y * y + z * z)  # in [1, sqrt(3)] unless zero
    inv = dr.select(nonzero, 1.0 / dr.select(nonzero, length, 1.0), 0.0)
    return x * inv, y * inv, z * inv


def camera_constants(m, K: np.ndarray, world_to_camera: np.ndarray) -> dict:
    """Camera parameters as opaque Dr.Jit scalars: kernels stay cached across views."""
    K = np.asarray(K, dtype=np.float64)
    W = np.asarray(world_to_camera, dtype=np.float64)
    op = lambda v: dr.opaque(m.Float, float(v))  # noqa: E731
    return {
        "fx": op(K[0, 0]), "fy": op(K[1, 1]), "cx": op(K[0, 2]), "cy": op(K[1, 2]),
        "R": [[op(W[i, j]) for j in range(3)] for i in range(3)],
        "t": [op(W[i, 3]) for i in range(3)],
        # camera centre -R^T t, computed in float64 on the host
        "center": [op(v) for v in -W[:3, :3].T @ W[:3, 3]],
    }


def clip_planes(camera, options: RasterOptions) -> tuple[float, float]:
    """The near and far planes in effect: the options', else the camera's."""
    near = camera.near if options.near is None else options.near
    far = camera.far if options.far is None else options.far
    return near, far


def project(means, log_scales, quats, opacity_logits, camera, options: RasterOptions = DEFAULTS) -> Projection:
    """Project Gaussians to the screen (mirrors `reference.project`, matched mode).

    Args:
        means: [N, 3] Dr.Jit tensor, world positions.
        log_scales: [N, 3] tensor, log of the axis scales.
        quats: [N, 4] tensor, (w, x, y, z), any length.
        opacity_logits: [N] tensor or flat array.
        camera: `splatbench.Camera`: intrinsics K, world_to_camera (OpenCV axes), width W and
            height H in pixels, and the near and far planes unless ``options`` sets them.
        options: `RasterOptions`; projection reads eps2d, near, far, radius, alpha_min and
            antialiased.

    Returns:
        `Projection` (its fields name their shapes).
    """
    K, world_to_camera, width, height = camera.K, camera.world_to_camera, camera.width, camera.height
    near, far = clip_planes(camera, options)
    eps2d, radius, alpha_min, antialiased = options.eps2d, options.radius, options.alpha_min, options.antialiased
    m = array_namespace(means.array)
    Float = m.Float
    mx, my, mz = columns(means, 3)  # also read for the SH view direction: no permute
    sx, sy, sz = (dr.exp(dr.clip(v, -LOG_SCALE_CLIP, LOG_SCALE_CLIP))
                  for v in columns(log_scales, 3, permute=True))
    R = quat_to_rotmat(*columns(quats, 4, permute=True))
    logits = opacity_logits.array if hasattr(opacity_logits, "shape") else opacity_logits
    cam = camera_constants(m, K, world_to_camera)
    Rw, tw = cam["R"], cam["t"]

    # 1. Camera space.
    px = Rw[0][0] * mx + Rw[0][1] * my + Rw[0][2] * mz + tw[0]
    py = Rw[1][0] * mx + Rw[1][1] * my + Rw[1][2] * mz + tw[1]
    pz = Rw[2][0] * mx + Rw[2][1] * my + Rw[2][2] * mz + tw[2]
    # 2. Depth cull (and non-finite camera points); culled Gaussians get safe operands below.
    in_depth = (pz >= near) & (pz <= far) & dr.isfinite(px) & dr.isfinite(py) & dr.isfinite(pz)
    z = dr.select(in_depth, pz, 1.0)
    x = dr.select(in_depth, px, 0.0)
    y = dr.select(in_depth, py, 0.0)
    inv_z = 1.0 / z

    fx, fy, cx, cy = cam["fx"], cam["fy"], cam["cx"], cam["cy"]

    # 3. EWA Jacobian, with graphdeco's clamp of x/z and y/z to 1.3x the field of view.
    #    The 2D mean uses the unclamped camera point.
    mean_u = fx * x * inv_z + cx
    mean_v = fy * y * inv_z + cy
    lim_x_pos = (width - cx) / fx + JACOBIAN_GUARD * (0.5 * width) / fx
    lim_x_neg = cx / fx + JACOBIAN_GUARD * (0.5 * width) / fx
    lim_y_pos = (height - cy) / fy + JACOBIAN_GUARD * (0.5 * height) / fy
    lim_y_neg = cy / fy + JACOBIAN_GUARD * (0.5 * height) / fy
    tx = z * dr.clip(x * inv_z, -lim_x_neg, lim_x_pos)
    ty = z * dr.clip(y * inv_z, -lim_y_neg, lim_y_pos)
    j00, j02 = fx * inv_z, -fx * tx * inv_z * inv_z
    j11, j12 = fy * inv_z, -fy * ty * inv_z * inv_z

    # 4. Sigma2D = J Rw Sigma Rw^T J^T + eps2d I, as T = J Rw (2x3), A = T R S, Sigma2D = A A^T
    #    (PSD by construction).
    T0 = [j00 * Rw[0][k] + j02 * Rw[2][k] for k in range(3)]
    T1 = [j11 * Rw[1][k] + j12 * Rw[2][k] for k in range(3)]
    scales = (sx, sy, sz)
    A0 = [(T0[0] * R[0][k] + T0[1] * R[1][k] + T0[2] * R[2][k]) * scales[k] for k in range(3)]
    A1 = [(T1[0] * R[0][k] + T1[1] * R[1][k] + T1[2] * R[2][k]) * scales[k] for k in range(3)]
    a_raw = A0[0] * A0[0] + A0[1] * A0[1] + A0[2] * A0[2]
    b_raw = A0[0] * A1[0] + A0[1] * A1[1] + A0[2] * A1[2]
    c_raw = A1[0] * A1[0] + A1[1] * A1[1] + A1[2] * A1[2]
    a, b, c = a_raw + eps2d, b_raw, c_raw + eps2d

    # 5. Cull degenerate or non-finite Sigma2D, and huge ones.
    max_var = (BIG_FACTOR * max(width, height)) ** 2
    det_unsafe = a * c - b * b
    valid = (in_depth & (dr.maximum(a, c) <= max_var) & (det_unsafe > 0)
             & dr.isfinite(det_unsafe) & dr.isfinite(mean_u) & dr.isfinite(mean_v))
    a = dr.select(valid, a, 1.0)
    b = dr.select(valid, b, 0.0)
    c = dr.select(valid, c, 1.0)
    # 6. Conic = inverse(Sigma2D) as (A, B, C).
    det = a * c - b * b
    inv_det = 1.0 / det
    conic_a, conic_b, conic_c = c * inv_det, -b * inv_det, a * inv_det

    # 7. Opacity, with the Mip-Splatting compensation.
    opacity = sigmoid(logits)
    if antialiased:
        det_raw = dr.select(valid, a_raw * c_raw - b_raw * b_raw, 0.0)
        opacity = opacity * dr.safe_sqrt(dr.maximum(det_raw, 0.0) * inv_det)

    # 8. Cutoff radius (Mahalanobis units), R^2.
    o_det = dr.detach(opacity)
    if radius == "3sigma":
        cutoff_sq = dr.full(Float, 9.0, dr.width(o_det))
    else:
        faint = o_det <= alpha_min
        valid &= ~faint
        cutoff_sq = dr.select(faint, 0.0, 2.0 * dr.log(dr.select(faint, 1.0, o_det / alpha_min)))
    # 9. Screen extent (the bounding box of the ellipse d^2 <= R^2) and off-screen cull.
    rx = dr.sqrt(cutoff_sq * dr.detach(a))
    ry = dr.sqrt(cutoff_sq * dr.detach(c))
    u, v = dr.detach(mean_u), dr.detach(mean_v)
    on_screen = (u + rx >= 0) & (u - rx <= width) & (v + ry >= 0) & (v - ry <= height)
    visible = valid & on_screen
    # 10. Integer radii; 0 when culled.
    radius_px = dr.ceil(dr.minimum(dr.maximum(rx, ry), 2.0**30))
    radii = dr.select(visible, m.Int32(radius_px), 0)

    return Projection(
        means2d=m.Array2f(mean_u, mean_v),
        conics=m.Array3f(conic_a, conic_b, conic_c),
        depths=z,
        opacities=opacity,
        cutoff_sq=cutoff_sq,
        extents=m.Array2f(rx, ry),
        radii=radii,
        visible=visible,
    )


def next_power_of_two(n: int) -> int:
    return 1 if n <= 1 else 1 << math.ceil(math.log2(n))
