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

Example::

    import splatbench
    from splatbench.validate import mitsuba as vm
    g, cam = vm.size_cases(64)[0].gaussians, vm.size_cases(64)[0].camera
    c = vm.compare(g, cam)
    c.psnr, c.max_error, c.rehit_pixels
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.gaussians import SH_C0, Gaussians

MITSUBA_VARIANT = "llvm_ad_rgb"
#: The extent of Mitsuba's ellipsoid shells in sigma; the rasterizer's ``radius="3sigma"``.
ELLIPSOID_EXTENT = 3.0
#: Rasterizer options that match ``volprim_rf_basic`` wherever the two definitions allow.
MATCHED_OPTIONS = {"eps2d": 0.0, "alpha_min": 1e-7, "alpha_max": 0.9999, "transmittance_min": 0.0,
                   "radius": "3sigma"}
#: The rasterizer's defaults (graphdeco-inria 3DGS), for the "3dgs" rows of the size sweep.
DEFAULT_OPTIONS: dict = {}
OPTION_SETS = {"matched": MATCHED_OPTIONS, "3dgs": DEFAULT_OPTIONS}
#: Opacity of every Gaussian in the sweeps (below Mitsuba's 0.9999 clamp).
SWEEP_OPACITY = 0.8
#: Default output folder of `write_report`, relative to the current folder.
DEFAULT_OUT = Path("reports") / "validate_mitsuba"
_EPS32 = float(np.finfo(np.float32).eps)


# ------------------------------------------------------------------------ Mitsuba
def mitsuba():
    """The ``mitsuba`` module with variant ``llvm_ad_rgb`` and ``volprim_rf_dedup`` registered."""
    import splatbench  # noqa: F401 - sets DRJIT_LIBLLVM_PATH before drjit loads
    import mitsuba as mi

    if mi.variant() != MITSUBA_VARIANT:
        mi.set_variant(MITSUBA_VARIANT)
    _register_dedup(mi)
    return mi


_REGISTERED: set[str] = set()


def _register_dedup(mi) -> None:
    """Register ``volprim_rf_dedup`` (`splatbench.validate._volprim_dedup`) for the current variant, once."""
    if mi.variant() in _REGISTERED:
        return
    from splatbench.validate._volprim_dedup import DedupVolprim

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
    mi = mitsuba()
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


def render_traced(gaussians: Gaussians, camera: Camera, *, shipped: bool = False) -> np.ndarray:
    """[H, W, 3] float32: Mitsuba's ray-traced Gaussians, one ray per pixel centre, no transfer curve.

    ``shipped=True`` uses ``volprim_rf_basic`` as shipped (which may composite a
    small Gaussian twice; see the module docstring); the default its dedup subclass.
    """
    mi = mitsuba()
    scene = mitsuba_scene(gaussians, camera, integrator="volprim_rf_basic" if shipped else "volprim_rf_dedup")
    image = np.asarray(mi.render(scene, spp=1), dtype=np.float32)
    return np.ascontiguousarray(image[..., :3])


def render_splat(gaussians: Gaussians, camera: Camera, options: dict | None = None) -> np.ndarray:
    """[H, W, 3] float32 from `splatbench.render` (black background); ``options`` default `MATCHED_OPTIONS`."""
    import splatbench

    opts = MATCHED_OPTIONS if options is None else options
    return splatbench.render(gaussians, camera, background=(0.0, 0.0, 0.0), device="cpu", **opts).rgb


def psnr(a: np.ndarray, b: np.ndarray, peak: float = 1.0) -> float:
    """``10 log10(peak^2 / MSE)`` over all pixels and channels; ``inf`` for identical images."""
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(peak * peak / mse)


@dataclass(frozen=True)
class Comparison:
    """The same Gaussians rendered by the rasterizer and by Mitsuba, and how far apart they are.

    splat, traced, traced_shipped: [H, W, 3] float32 (linear, black background).
    psnr, max_error, mean_error: splat vs traced (``volprim_rf_dedup``); PSNR with peak 1.
    psnr_shipped, max_error_shipped: splat vs ``volprim_rf_basic`` as shipped.
    rehit_pixels: pixels where the shipped integrator composited a primitive twice
    (where the two Mitsuba images differ by more than 1e-6).
    """

    splat: np.ndarray
    traced: np.ndarray
    traced_shipped: np.ndarray
    psnr: float
    max_error: float
    mean_error: float
    psnr_shipped: float
    max_error_shipped: float
    rehit_pixels: int


