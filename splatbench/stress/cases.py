"""Degenerate-input scenes for the numerical-stability stress test (hand-made probe scenes, one of
the five kinds of "scene": docs/architecture.md).

Every builder takes an integer seed and returns a `StressCase`: a small scene
(1-60 Gaussians, or 1000 stacked ones) seen by a small, randomly posed camera.
Plain NumPy (``np.random.default_rng``), so the CLI needs no test dependency;
``tests/test_stress.py`` feeds the same builders from hypothesis strategies.

Scenes are made in camera space (so they land in view) and moved to the world
through the camera pose (`splatbench.render_inputs`). The camera's rotation is
uniformly random; its centre, the image size, N and the rasterizer options come
from small menus, because the rasterizer bakes these into its Dr.Jit kernels as
literals (see docs/stress.md): free choices would recompile kernels in every case.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.gaussians import GROUPS, quat_to_rotmat
from splatbench.raster import RasterOptions
from splatbench.render_inputs import RenderInput, camera_points, to_world, world_sigma
from splatbench.workloads import random_unit_quats

FIELDS = GROUPS  # StressCase's parameter fields, in rasterize's argument order

SIZES = ((24, 20), (32, 24), (48, 40))          # (W, H) menu
COUNTS = (1, 3, 12, 60)                          # N menu (the stacked category uses STACK)
SH_DEGREES = (0, 3)                              # SH degree menu
STACK = 1000                                     # Gaussians piled on one spot
CENTRES = ((0.0, 0.0, 0.0), (1.5, -2.0, 0.5), (-3.0, 1.0, 2.0))   # camera centres (exact in float32)
FAR_CENTRES = ((1e4, 0.0, 0.0), (0.0, -1e4, 0.0), (-6e3, 8e3, 0.0))  # |c| = 1e4
NEAR = 0.01                                      # the camera's near plane (Camera's default)


@dataclass(frozen=True, kw_only=True)
class StressCase(RenderInput):
    """One stress scene: a `RenderInput` (the five raw parameter groups, float32: means [N, 3],
    log_scales [N, 3], quats [N, 4], opacity_logits [N], sh [N, K, 3]; a camera; background and
    SH degree left at None: black, every band), with, by keyword, its ``category`` and ``seed``,
    the rasterizer ``options``, and ``nonfinite_field``: the group holding a NaN/Inf (the case
    must be rejected with an error naming it), None when every value is finite.
    """

    category: str
    seed: int
    options: RasterOptions = RasterOptions()
    nonfinite_field: str | None = None

    @property
    def label(self) -> str:
        """How to rebuild this case: ``build_case(category, seed)``."""
        return f"build_case({self.category!r}, {self.seed})"


# ------------------------------------------------------------------ helpers
@dataclass(frozen=True)
class _View:
    camera: Camera
    cam_quat: np.ndarray  # unit quaternion of the world-to-camera rotation

    def aligned_quats(self, n: int) -> np.ndarray:
        """[n, 4] quaternions whose Gaussian axes are the camera axes (x, y, z) in world."""
        w, x, y, z = self.cam_quat
        return np.tile([w, -x, -y, -z], (n, 1))  # the inverse rotation


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix [3, 3] (Shepperd's method)."""
    t = np.trace(R)
    i = int(np.argmax([t, R[0, 0], R[1, 1], R[2, 2]]))
    if i == 0:
        w = 0.5 * np.sqrt(1 + t)
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
    else:
        a, b, c = (i - 1, i % 3, (i + 1) % 3)
        r = 0.5 * np.sqrt(1 + R[a, a] - R[b, b] - R[c, c])
        v = np.zeros(3)
        v[a], v[b], v[c] = r, (R[b, a] + R[a, b]) / (4 * r), (R[c, a] + R[a, c]) / (4 * r)
        q = [(R[c, b] - R[b, c]) / (4 * r), *v]
    return np.array(q)


def _exact_rotation(rng: np.random.Generator) -> np.ndarray:
    """A random signed permutation matrix with det +1: rotating by it is exact in float32."""
    R = np.eye(3)[rng.permutation(3)] * rng.choice([-1.0, 1.0], 3)[:, None]
    if np.linalg.det(R) < 0:
        R[2] = -R[2]
    return R


