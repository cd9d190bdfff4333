"""The probe scenes of `splatbench conform`: a few Gaussians each, 16x16 to 32x32 pixels (hand-made
probe scenes, one of the five kinds of "scene": docs/architecture.md).

Each scene isolates one convention or one classic bug (see `probes` for what each checks).
Scenes are built so that the approximations a probe does not test cannot matter: outside
the early-stop and radius scenes, every opacity is below 0.35 (so alpha < 1/255 beyond
3 sigma: the radius rule never decides a pixel) or every Gaussian covers the whole image
within 3 sigma; transmittance stays far above 1e-4; no pixel sits near a discrete decision
(tests/test_conform.py checks the margins). So a dense renderer that follows every 3DGS
convention but has no radius cutoff, no tiles and no early termination passes them all.
"""

from __future__ import annotations

import functools

import numpy as np

from splatbench.cameras import Camera
from splatbench.conventions import SH_C0
from splatbench.render_inputs import RenderInput, logit, point_at, sh_dc, world_sigma
from splatbench.workloads import random_unit_quats


# ----------------------------------------------------------------------------
# Scene building blocks (those every verification application uses: `splatbench.render_inputs`)
# ----------------------------------------------------------------------------

def camera(width: int = 16, height: int = 16, **kw) -> Camera:
    """An oblique camera looking at the origin (world z is not camera z, world x is not camera x)."""
    return Camera.look_at(eye=[1.6, -1.1, -4.0], target=[0.0, 0.0, 0.0], up=[0.0, -1.0, 0.0],
                          width=width, height=height, fov_x_deg=60.0, **kw)


def scene(cam: Camera, means, sigma_px, opacity, sh, *, z=None, quats=None, seed=0, background=None,
          sh_degree=None) -> RenderInput:
    """A probe scene (`RenderInput`) from screen-space sizes: sigma_px [N] or [N, 3] pixels at each
    Gaussian's depth (per axis for anisotropic ones), opacity [N] in (0, 1); values rounded to float32
    (held in float64 arrays)."""
    means = np.asarray(means, dtype=np.float64)
    n = means.shape[0]
    depth = (means @ cam.rotation.T + cam.translation)[:, 2] if z is None else np.asarray(z, dtype=np.float64)
    sig = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64).reshape(n, -1), (n, 3))
    log_scales = np.log(world_sigma(cam, sig, depth[:, None]))
    quats = random_unit_quats(np.random.default_rng(seed), n) if quats is None else np.asarray(quats, dtype=np.float64)
    f32 = lambda a: np.asarray(a, dtype=np.float32).astype(np.float64)  # noqa: E731
    return RenderInput(f32(means), f32(log_scales), f32(quats), f32(logit(opacity)), f32(sh), cam,
                      background, sh_degree)


def _grid(cam: Camera, cols: int, rows: int, z: float, margin: float = 3.5) -> np.ndarray:
    us = np.linspace(margin, cam.width - margin, cols)
    vs = np.linspace(margin, cam.height - margin, rows)
    return np.array([point_at(cam, u + 0.17 * (i % 2), v, z + 0.3 * i) for i, (v, u) in
                     enumerate((v, u) for v in vs for u in us)])


def _sh_band(degree: int, n: int, seed: int, *, only_band: bool = True) -> np.ndarray:
    """SH [n, (degree+1)^2, 3]: DC a mid grey, band ``degree`` random (others zero unless not only_band)."""
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    sh = rng.uniform(-0.25, 0.25, size=(n, k, 3))
    sh[:, 0, :] = rng.uniform(-0.3, 0.3, size=(n, 3))
    if only_band:
        sh[:, 1:degree ** 2, :] = 0.0
    return sh


# ----------------------------------------------------------------------------
# The scenes
# ----------------------------------------------------------------------------

@functools.cache
def basic_centred() -> RenderInput:
    # One anisotropic Gaussian near the image centre, degree-1 SH: pixel centre, activations,
    # rotation, SH basis all act on it, and nothing else (no sort, no background).
    cam = camera(12, 12)
    means = np.array([point_at(cam, 6.2, 5.7, 4.0)])
    sh = np.zeros((1, 4, 3))
    sh[0, 0] = (np.array([0.8, 0.5, 0.3]) - 0.5) / SH_C0
    sh[0, 1:] = [[0.3, -0.2, 0.1], [-0.1, 0.25, 0.2], [0.2, 0.1, -0.3]]
    return scene(cam, means, [[2.4, 1.3, 1.8]], [0.33], sh, z=np.array([4.0]), seed=31)