def compare(gaussians: Gaussians, camera: Camera, options: dict | None = None) -> Comparison:
    """Render ``gaussians`` from ``camera`` with both renderers and compare (see `Comparison`)."""
    splat = render_splat(gaussians, camera, options)
    traced = render_traced(gaussians, camera)
    shipped = render_traced(gaussians, camera, shipped=True)
    err = np.abs(splat.astype(np.float64) - traced)
    rehits = int(np.count_nonzero(np.abs(shipped.astype(np.float64) - traced).max(axis=-1) > 1e-6))
    return Comparison(splat, traced, shipped, psnr(splat, traced), float(err.max()), float(err.mean()),
                      psnr(splat, shipped), float(np.abs(splat.astype(np.float64) - shipped).max()), rehits)


# --------------------------------------------------------- the isotropic closed form
@dataclass(frozen=True)
class IsotropicPrediction:
    """What each renderer computes for disjoint isotropic degree-0 Gaussians, in closed form.

    splat, traced: [H, W, 3] float64 predicted images (`isotropic_prediction`).
    bound_max: per-pixel bound on |splat - traced| (affine term + truncation band +
    float32 allowance); bound_psnr: the PSNR that the bound guarantees.
    rho: [N] ``max |r - 1|`` over each Gaussian's footprint, ``r = m_ray^2 / m_affine^2``.
    band_pixels: pixels where one renderer may truncate and the other not.
    """

    splat: np.ndarray
    traced: np.ndarray
    bound_max: float
    bound_psnr: float
    rho: np.ndarray
    band_pixels: int