def _view(rng: np.random.Generator, centres=CENTRES, exact: bool = False) -> _View:
    """A random camera; ``exact``: axis-aligned at the origin, so camera coordinates
    survive the round trip to the world and back bit for bit."""
    W, H = SIZES[rng.integers(len(SIZES))]
    fx = W * rng.uniform(0.8, 1.5)
    fy = fx * rng.uniform(0.9, 1.1)
    cx = W / 2 + rng.uniform(-0.15, 0.15) * W
    cy = H / 2 + rng.uniform(-0.15, 0.15) * H
    if exact:
        R = _exact_rotation(rng)
        q = matrix_to_quat(R)
        centre = np.zeros(3)
    else:
        q = random_unit_quats(rng, 1)[0]
        R = quat_to_rotmat(q)
        centre = np.array(centres[rng.integers(len(centres))])
    w2c = np.eye(4)
    w2c[:3, :3] = R
    w2c[:3, 3] = -R @ centre
    return _View(Camera(W, H, fx, fy, cx, cy, w2c, near=NEAR), q)


def _count(rng: np.random.Generator) -> int:
    return int(COUNTS[rng.integers(len(COUNTS))])


def _in_view(rng: np.random.Generator, cam: Camera, n: int, depth=(2.0, 6.0), spill=0.1) -> np.ndarray:
    """[n, 3] camera-space points whose centres project onto the image (give or take ``spill``)."""
    z = rng.uniform(*depth, n)
    u = rng.uniform(-spill * cam.width, (1 + spill) * cam.width, n)
    v = rng.uniform(-spill * cam.height, (1 + spill) * cam.height, n)
    return camera_points(cam, u, v, z)


def _pixel_log_scales(rng: np.random.Generator, cam: Camera, z: np.ndarray, sigma_px=(0.5, 6.0)) -> np.ndarray:
    """[n, 3] log-scales giving a 1-sigma screen size log-uniform on ``sigma_px`` pixels."""
    sigma = np.exp(rng.uniform(np.log(sigma_px[0]), np.log(sigma_px[1]), len(z)))
    return np.log(world_sigma(cam, sigma, z))[:, None] + 0.25 * rng.standard_normal((len(z), 3))


def _sh(rng: np.random.Generator, n: int) -> np.ndarray:
    k = (int(SH_DEGREES[rng.integers(len(SH_DEGREES))]) + 1) ** 2
    return np.concatenate([0.6 * rng.standard_normal((n, 1, 3)), 0.1 * rng.standard_normal((n, k - 1, 3))], 1)