@functools.cache
def basic_overlap() -> RenderInput:
    # Two overlapping translucent Gaussians over a coloured background: compositing order, transmittance
    # and the background's weight. Listed far first; the nearer in camera z (off axis) is the farther
    # from the camera centre (4.36 against 4.30), so a sort on distance gets the order wrong too.
    cam = camera(12, 12)
    z = np.array([4.3, 4.0])
    means = np.array([point_at(cam, 5.5, 6.3, 4.3), point_at(cam, 1.5, 6.0, 4.0)])
    return scene(cam, means, [2.6, 2.0], [0.32, 0.3], sh_dc([(0.2, 0.3, 0.9), (0.9, 0.4, 0.1)]), z=z, seed=32,
                 background=(0.1, 0.6, 0.3))


@functools.cache
def basic_offaxis() -> RenderInput:
    # A camera far from the world origin, looking away from it, degree-1 SH on three Gaussians: the SH
    # view direction, world vs camera axes.
    cam = Camera.look_at(eye=[4.0, -3.0, -2.0], target=[5.0, -1.5, 2.0], up=[0.0, -1.0, 0.0], width=12,
                         height=12, fov_x_deg=60.0)
    means = _grid(cam, 3, 1, 4.0, margin=3.0)
    sh = _sh_band(1, 3, 33)
    sh[:, 1:, :] *= 2.0
    return scene(cam, means, [1.5] * 3, [0.33] * 3, sh, seed=33)


@functools.cache
def depth_order() -> RenderInput:
    # The camera looks along world x: listed far to near (index order is wrong), and world z
    # and a strided read of the camera points [x0 y0 z0 x1 ...] give two other wrong orders.
    cam = Camera.look_at(eye=[-4.0, -1.1, 1.6], target=[0.0, 0.0, 0.0], up=[0.0, -1.0, 0.0], width=16,
                         height=16, fov_x_deg=60.0)
    z = np.array([6.0, 3.2, 5.1, 4.0])
    uv = [(9.0, 7.0), (7.0, 9.5), (8.5, 8.0), (6.5, 7.5)]
    means = np.array([point_at(cam, u, v, zi) for (u, v), zi in zip(uv, z)])
    colours = [(0.9, 0.1, 0.1), (0.1, 0.9, 0.2), (0.1, 0.2, 0.9), (0.9, 0.8, 0.1)]
    return scene(cam, means, [7.0, 6.5, 7.5, 6.0], [0.7, 0.6, 0.65, 0.55], sh_dc(colours), z=z, seed=1)


@functools.cache
def pixel_centre() -> RenderInput:
    cam = camera()
    z = np.array([4.0, 4.5])
    means = np.array([point_at(cam, 7.3, 8.6, 4.0), point_at(cam, 11.8, 4.1, 4.5)])
    return scene(cam, means, [1.3, 1.1], [0.32, 0.3], sh_dc([(0.9, 0.6, 0.2), (0.2, 0.7, 0.9)]), z=z,
                 quats=[[1, 0, 0, 0]] * 2)


def _anisotropic(quat_scale=None) -> RenderInput:
    cam = camera()
    z = np.array([4.0, 4.6])
    means = np.array([point_at(cam, 6.23, 7.1, 4.0), point_at(cam, 10.43, 9.3, 4.6)])
    quats = np.array([[0.82, 0.31, -0.42, 0.25], [0.35, -0.6, 0.2, 0.69]])
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    if quat_scale is not None:
        quats = quats * np.asarray(quat_scale)[:, None]
    return scene(cam, means, [[4.0, 1.2, 2.0], [3.2, 2.4, 0.9]], [0.33, 0.3],
                 sh_dc([(0.9, 0.3, 0.2), (0.2, 0.5, 0.9)]), z=z, quats=quats)


@functools.cache
def quat_order() -> RenderInput:
    return _anisotropic()