def isotropic_prediction(gaussians: Gaussians, camera: Camera) -> IsotropicPrediction:
    """Closed-form images and error bound for isotropic, degree-0, screen-disjoint Gaussians.

    For an isotropic Gaussian (sigma, mean at camera coordinates (x, y, z), ``m = (x/z,
    y/z)``) and the ray of a pixel with normalised coordinates ``a = ((u-cx)/fx,
    (v-cy)/fy)``, the EWA splat's Mahalanobis distance is
    ``m_a^2 = (z/sigma)^2 (|a-m|^2 + ((a-m) x m)^2) / (1 + |m|^2)`` and the ray's is
    ``m_e^2 = (z/sigma)^2 (|a-m|^2 + ((a-m) x m)^2) / (1 + |a|^2)`` (Lagrange's identity;
    docs/validation.md), so ``m_e^2 = r m_a^2`` with ``r = (1+|m|^2)/(1+|a|^2)``. With
    ``rho = max |r - 1|`` over the footprint, where both keep the Gaussian
    ``|o c (e^{-m_a^2/2} - e^{-r m_a^2/2})| <= o c rho / ((1 - rho) e)``; in the band
    ``9/(1+rho) < m_a^2 <= 9/(1-rho)`` one of them may cut it, costing at most
    ``o c e^{-9(1-rho)/2}``. A float32 allowance ``o c e^{-1/2} 8 eps32 D/sigma`` (the
    ray's peak point is computed in float32 at distance D) is added. Requires
    footprints (``m_a^2 <= 18``) that no two Gaussians share; `InputError` otherwise.
    """
    n = len(gaussians)
    scales = gaussians.scales.astype(np.float64)
    if n == 0 or not np.allclose(scales, scales[:, :1], rtol=1e-6):
        raise InputError("gaussians: isotropic_prediction needs N >= 1 isotropic Gaussians (equal scales)")
    if gaussians.sh_degree != 0:
        raise InputError(f"gaussians: isotropic_prediction needs SH degree 0, got {gaussians.sh_degree}")
    sigma = scales[:, 0]
    w2c = camera.world_to_camera
    cam_pts = gaussians.means.astype(np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
    z = cam_pts[:, 2]
    if not np.all(z > 6 * sigma):
        raise InputError("gaussians: isotropic_prediction needs every Gaussian's 3-sigma ball in front of the camera")
    m = cam_pts[:, :2] / z[:, None]
    opac = gaussians.opacities.astype(np.float64)
    colour = np.maximum(SH_C0 * gaussians.sh[:, 0, :].astype(np.float64) + 0.5, 0.0)  # [N, 3]
    jj, ii = np.meshgrid(np.arange(camera.width) + 0.5, np.arange(camera.height) + 0.5)
    a = np.stack([(jj - camera.cx) / camera.fx, (ii - camera.cy) / camera.fy], axis=-1)  # [H, W, 2]
    a2 = np.sum(a * a, axis=-1)
    splat = np.zeros((camera.height, camera.width, 3))
    traced = np.zeros_like(splat)
    bound = np.zeros((camera.height, camera.width))
    owner = np.full((camera.height, camera.width), -1)
    rho = np.zeros(n)
    band_pixels = 0
    for k in range(n):
        d = a - m[k]
        cross = d[..., 0] * m[k, 1] - d[..., 1] * m[k, 0]
        common = (z[k] / sigma[k]) ** 2 * (np.sum(d * d, axis=-1) + cross * cross)
        m2_affine = common / (1.0 + m[k] @ m[k])
        m2_ray = common / (1.0 + a2)
        near = m2_affine <= 18.0
        if np.any(owner[near] >= 0):
            raise InputError(f"gaussians: footprints of Gaussians {int(owner[near].max())} and {k} overlap; "
                             f"isotropic_prediction needs screen-disjoint Gaussians")
        owner[near] = k
        r = m2_ray[near] / np.where(m2_affine[near] > 0, m2_affine[near], 1.0)
        r = np.where(m2_affine[near] > 0, r, 1.0)
        rho[k] = float(np.max(np.abs(r - 1.0))) if r.size else 0.0
        if rho[k] >= 0.5:
            raise InputError(f"gaussians: Gaussian {k} is too large for the bound (rho = {rho[k]:.3f} >= 0.5)")
        keep_a = m2_affine <= ELLIPSOID_EXTENT ** 2
        keep_e = m2_ray <= ELLIPSOID_EXTENT ** 2
        splat += (opac[k] * np.exp(-0.5 * m2_affine) * keep_a)[..., None] * colour[k]
        traced += (opac[k] * np.exp(-0.5 * m2_ray) * keep_e)[..., None] * colour[k]
        peak = opac[k] * float(colour[k].max())
        dist = float(np.linalg.norm(cam_pts[k]))
        f32 = peak * math.exp(-0.5) * 8 * _EPS32 * dist / sigma[k]
        inside = m2_affine <= 9.0 / (1.0 + rho[k])
        band = (m2_affine > 9.0 / (1.0 + rho[k])) & (m2_affine <= 9.0 / (1.0 - rho[k]))
        bound[inside] = peak * rho[k] / ((1.0 - rho[k]) * math.e) + f32
        bound[band] = peak * math.exp(-4.5 * (1.0 - rho[k])) + f32
        band_pixels += int(band.sum())
    mse_bound = float(np.mean(bound ** 2))  # every channel's error is at most the pixel's bound
    bound_psnr = math.inf if mse_bound == 0 else -10.0 * math.log10(mse_bound)
    return IsotropicPrediction(splat, traced, float(bound.max()), bound_psnr, rho, band_pixels)


# -------------------------------------------------------------------------- sweeps
@dataclass(frozen=True)
class Case:
    """One scene of a sweep: the factor, its value, and what to render."""

    sweep: str              # "size", "anisotropy", "angle", "overlap" or "sh"
    parameter: str          # what ``value`` measures, e.g. "sigma_px"
    value: float
    gaussians: Gaussians
    camera: Camera
    options: str = "matched"  # key of OPTION_SETS used for the rasterizer


@dataclass(frozen=True)
class SweepRow:
    """One line of the report table (CSV and markdown columns, in this order)."""

    sweep: str
    parameter: str
    value: float
    options: str
    gaussians: int
    psnr: float
    max_error: float
    mean_error: float
    psnr_shipped: float
    max_error_shipped: float
    rehit_pixels: int


_DISTANCE = 400.0  # camera distance to the target (world units; see "Scale" in docs/validation.md)


def _camera(width: int, fov_x_deg: float = 50.0) -> Camera:
    return Camera.look_at(eye=[0.0, 0.0, -_DISTANCE], target=[0.0, 0.0, 0.0], up=[0.0, -1.0, 0.0],
                          width=width, height=width, fov_x_deg=fov_x_deg)


def _point_at(camera: Camera, u: float, v: float, depth: float) -> np.ndarray:
    """The world point at camera depth ``depth`` seen at pixel position (u, v)."""
    pc = np.array([(u - camera.cx) / camera.fx * depth, (v - camera.cy) / camera.fy * depth, depth])
    return camera.camera_to_world[:3, :3] @ pc + camera.camera_to_world[:3, 3]


def _colours(n: int, rng: np.random.Generator) -> np.ndarray:
    """[n, 3] saturated colours in [0.15, 0.95] (degree-0 SH values, not clipped)."""
    base = rng.uniform(0.15, 0.95, size=(n, 3))
    base[np.arange(n), rng.integers(0, 3, n)] = 0.95  # one strong channel each
    return base


def _gaussians(means, sigmas, colours, *, quats=None, sh_rest=None) -> Gaussians:
    """Gaussians with given means [N, 3], per-axis sigmas [N, 3], degree-0 colours [N, 3]."""
    means = np.asarray(means, np.float64)
    n = len(means)
    sh0 = (np.asarray(colours, np.float64) - 0.5) / SH_C0
    sh = sh0[:, None, :] if sh_rest is None else np.concatenate([sh0[:, None, :], sh_rest], axis=1)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) if quats is None else quats
    logit = math.log(SWEEP_OPACITY / (1 - SWEEP_OPACITY))
    return Gaussians(means, np.log(np.asarray(sigmas, np.float64)), q, np.full(n, logit), sh)