def _subset(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random boolean mask [n] with at least one entry set."""
    mask = rng.random(n) < rng.uniform(0.3, 1.0)
    mask[rng.integers(n)] = True
    return mask


def _case(category: str, seed: int, view: _View, cam_pts: np.ndarray, log_scales: np.ndarray,
          quats: np.ndarray, logits: np.ndarray, sh: np.ndarray, **options) -> StressCase:
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return StressCase(f32(to_world(view.camera, cam_pts)), f32(log_scales), f32(quats), f32(logits), f32(sh),
                      view.camera, category=category, seed=seed, options=RasterOptions(**options))


def _base(category: str, seed: int, rng: np.random.Generator, n: int | None = None, centres=CENTRES,
          **options) -> StressCase:
    """An ordinary scene: in view, pixel-sized, random rotations and opacities."""
    view = _view(rng, centres)
    n = _count(rng) if n is None else n
    cam_pts = _in_view(rng, view.camera, n)
    return _case(category, seed, view, cam_pts, _pixel_log_scales(rng, view.camera, cam_pts[:, 2]),
                 random_unit_quats(rng, n), rng.normal(0.0, 2.0, n), _sh(rng, n), **options)


# ---------------------------------------------------------------- categories
def zero_quats(seed: int) -> StressCase:
    """Some quaternions exactly zero (or -0): conventions.md maps them to R = I."""
    rng = np.random.default_rng(seed)
    case = _base("zero_quats", seed, rng)
    q = case.quats.copy()
    mask = _subset(rng, case.n)
    q[mask] = np.where(rng.random((int(mask.sum()), 4)) < 0.5, -0.0, 0.0)
    return dataclasses.replace(case, quats=q)


def tiny_quats(seed: int) -> StressCase:
    """Nonzero quaternions of length 1e-45..1e-19 (denormals included): q / |q| is
    still a rotation, though 1/|q| or 1/|q|^2 overflows float32 on the way."""
    rng = np.random.default_rng(seed)
    case = _base("tiny_quats", seed, rng)
    q = case.quats.astype(np.float64)
    for i in np.flatnonzero(_subset(rng, case.n)):
        if rng.random() < 0.3:  # some components exactly zero
            q[i, rng.permutation(4)[:int(rng.integers(1, 4))]] = 0.0
        q[i] *= 10.0 ** rng.uniform(-45, -19) / max(np.abs(q[i]).max(), 1e-300)
    return dataclasses.replace(case, quats=q.astype(np.float32))


def huge_quats(seed: int) -> StressCase:
    """Quaternion components of magnitude 1e20..1e30, alone or beside tiny/zero/unit ones."""
    rng = np.random.default_rng(seed)
    case = _base("huge_quats", seed, rng)
    q = case.quats.astype(np.float64)
    for i in np.flatnonzero(_subset(rng, case.n)):
        huge = rng.choice([-1.0, 1.0], 4) * 10.0 ** rng.uniform(20, 30, 4)
        kind = rng.integers(4)
        if kind == 0:    # all four huge
            q[i] = huge
        elif kind == 1:  # one huge, the rest of order one
            q[i, rng.integers(4)] = huge[0]
        elif kind == 2:  # one huge, the rest tiny or zero
            q[i] = rng.choice([0.0, 1e-30, -1e-30], 4)
            q[i, rng.integers(4)] = huge[0]
        else:            # the largest float32 magnitudes
            q[i] = rng.choice([-1.0, 1.0], 4) * rng.uniform(1e37, 3.4e38, 4)
    return dataclasses.replace(case, quats=q.astype(np.float32))


def extreme_scales(seed: int) -> StressCase:
    """Log-scales anywhere in [-30, 30], including the clip bounds (+-20) and beyond."""
    rng = np.random.default_rng(seed)
    case = _base("extreme_scales", seed, rng)
    s = case.log_scales.copy()
    mask = _subset(rng, case.n)
    m = int(mask.sum())
    picks = np.where(rng.random((m, 3)) < 0.3, rng.choice([-30.0, -20.0, -19.99, 19.99, 20.0, 30.0], (m, 3)),
                     rng.uniform(-30, 30, (m, 3)))
    s[mask] = picks
    return dataclasses.replace(case, log_scales=s)


def needles(seed: int) -> StressCase:
    """Aspect ratios up to 1e6: one long axis (needle) or one short axis (disc)."""
    rng = np.random.default_rng(seed)
    view = _view(rng)
    n = _count(rng)
    cam_pts = _in_view(rng, view.camera, n)
    short = np.log(world_sigma(view.camera, np.exp(rng.uniform(np.log(0.05), np.log(3.0), n)), cam_pts[:, 2]))
    ratio = np.log(10.0) * rng.uniform(0, 6, n)
    disc = rng.random(n) < 0.4
    s = np.repeat(short[:, None], 3, axis=1)
    long_axis = rng.integers(3, size=n)
    s[np.arange(n), long_axis] += ratio                # needle: one axis long
    s[disc] += ratio[disc, None]                       # disc: two axes long ...
    s[disc, long_axis[disc]] -= ratio[disc]            # ... and the picked one short
    aligned = rng.random(n) < 0.3                      # axes along the camera's: needles seen end-on
    quats = np.where(aligned[:, None], view.aligned_quats(n), random_unit_quats(rng, n))
    return _case("needles", seed, view, cam_pts, s, quats, rng.normal(0.0, 2.0, n), _sh(rng, n))


def near_plane(seed: int) -> StressCase:
    """Depths on, just beside, and behind the near plane; at z = 0; exactly at the camera
    centre. Half the cameras are axis-aligned at the origin, so these depths are exact."""
    rng = np.random.default_rng(seed)
    view = _view(rng, exact=bool(rng.random() < 0.5))
    cam = view.camera
    n = _count(rng)
    near32 = np.float32(NEAR)
    menu = np.array([NEAR, near32, np.nextafter(near32, np.float32(1)), np.nextafter(near32, np.float32(0)),
                     NEAR * (1 - 1e-7), 0.0, 1e-30, -1e-30, -NEAR, 2 * NEAR, 0.05])
    z = np.where(rng.random(n) < 0.6, rng.choice(menu, n), rng.uniform(-1.0, 0.1, n))
    cam_pts = _in_view(rng, cam, n)
    cam_pts[:, :2] *= (z / cam_pts[:, 2])[:, None]  # keep the same pixel: x, y shrink with z
    cam_pts[:, 2] = z
    cam_pts[rng.random(n) < 0.2] = 0.0                # exactly at the camera centre
    log_scales = np.log(10.0) * rng.uniform(-6, 1, (n, 1)) + 0.5 * rng.standard_normal((n, 3))
    case = _case("near_plane", seed, view, cam_pts, log_scales, random_unit_quats(rng, n),
                 rng.normal(0.0, 2.0, n), _sh(rng, n))
    # The world transform rounds: put the centre cases on the camera centre exactly.
    at_centre = np.all(cam_pts == 0.0, axis=1)
    means = case.means.copy()
    means[at_centre] = cam.center.astype(np.float32)
    return dataclasses.replace(case, means=means)


def far_coords(seed: int) -> StressCase:
    """Camera and Gaussians 1e4 units from the origin (float32 keeps ~1e-3 there)."""
    rng = np.random.default_rng(seed)
    return _base("far_coords", seed, rng, centres=FAR_CENTRES)


def singular_cov(seed: int) -> StressCase:
    """Near-singular 2D covariances: eps2d = 0 with flat, needle or point Gaussians,
    some seen exactly edge-on; antialiasing on or off."""
    rng = np.random.default_rng(seed)
    view = _view(rng)
    n = _count(rng)
    cam_pts = _in_view(rng, view.camera, n)
    s = _pixel_log_scales(rng, view.camera, cam_pts[:, 2], sigma_px=(0.3, 4.0))
    tiny = rng.uniform(-30.0, -12.0, (n, 3))
    kind = rng.integers(4, size=n)  # 0: disc (one tiny axis), 1: needle (two), 2: point (three), 3: ordinary
    for i in range(n):
        axes = rng.permutation(3)[:[1, 2, 3, 0][kind[i]]]
        s[i, axes] = tiny[i, axes]
    aligned = rng.random(n) < 0.5  # axes along the camera's: a disc seen edge-on projects to a segment
    quats = np.where(aligned[:, None], view.aligned_quats(n), random_unit_quats(rng, n))
    eps2d = 0.0 if rng.random() < 0.75 else 0.3
    return _case("singular_cov", seed, view, cam_pts, s, quats, rng.normal(1.0, 3.0, n), _sh(rng, n),
                 eps2d=eps2d, antialiased=bool(rng.random() < 0.5))


def stacked(seed: int) -> StressCase:
    """A thousand nearly opaque Gaussians at one spot (equal depths: ties), opacity
    logits up to +30; some cases let transmittance underflow (no early stop)."""
    rng = np.random.default_rng(seed)
    view = _view(rng)
    cam = view.camera
    n = STACK
    spot = _in_view(rng, cam, 1, spill=-0.2)
    cam_pts = np.repeat(spot, n, axis=0)
    s = _pixel_log_scales(rng, cam, cam_pts[:, 2], sigma_px=(1.0, 10.0))
    if rng.random() < 0.5:
        s[:] = s[0]  # identical Gaussians
    logits = np.where(rng.random(n) < 0.2, 30.0, rng.uniform(4.0, 30.0, n))
    options = [{}, {"transmittance_min": 0.0}, {"transmittance_min": 0.0, "alpha_max": 1.0 - 1e-6}]
    return _case("stacked", seed, view, cam_pts, s, random_unit_quats(rng, n), logits, _sh(rng, n),
                 **options[rng.integers(len(options))])


FINITE_BUILDERS: dict[str, Callable[[int], StressCase]] = {
    "zero_quats": zero_quats,
    "tiny_quats": tiny_quats,
    "huge_quats": huge_quats,
    "extreme_scales": extreme_scales,
    "needles": needles,
    "near_plane": near_plane,
    "far_coords": far_coords,
    "singular_cov": singular_cov,
    "stacked": stacked,
}


def nonfinite(seed: int, field: str | None = None) -> StressCase:
    """NaN, +Inf or -Inf at one random entry of one field (``field``, or a random one),
    on top of a scene of any finite category."""
    rng = np.random.default_rng(seed)
    inner = list(FINITE_BUILDERS)[rng.integers(len(FINITE_BUILDERS))]
    case = FINITE_BUILDERS[inner](int(rng.integers(2**63)))
    field = FIELDS[rng.integers(len(FIELDS))] if field is None else field
    array = getattr(case, field).copy()
    array.reshape(-1)[rng.integers(array.size)] = rng.choice([np.nan, np.inf, -np.inf])
    return dataclasses.replace(case, category="nonfinite", seed=seed, nonfinite_field=field, **{field: array})


BUILDERS: dict[str, Callable[[int], StressCase]] = {**FINITE_BUILDERS, "nonfinite": nonfinite}
CATEGORIES: tuple[str, ...] = tuple(BUILDERS)


def build_case(category: str, seed: int) -> StressCase:
    """The case ``seed`` of ``category`` (one of `CATEGORIES`); deterministic."""
    if category not in BUILDERS:
        raise InputError(f"category: expected one of {', '.join(CATEGORIES)}, got {category!r}")
    return BUILDERS[category](seed)