@functools.cache
def quat_norm() -> RenderInput:
    return _anisotropic(quat_scale=[2.7, 0.45])


@functools.cache
def scale_activation() -> RenderInput:
    cam = camera()
    z = np.array([4.0, 5.0])
    means = np.array([point_at(cam, 6.0, 6.5, 4.0), point_at(cam, 10.5, 10.0, 5.0)])
    return scene(cam, means, [1.6, 2.2], [0.3, 0.32], sh_dc([(0.8, 0.3, 0.3), (0.3, 0.8, 0.4)]), z=z, seed=3)


@functools.cache
def opacity_activation() -> RenderInput:
    cam = camera()
    z = np.array([4.0, 4.4])
    means = np.array([point_at(cam, 7.0, 6.0, 4.0), point_at(cam, 9.5, 10.0, 4.4)])
    return scene(cam, means, [2.5, 2.2], [0.31, 0.18], sh_dc([(0.8, 0.7, 0.2), (0.2, 0.4, 0.9)]), z=z, seed=4)


@functools.cache
def eps2d() -> RenderInput:
    cam = camera()
    # Far below a pixel: the footprint is the eps2d low-pass alone (sigma ~ sqrt(0.3) px).
    z = np.array([4.0, 4.2])
    means = np.array([point_at(cam, 5.5, 6.5, 4.0), point_at(cam, 10.5, 9.5, 4.2)])
    return scene(cam, means, [0.01, 0.02], [0.6, 0.5], sh_dc([(0.9, 0.9, 0.2), (0.2, 0.9, 0.9)]), z=z, seed=5)


@functools.cache
def jacobian_clamp() -> RenderInput:
    cam = camera()
    # Centres beyond graphdeco's 1.3 x half-FoV limit (u < -0.15 W), footprints reaching into the image.
    z = np.array([4.0, 4.5])
    means = np.array([point_at(cam, -0.45 * cam.width, 6.0, 4.0), point_at(cam, 1.45 * cam.width, 11.0, 4.5)])
    return scene(cam, means, [[9.0, 2.0, 8.0], [8.0, 3.0, 9.0]], [0.33, 0.3],
                 sh_dc([(0.9, 0.4, 0.2), (0.3, 0.5, 0.9)]), z=z, seed=6)


@functools.cache
def near_plane() -> RenderInput:
    cam = camera(near=1.0)
    # In front of the camera but before camera.near (culled), behind the camera (culled), and a backdrop.
    z = np.array([0.6, -2.0, 4.0])
    means = np.array([point_at(cam, 8.2, 7.6, 0.6), point_at(cam, 8.0, 8.0, -2.0), point_at(cam, 8.0, 8.0, 4.0)])
    return scene(cam, means, [2.0, 2.0, 7.0], [0.33, 0.33, 0.3],
                 sh_dc([(0.9, 0.1, 0.1), (0.1, 0.9, 0.1), (0.3, 0.3, 0.8)]), z=np.abs(z), seed=7)


@functools.cache
def alpha_max() -> RenderInput:
    cam = camera()
    # An opaque, very wide Gaussian: its raw alpha exceeds 0.99 (clamped) near its centre and
    # stays below 0.999 (gsplat's clamp) everywhere; a translucent one behind it shows through
    # T = 0.01. Opacity 0.998 rather than closer to 1: sigmoid'(logit) = o (1 - o) loses
    # u / (1 - o) relative precision in float32.
    z = np.array([4.0, 5.0])
    means = np.array([point_at(cam, 8.14, 8.3, 4.0), point_at(cam, 8.5, 7.5, 5.0)])
    return scene(cam, means, [[30.0, 22.0, 26.0], [7.0, 5.0, 6.0]], [0.998, 0.5],
                 sh_dc([(0.9, 0.5, 0.2), (0.1, 0.6, 0.9)]), z=z,
                 seed=8)


@functools.cache
def alpha_min() -> RenderInput:
    cam = camera()
    # A faint wide Gaussian (opacity 0.003 < 1/255: skipped everywhere) and a faint one whose
    # alpha crosses 1/255 inside the image.
    z = np.array([4.0, 4.5])
    means = np.array([point_at(cam, 8.0, 8.0, 4.0), point_at(cam, 9.3, 7.2, 4.5)])
    return scene(cam, means, [8.0, 2.6], [0.003, 0.02], sh_dc([(0.9, 0.9, 0.9), (0.9, 0.2, 0.6)]), z=z, seed=9)