def _grid(camera: Camera, rng: np.random.Generator, count: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``count`` x ``count`` pixel positions (spacing W/count) and distinct depths near the target."""
    w = camera.width
    offsets = (np.arange(count) - (count - 1) / 2) * (w / count)
    uu, vv = np.meshgrid(camera.cx + offsets, camera.cy + offsets)
    depths = _DISTANCE * (1.0 + np.linspace(-0.075, 0.075, count * count))
    rng.shuffle(depths)  # depth-separated, in no particular screen order
    return np.stack([uu.ravel(), vv.ravel()], axis=1), depths


def _random_quats(n: int, rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def size_cases(width: int = 128, sizes_px: Sequence[float] | None = None, *, seed: int = 0,
               options: str = "matched") -> list[Case]:
    """Isotropic Gaussians on a 3x3 grid (field angles up to ~24 degrees), screen sigma in pixels.

    ``sizes_px`` default ``width/128 * (0.5, 1, 2, 4, 6)``: 6 px at 128 is the largest
    that keeps the 3-sigma footprints (spacing W/3) apart.
    """
    cam = _camera(width)
    sizes = [width / 128 * s for s in (0.5, 1.0, 2.0, 4.0, 6.0)] if sizes_px is None else list(sizes_px)
    out = []
    for s in sizes:
        rng = np.random.default_rng(seed)
        uv, depths = _grid(cam, rng)
        means = np.stack([_point_at(cam, u, v, z) for (u, v), z in zip(uv, depths)])
        sig = s * depths / cam.fx
        out.append(Case("size", "sigma_px", float(s), _gaussians(means, np.repeat(sig[:, None], 3, 1),
                                                                 _colours(len(means), rng)), cam, options))
    return out


def anisotropy_cases(width: int = 128, ratios: Sequence[float] = (1, 2, 4, 8, 16, 32), *, seed: int = 0) -> list[Case]:
    """Flat Gaussians (sigma, sigma, sigma/ratio), random orientations, largest axis 4 px at 128."""
    cam = _camera(width)
    out = []
    for ratio in ratios:
        rng = np.random.default_rng(seed)
        uv, depths = _grid(cam, rng)
        means = np.stack([_point_at(cam, u, v, z) for (u, v), z in zip(uv, depths)])
        s = (width / 32) * depths / cam.fx
        sig = np.stack([s, s, s / ratio], axis=1)
        out.append(Case("anisotropy", "ratio", float(ratio),
                        _gaussians(means, sig, _colours(len(means), rng), quats=_random_quats(len(means), rng)), cam))
    return out


def angle_cases(width: int = 128, angles_deg: Sequence[float] = (0, 10, 20, 30, 40, 50), *, seed: int = 0) -> list[Case]:
    """One isotropic Gaussian at a field angle off the optical axis (120-degree camera).

    Its angular size is fixed (sigma = 0.04 x distance: 1.5 px at the image centre at
    128), so only the position in the field changes.
    """
    cam = _camera(width, fov_x_deg=120.0)
    out = []
    for angle in angles_deg:
        rng = np.random.default_rng(seed)
        t = math.radians(angle)
        direction = np.array([math.sin(t) / math.sqrt(2), math.sin(t) / math.sqrt(2), math.cos(t)])
        mean_cam = direction * _DISTANCE
        mean = cam.camera_to_world[:3, :3] @ mean_cam + cam.camera_to_world[:3, 3]
        sig = 0.04 * _DISTANCE
        out.append(Case("angle", "field_angle_deg", float(angle),
                        _gaussians(mean[None], np.full((1, 3), sig), _colours(1, rng)), cam))
    return out


def overlap_cases(width: int = 128, gaps: Sequence[float] = (12, 6, 3, 1.5, 0.75, 0), *, seed: int = 0) -> list[Case]:
    """Four stacks of three Gaussians (sigma s, 1.5 s, 2 s in random order) at one screen position each.

    ``gap``: depth between consecutive centres of a stack, in units of s (s = 3 px on
    screen at 128). Every member keeps its screen position (lateral jitter up to 0.5 s)
    and its screen size whatever the gap, so only the depth overlap changes: at 12 s the
    3-sigma shells are apart in depth; at 0 the centres share a depth and only the
    sort's tie-break orders them.
    """
    cam = _camera(width)
    out = []
    for gap in gaps:
        rng = np.random.default_rng(seed)
        s = (width / 128) * 3.0 * _DISTANCE / cam.fx  # world sigma of 3 px (at 128) at the target depth
        means, sigs = [], []
        for u, v in ((0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7)):
            for k, factor in enumerate(rng.permutation([1.0, 1.5, 2.0])):
                jitter = rng.uniform(-0.5, 0.5, 2) * s * cam.fx / _DISTANCE  # pixels
                depth = _DISTANCE + (k - 1) * gap * s
                means.append(_point_at(cam, u * width + jitter[0], v * width + jitter[1], depth))
                sigs.append(factor * s * depth / _DISTANCE)
        sigs_ = np.repeat(np.asarray(sigs)[:, None], 3, 1)
        out.append(Case("overlap", "gap_sigma", float(gap),
                        _gaussians(np.asarray(means), sigs_, _colours(len(means), rng)), cam))
    return out


def sh_cases(width: int = 128, degrees: Sequence[int] = (0, 1, 2, 3), *, seed: int = 0) -> list[Case]:
    """The 3x3 grid at 4 px (at 128) with SH of degree d: random bands above 0, N(0, 0.2)."""
    cam = _camera(width)
    out = []
    for degree in degrees:
        rng = np.random.default_rng(seed)
        uv, depths = _grid(cam, rng)
        means = np.stack([_point_at(cam, u, v, z) for (u, v), z in zip(uv, depths)])
        sig = (width / 32) * depths / cam.fx
        colours = _colours(len(means), rng)
        rest = rng.normal(0.0, 0.2, size=(len(means), 15, 3))[:, : (degree + 1) ** 2 - 1]
        out.append(Case("sh", "sh_degree", float(degree),
                        _gaussians(means, np.repeat(sig[:, None], 3, 1), colours,
                                   sh_rest=rest if degree else None), cam))
    return out


#: Every sweep: name -> case factory ``f(width) -> list[Case]``.
SWEEPS: dict[str, Callable[[int], list[Case]]] = {
    "size": lambda w: size_cases(w) + size_cases(w, options="3dgs"),
    "anisotropy": anisotropy_cases,
    "angle": angle_cases,
    "overlap": overlap_cases,
    "sh": sh_cases,
}


def run_case(case: Case) -> SweepRow:
    """Render one `Case` with both renderers and summarise it."""
    c = compare(case.gaussians, case.camera, OPTION_SETS[case.options])
    return SweepRow(case.sweep, case.parameter, case.value, case.options, len(case.gaussians), c.psnr, c.max_error,
                    c.mean_error, c.psnr_shipped, c.max_error_shipped, c.rehit_pixels)


def run_sweeps(width: int = 128, sweeps: Iterable[str] | None = None, *, progress: bool = False) -> list[SweepRow]:
    """Run the named sweeps (default all of `SWEEPS`) at ``width`` x ``width`` pixels."""
    names = list(SWEEPS) if sweeps is None else list(sweeps)
    for name in names:
        if name not in SWEEPS:
            raise InputError(f"sweep: expected one of {', '.join(SWEEPS)}, got {name!r}")
    if not (isinstance(width, int) and width >= 16):
        raise InputError(f"width: expected an int >= 16, got {width!r}")
    cases = [case for name in names for case in SWEEPS[name](width)]
    from tqdm import tqdm

    return [run_case(case) for case in tqdm(cases, desc="validate mitsuba", unit="case", disable=not progress,
                                            leave=False)]


# ------------------------------------------------------------ intersection probe
@dataclass(frozen=True)
class ProbeRow:
    """How often Mitsuba's ray-ellipsoid test disagrees with the exact one (``m_ray < 3``)."""

    sigma: float           # the Gaussian's (isotropic) standard deviation, world units
    distance_ratio: float  # ray origin distance / sigma
    rays: int
    wrong: float           # fraction of rays whose hit/miss differs from the exact test
    max_m_error: float     # largest |m_ray - 3| among the wrong rays (0 when none)


def intersection_probe(sigmas: Sequence[float] = (0.01, 0.1, 1.0, 10.0),
                       ratios: Sequence[float] = (10, 30, 100, 300, 1000), *, rays: int = 20000,
                       seed: int = 0) -> list[ProbeRow]:
    """Shoot ``rays`` rays at one isotropic ``ellipsoids`` primitive and check each hit/miss.

    For each sigma and distance ratio, rays start on the axis at distance
    ``ratio * sigma`` and pass the centre at a Mahalanobis distance drawn uniformly in
    [0, 6]; the exact answer is a hit when that distance is below the extent (3).
    """
    mi = mitsuba()
    out = []
    for sigma in sigmas:
        data = np.array([[0.0, 0.0, 0.0, sigma, sigma, sigma, 0.0, 0.0, 0.0, 1.0]], np.float32)
        scene = mi.load_dict({"type": "scene", "shape": {"type": "ellipsoids", "extent": ELLIPSOID_EXTENT,
                                                         "data": mi.TensorXf(data)}})
        for ratio in ratios:
            rng = np.random.default_rng(seed)
            m = rng.uniform(0.0, 6.0, rays)
            phi = rng.uniform(0.0, 2 * math.pi, rays)
            target = np.stack([np.cos(phi) * m * sigma, np.sin(phi) * m * sigma, np.zeros(rays)], axis=1)
            origin = np.array([0.0, 0.0, -ratio * sigma])
            d = target - origin
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            m_exact = np.linalg.norm(-origin[None] - (d @ -origin)[:, None] * d, axis=1) / sigma
            ray = mi.Ray3f(mi.Point3f(*[np.full(rays, c, np.float32) for c in origin]),
                           mi.Vector3f(*[np.ascontiguousarray(d[:, k], dtype=np.float32) for k in range(3)]))
            hit = np.asarray(scene.ray_intersect(ray).is_valid(), dtype=bool)
            wrong = hit != (m_exact < ELLIPSOID_EXTENT)
            out.append(ProbeRow(float(sigma), float(ratio), rays, float(wrong.mean()),
                                float(np.abs(m_exact[wrong] - ELLIPSOID_EXTENT).max()) if wrong.any() else 0.0))
    return out


# -------------------------------------------------------------------------- checks
@dataclass(frozen=True)
class Check:
    """One pass/fail statement of `splatbench validate mitsuba`."""

    name: str
    passed: bool
    detail: str


#: Largest |(splat - traced) - (predicted splat - predicted traced)| accepted by `check_tight`
#: (float32 in both renderers; the closed form is float64).
PREDICTION_ATOL = 1e-4
#: Smallest screen sigma (px) that `check_trends` orders by size.
MIN_TREND_SIGMA_PX = 0.5


def check_tight(width: int = 128, max_sigma_px: float | None = None) -> list[Check]:
    """The tight regime: small, isotropic, screen-disjoint, depth-separated degree-0 Gaussians.

    For every `size_cases` scene with sigma <= ``max_sigma_px`` (default 2 px at 128,
    scaled with ``width``: an angular sigma of 0.0145 rad): (1) the derived bound (`isotropic_prediction`) guarantees
    >= 40 dB; (2) the measured PSNR and max error are within the bound; (3) the
    measured difference equals the closed-form difference within `PREDICTION_ATOL`
    per pixel (both renderers do exactly what docs/validation.md says).
    """
    limit = 2 * width / 128 if max_sigma_px is None else max_sigma_px
    out = []
    for case in size_cases(width):
        if case.value > limit + 1e-9:
            continue
        c = compare(case.gaussians, case.camera)
        pred = isotropic_prediction(case.gaussians, case.camera)
        residual = float(np.abs((c.splat.astype(np.float64) - c.traced) - (pred.splat - pred.traced)).max())
        tag = f"sigma {case.value:.3g} px"
        out.append(Check(f"tight bound >= 40 dB ({tag})", pred.bound_psnr >= 40.0,
                         f"derived bound {pred.bound_psnr:.1f} dB (rho <= {pred.rho.max():.4f}, "
                         f"{pred.band_pixels} band pixels)"))
        out.append(Check(f"tight PSNR within bound ({tag})", c.psnr >= pred.bound_psnr and
                         c.max_error <= pred.bound_max,
                         f"PSNR {c.psnr:.1f} dB >= {pred.bound_psnr:.1f}; max error {c.max_error:.2e} <= "
                         f"{pred.bound_max:.2e}"))
        out.append(Check(f"closed form predicts both renderers ({tag})", residual <= PREDICTION_ATOL,
                         f"max |measured - predicted difference| {residual:.1e} <= {PREDICTION_ATOL:g}"))
    return out


def check_trends(rows: Sequence[SweepRow], *, tolerance_db: float = 0.5, min_drop_db: float = 10.0) -> list[Check]:
    """Error grows with size (PSNR strictly decreasing, matched options) and with overlap.

    Size: sigma >= `MIN_TREND_SIGMA_PX` only; below half a pixel a handful of pixel
    centres sample each Gaussian and where they fall, not the size, sets the error.
    Overlap: PSNR non-increasing as the depth gap shrinks, within ``tolerance_db``
    (well-separated stacks are equal up to rounding). Both sweeps must lose at least
    ``min_drop_db`` from first to last value.
    """
    out = []
    for sweep, strict in (("size", True), ("overlap", False)):
        psnrs = [r.psnr for r in rows if r.sweep == sweep and r.options == "matched"
                 and (sweep != "size" or r.value >= MIN_TREND_SIGMA_PX)]
        if len(psnrs) < 2:
            continue
        steps = np.diff(psnrs)
        ok = bool(np.all(steps < 0)) if strict else bool(np.all(steps <= tolerance_db))
        ok &= psnrs[0] - psnrs[-1] >= min_drop_db
        out.append(Check(f"error grows with {sweep}", ok,
                         "PSNR " + (" > " if strict else " >= ").join(f"{x:.1f}" for x in psnrs) + " dB"))
    return out


# -------------------------------------------------------------------------- report
@dataclass(frozen=True)
class ReportPaths:
    """Files written by `write_report`."""

    csv: Path
    markdown: Path
    plot: Path
    extra: dict = field(default_factory=dict)


_LABELS = {"size": "screen size sigma (px)", "anisotropy": "anisotropy (largest / smallest axis)",
           "angle": "field angle (deg)", "overlap": "depth gap between overlapping Gaussians (sigma)",
           "sh": "SH degree"}


def _fmt(x: float) -> str:
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def markdown_table(rows: Sequence[SweepRow], width: int) -> str:
    """The rows as a markdown table (one per sweep)."""
    lines = [f"Rasterizer vs Mitsuba `volprim_rf_dedup`, {width}x{width}, one ray per pixel centre, linear RGB, "
             f"peak 1. `shipped`: `volprim_rf_basic` as shipped. Options `matched`: {MATCHED_OPTIONS}; "
             f"`3dgs`: the rasterizer's defaults (eps2d 0.3, alpha_min 1/255, alpha_max 0.99).", ""]
    header = ("| sweep | parameter | value | options | N | PSNR (dB) | max error | mean error | PSNR shipped | "
              "max error shipped | re-hit pixels |")
    lines += [header, "|" + "---|" * 11]
    for r in rows:
        lines.append(f"| {r.sweep} | {r.parameter} | {_fmt(r.value)} | {r.options} | {r.gaussians} | "
                     f"{_fmt(r.psnr)} | {_fmt(r.max_error)} | {_fmt(r.mean_error)} | {_fmt(r.psnr_shipped)} | "
                     f"{_fmt(r.max_error_shipped)} | {r.rehit_pixels} |")
    return "\n".join(lines) + "\n"


def probe_markdown(probe: Sequence[ProbeRow]) -> str:
    """`intersection_probe` rows as a markdown table (fraction of wrong hit/miss decisions)."""
    ratios = sorted({r.distance_ratio for r in probe})
    sigmas = sorted({r.sigma for r in probe})
    cell = {(r.sigma, r.distance_ratio): r for r in probe}
    lines = ["## Mitsuba's ray-ellipsoid test (llvm_ad_rgb): wrong hit/miss decisions", "",
             "Fraction of rays whose hit/miss differs from the exact test m_ray < 3 (max |m_ray - 3| among "
             "them in brackets); rows: sigma (world units), columns: ray-origin distance / sigma.", "",
             "| sigma | " + " | ".join(f"D/sigma {x:g}" for x in ratios) + " |", "|---|" + "---|" * len(ratios)]
    for sg in sigmas:
        cells = []
        for ra in ratios:
            r = cell.get((sg, ra))
            cells.append("" if r is None else (f"{r.wrong:.2%}" + (f" ({r.max_m_error:.2g})" if r.wrong else "")))
        lines.append(f"| {sg:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_report(rows: Sequence[SweepRow], out_dir: str | Path = DEFAULT_OUT, *, width: int = 128,
                 probe: Sequence[ProbeRow] = (), checks: Sequence[Check] = ()) -> ReportPaths:
    """Write ``table.csv``, ``table.md`` and ``plot.png`` (PSNR and max error per sweep) to ``out_dir``.

    With ``probe`` rows, also ``intersection.csv`` and a section of ``table.md``; with
    ``checks``, a pass/fail section of ``table.md``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    csv_path, md_path, plot_path = out / "table.csv", out / "table.md", out / "plot.png"
    names = [f.name for f in SweepRow.__dataclass_fields__.values()]
    with open(csv_path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=names)
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (_fmt(v) if isinstance(v, float) else v) for k, v in asdict(r).items()})
    text = markdown_table(rows, width)
    extra = {}
    if probe:
        probe_path = out / "intersection.csv"
        with open(probe_path, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(ProbeRow.__dataclass_fields__))
            writer.writeheader()
            for r in probe:
                writer.writerow(asdict(r))
        extra["intersection"] = probe_path
        text += "\n" + probe_markdown(probe)
    if checks:
        text += "\n## Checks\n\n" + "".join(f"- {'PASS' if c.passed else 'FAIL'} {c.name}: {c.detail}\n"
                                             for c in checks)
    md_path.write_text(text, encoding="utf-8")

    sweeps = list(dict.fromkeys(r.sweep for r in rows))
    fig, axes = plt.subplots(1, max(1, len(sweeps)), figsize=(4.2 * max(1, len(sweeps)), 3.6), squeeze=False)
    for ax, name in zip(axes[0], sweeps):
        ax2 = ax.twinx()
        for opt, style in (("matched", "-"), ("3dgs", ":")):
            sel = [r for r in rows if r.sweep == name and r.options == opt]
            if not sel:
                continue
            x = [r.value for r in sel]
            ax.plot(x, [min(r.psnr, 120.0) for r in sel], "o" + style, color="tab:blue", label=f"PSNR ({opt})")
            ax2.semilogy(x, [max(r.max_error, 1e-9) for r in sel], "s" + style, color="tab:red",
                         label=f"max error ({opt})")
        ax.set_xlabel(_LABELS.get(name, name))
        ax.set_ylabel("PSNR (dB)", color="tab:blue")
        ax2.set_ylabel("max |error|", color="tab:red")
        ax.set_title(name)
        ax.grid(alpha=0.3)
        if name == "size":
            ax.set_xscale("log", base=2)
        lines = ax.get_legend_handles_labels()
        lines2 = ax2.get_legend_handles_labels()
        ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=7, loc="center left", framealpha=0.8)
    fig.suptitle(f"splat rasterizer vs Mitsuba volprim_rf (ray-traced Gaussians), {width}x{width}")
    fig.tight_layout()
    fig.savefig(plot_path, dpi=110)
    plt.close(fig)
    return ReportPaths(csv_path, md_path, plot_path, extra)