def _sh_scene(degree: int, seed: int, *, sh_degree=None, full=False) -> RenderInput:
    cam = camera()
    means = _grid(cam, 3, 2, 4.0)
    return scene(cam, means, [1.4] * 6, [0.33] * 6, _sh_band(degree, 6, seed, only_band=not full), seed=seed,
                 sh_degree=sh_degree)


@functools.cache
def sh_degree1() -> RenderInput:
    return _sh_scene(1, 11)


@functools.cache
def sh_degree2() -> RenderInput:
    return _sh_scene(2, 12)


@functools.cache
def sh_degree3() -> RenderInput:
    return _sh_scene(3, 13)


@functools.cache
def sh_degree_arg() -> RenderInput:
    return _sh_scene(3, 14, sh_degree=1, full=True)


@functools.cache
def sh_viewdir() -> RenderInput:
    # Degree 1 only, camera far from the world origin: mean - camera centre, not mean - origin.
    cam = Camera.look_at(eye=[5.0, -2.0, -3.0], target=[4.0, -1.0, 1.0], up=[0.0, -1.0, 0.0], width=16,
                         height=16, fov_x_deg=60.0)
    means = _grid(cam, 3, 2, 4.0)
    sh = _sh_band(1, 6, 15)
    sh[:, 1:, :] *= 2.0
    return scene(cam, means, [1.4] * 6, [0.33] * 6, sh, seed=15)


@functools.cache
def sh_viewdir_grad() -> RenderInput:
    # Strong degree-1 colour on wide Gaussians: a good share of d/dmeans flows through the
    # view direction of the SH evaluation.
    cam = camera()
    z = np.array([3.0, 3.6, 4.2])
    means = np.array([point_at(cam, 7.0, 7.5, 3.0), point_at(cam, 9.5, 8.0, 3.6), point_at(cam, 8.0, 9.5, 4.2)])
    sh = np.zeros((3, 4, 3))
    sh[:, 0, :] = (0.9 - 0.5) / SH_C0  # colours stay in (0.1, 1.7): the clamp at 0 never cuts the SH path
    sh[:, 1:, :] = np.random.default_rng(16).choice([-1.0, 1.0], size=(3, 3, 3)) * 0.9
    return scene(cam, means, [7.0, 6.5, 7.5], [0.45, 0.4, 0.5], sh, z=z, seed=16)


@functools.cache
def colour_clamp() -> RenderInput:
    cam = camera()
    # SH colours below 0 (clamped to 0) and above 1 (not clamped) in some channels.
    z = np.array([4.0, 4.5])
    means = np.array([point_at(cam, 6.5, 7.0, 4.0), point_at(cam, 10.0, 9.5, 4.5)])
    return scene(cam, means, [2.5, 3.0], [0.33, 0.3], sh_dc([(-0.4, 0.6, 1.3), (1.4, -0.3, 0.5)]), z=z, seed=25)


@functools.cache
def background() -> RenderInput:
    cam = camera()
    z = np.array([4.0, 4.5])
    means = np.array([point_at(cam, 6.5, 7.0, 4.0), point_at(cam, 10.0, 9.5, 4.5)])
    return scene(cam, means, [2.5, 3.0], [0.33, 0.3], sh_dc([(0.9, 0.2, 0.2), (0.2, 0.2, 0.9)]), z=z, seed=17,
                 background=(0.2, 0.5, 0.9))


@functools.cache
def expected_depth() -> RenderInput:
    cam = camera()
    # Translucent, at different depths, off the optical axis (distance != camera z).
    z = np.array([3.0, 5.0, 7.0])
    means = np.array([point_at(cam, 4.5, 5.0, 3.0), point_at(cam, 10.5, 6.0, 5.0), point_at(cam, 8.0, 11.0, 7.0)])
    return scene(cam, means, [3.0, 3.5, 3.0], [0.33, 0.3, 0.32], sh_dc([(0.6, 0.6, 0.6)] * 3), z=z, seed=18)


@functools.cache
def intrinsics() -> RenderInput:
    base = camera(24, 16)
    cam = Camera(24, 16, 19.0, 13.0, 10.3, 9.1, base.world_to_camera)
    z = np.array([4.0, 4.5, 5.0])
    means = np.array([point_at(cam, 5.0, 5.0, 4.0), point_at(cam, 18.5, 6.0, 4.5), point_at(cam, 11.0, 12.0, 5.0)])
    return scene(cam, means, [1.6, 1.8, 2.0], [0.33, 0.3, 0.32],
                 sh_dc([(0.9, 0.3, 0.2), (0.2, 0.9, 0.3), (0.3, 0.2, 0.9)]), z=z, seed=19)


@functools.cache
def tiles() -> RenderInput:
    cam = camera(32, 32)
    # Centres on tile corners and edges (tiles of 16 and 8): each footprint spans several tiles.
    z = np.array([4.0, 4.3, 4.6])
    means = np.array([point_at(cam, 16.0, 16.0, 4.0), point_at(cam, 8.0, 23.5, 4.3), point_at(cam, 24.5, 8.0, 4.6)])
    return scene(cam, means, [3.0, 2.5, 2.5], [0.33, 0.3, 0.32],
                 sh_dc([(0.9, 0.3, 0.2), (0.2, 0.9, 0.3), (0.3, 0.2, 0.9)]), z=z, seed=20)


@functools.cache
def gradients() -> RenderInput:
    cam = camera()
    # Three wide, overlapping, anisotropic Gaussians covering the image within 3 sigma
    # (no pixel near a cutoff, alpha_min or the early stop), SH degree 1. Opacity 0.5 is a
    # logit of exactly 0, where a sigmoid written with |x| loses its derivative.
    z = np.array([3.5, 4.0, 4.6])
    means = np.array([point_at(cam, 7.0, 7.5, 3.5), point_at(cam, 9.0, 8.0, 4.0), point_at(cam, 8.0, 9.0, 4.6)])
    sh = _sh_band(1, 3, 21)
    return scene(cam, means, [[9.0, 6.0, 7.0], [7.0, 9.5, 6.0], [8.0, 8.0, 6.5]], [0.5, 0.45, 0.55], sh, z=z,
                 seed=21)


@functools.cache
def conic() -> RenderInput:
    cam = camera()
    # Elongated and rotated on screen, so all of A, B and C matter; wide enough to cover the image.
    z = np.array([4.0, 4.5])
    means = np.array([point_at(cam, 7.5, 8.0, 4.0), point_at(cam, 8.5, 8.5, 4.5)])
    return scene(cam, means, [[12.0, 5.0, 6.0], [6.0, 11.0, 5.0]], [0.5, 0.45],
                 sh_dc([(0.9, 0.4, 0.2), (0.2, 0.5, 0.9)]), z=z, seed=22)


@functools.cache
def early_stop() -> RenderInput:
    cam = camera()
    # Three near-opaque, very wide layers: T is 2e-4 to 6e-4 after two and below 2e-5 after the
    # third everywhere in the image (far from 1e-4), so the third is never composited.
    z = np.array([3.0, 4.0, 5.0])
    means = np.array([point_at(cam, 8.0, 8.0, 3.0), point_at(cam, 8.3, 7.8, 4.0), point_at(cam, 7.7, 8.2, 5.0)])
    return scene(cam, means, [80.0, 80.0, 80.0], [0.985, 0.985, 0.985],
                 sh_dc([(0.9, 0.2, 0.2), (0.2, 0.9, 0.2), (0.2, 0.2, 0.9)]), z=z, seed=23)


@functools.cache
def radius() -> RenderInput:
    cam = camera(32, 32)
    # Opacity 0.98: alpha is still 0.011 > 1/255 at 3 sigma (12 px), so the radius rule decides a
    # ring of pixels out to 3.32 sigma; the 3-sigma box stops just short of the next 16-pixel tiles,
    # so a tile-granular rule (graphdeco's) draws part of that ring and not the rest.
    z = np.array([4.0])
    means = np.array([point_at(cam, 3.71, 3.87, 4.0)])
    return scene(cam, means, [3.95], [0.98], sh_dc([(0.9, 0.8, 0.2)]), z=z, seed=24)
