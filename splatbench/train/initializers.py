"""Initial Gaussians for training, by name (`TrainConfig.init`).

`INITIALIZERS` maps a name to a function ``(dataset, settings) -> Gaussians`` (or an
`Initialization`, to report how the points were made); a new method plugs in with
`register_init`::

    @register_init("mast3r")
    def mast3r(dataset, settings): ...

Built in (every one seeded by `splatbench.gaussians_from_points.from_points`: 3-NN scales,
opacity ``settings.opacity``, DC colour from the point colour):

* ``auto`` (the default) -- the dataset's own points when it has them (``surface``),
  else SfM with the dataset's known poses (``sfm``); never random unless asked. The
  summary's ``method`` is what ran, ``asked`` is ``"auto"``, and a note says which.
* ``surface`` -- the dataset's own point cloud (`Dataset.points`): samples of the true
  surfaces for a scene rendered by ``splatbench scenes``, ``points3D`` for a COLMAP
  folder, ``ply_file_path`` for the Blender layout. A dataset without points is one
  `InputError` line (use ``auto``, ``sfm`` or ``random``).
* ``sfm`` -- pycolmap on the **training** views only, as the dataset serves them
  (undistorted, downscaled), with its PINHOLE cameras: SIFT and exhaustive matching,
  then (``settings.sfm_poses = "known"``, the default) COLMAP's point triangulator with
  the dataset's poses and intrinsics held fixed, or (``"estimated"``) incremental mapping
  aligned to the dataset's frame by a similarity on the camera centres
  (`splatbench.sfm.run_sfm`). Cached by content in ``$SPLATBENCH_CACHE/sfm/<hash>``
  (`splatbench.sfm.cached_sfm`), never in the dataset folder. SfM's seed is
  ``settings.sfm_seed`` (0: one model per dataset, as a capture has one COLMAP model).
  Fails (one `InputError` line) where SIFT finds too few matches: textureless or tiny
  images, views too far apart.
* ``random`` -- ``settings.random_points`` points uniform in a region (`REGIONS`,
  `random_region`) with uniform random colours, drawn with the run's seed.

The start varies with the run's seed (``settings.seed``): ``random`` draws its points
with it, and the given points of ``surface`` / ``sfm`` are jittered by
``settings.jitter`` times each point's neighbour spacing (`jitter_points`), so a rerun
with another seed starts from other points, and the same seed from the same points.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from splatbench.errors import InputError
from splatbench.gaussians import Gaussians
from splatbench.gaussians_from_points import from_points, knn_mean_sq_dist

#: Where ``init = "random"`` samples (`random_region`):
#:
#: * ``convergence`` -- a ball around the point nearest every optical axis
#:   (`splatbench.sfm.axes_meeting_point`), of radius ``d tan(fov / 2)``: ``d`` the median
#:   distance of the cameras to that point (`splatbench.sfm.rig_radius`), ``fov`` the
#:   narrower field of view of the median camera, so that the ball fills the middle of
#:   every view. For captures whose cameras look inward at the scene (an object turntable,
#:   instant-ngp's fox). It holds the object the cameras look at, not a background farther
#:   away (that is grown from Gaussians at its edge), and it is undefined on a forward-facing
#:   or outward-looking rig (`InputError`).
#: * ``camera_cube`` -- gsplat's ``simple_trainer.py`` rule: a cube of half-side
#:   ``init_extent`` (3) x the scene scale (1.1 x the largest distance of a training camera
#:   from the centroid of the centres, `splatbench.train.params.scene_extent`) around that
#:   centroid. It holds the cameras and whatever lies within ~3 rig sizes of them; its
#:   points are sparse where the scene is (most lie behind or beside the cameras), and on a
#:   forward-facing rig the scene (tens of rig sizes away) is outside it.
#: * ``nerf_synthetic`` -- graphdeco's rule for the Blender layout: uniform in
#:   [-1.3, 1.3]^3 (graphdeco draws 100,000 points there). Right for NeRF-synthetic
#:   scenes (the object at the origin inside that box, cameras on a sphere of radius
#:   ~4); meaningless for a capture in another frame.
#: * ``depth_bounds`` -- spread over the training views' frusta between each view's near
#:   and far depth bounds (LLFF's ``poses_bounds.npy``: the depths its SfM points spanned
#:   in that view): a view drawn uniformly, then a pixel, then a depth uniform in
#:   [near, far]. Needs a dataset with bounds (`Dataset.bounds`).
#: * ``auto`` -- ``nerf_synthetic`` for a Blender-layout dataset with
#:   ``transforms_train.json`` whose axes meet within 0.1 rig radius of the origin with a
#:   rig radius of 2.5..6 (NeRF-synthetic's is 4.03); else ``convergence`` when the
#:   axes meet in front of the cameras; else (a forward-facing rig) ``depth_bounds`` when the
#:   dataset has bounds, else ``camera_cube``, with a note that no region here contains such
#:   a scene. The choice is in the summary.
REGIONS = ("auto", "convergence", "camera_cube", "nerf_synthetic", "depth_bounds")
#: graphdeco's NeRF-synthetic random box: uniform in [-NERF_SYNTHETIC_HALF, +]^3.
NERF_SYNTHETIC_HALF = 1.3


@dataclass(frozen=True)
class InitSettings:
    """What an initializer may use besides the dataset."""

    sh_degree: int        # SH degree of the Gaussians (bands above 0 start at zero)
    opacity: float        # initial opacity in (0, 1)
    random_points: int    # init="random": number of points
    seed: int             # the run's seed: random init's draws, the jitter of given points
    sfm_seed: int = 0     # init="sfm": pycolmap's seed
    say: Callable[[str], None] | None = None  # progress lines as they happen (init="sfm": starting, done)
    region: str = "auto"  # init="random": where (REGIONS)
    extent: float = 3.0   # init="random", region "camera_cube": half-side in scene scales (gsplat's init_extent)
    jitter: float = 0.0   # surface / sfm: seeded displacement of each point, in units of its neighbour spacing
    sfm_poses: str = "known"  # init="sfm": "known" (triangulate with the dataset's poses) or "estimated"
    say_note: bool = True  # `initialize` says the note too (False: a resumed run, whose model is its checkpoint's)


@dataclass(frozen=True)
class Initialization:
    """What `initialize` returns: the Gaussians and how they were made.

    ``summary``: JSON-ready numbers (``method``, ``points``; ``asked`` when it differs from
    ``method``; random: ``region``, ``center``, ``size``; given points: ``jitter``; SfM:
    ``poses``, ``registered``, ``total``, ``center_rmse_rel``, ``cached``); ``note``: one
    line for the train log (None when there is nothing to say); ``warning``: the note is a
    warning (`TrainResult.warnings`: the start is known not to fit the scene)."""

    gaussians: Gaussians
    summary: dict[str, Any] = field(default_factory=dict)
    note: str | None = None
    warning: bool = False


Initializer = Callable[..., "Gaussians | Initialization"]  # (dataset, settings: InitSettings) -> ...
INITIALIZERS: dict[str, Initializer] = {}


def register_init(name: str) -> Callable[[Initializer], Initializer]:
    """Decorator: make ``fn(dataset, settings) -> Gaussians`` available as ``init=name``."""

    def deco(fn: Initializer) -> Initializer:
        INITIALIZERS[name] = fn
        return fn

    return deco


def initialize(name: str, dataset, settings: InitSettings) -> Initialization:
    """The initial Gaussians of method ``name`` and their summary (`InputError` if unknown).
    Its note (which start ``auto`` chose, the SfM result, the random region) goes to
    ``settings.say`` once, as soon as it is made; initializers say only progress lines."""
    if name not in INITIALIZERS:
        raise InputError(f"init: unknown initialisation {name!r} (expected one of: {', '.join(INITIALIZERS)})")
    made = INITIALIZERS[name](dataset, settings)
    init = made if isinstance(made, Initialization) else Initialization(made)
    if init.note and settings.say is not None and settings.say_note:  # said as soon as the start is made, before training
        settings.say(init.note)
    return Initialization(init.gaussians, {"method": name, "points": len(init.gaussians), **init.summary},
                          init.note, init.warning)


# ------------------------------------------------------------------ given points
def jitter_points(xyz: np.ndarray, jitter: float, seed: int) -> np.ndarray:
    """``xyz`` [M, 3] each moved by a normal draw of standard deviation ``jitter`` x its
    neighbour spacing (the root of the mean squared distance to its 3 nearest points, the
    initial scale `from_points` gives it), per axis, seeded by ``seed``. ``jitter = 0``
    returns the points unchanged. [M, 3] float64."""
    pts = np.asarray(xyz, np.float64)
    if jitter == 0 or len(pts) < 2:
        return pts
    spacing = np.sqrt(np.maximum(knn_mean_sq_dist(pts), 0.0))
    rng = np.random.default_rng([int(seed), 0x1A17])  # its own stream: not the random init's draws
    return pts + jitter * spacing[:, None] * rng.standard_normal(pts.shape)


def _from_given(xyz: np.ndarray, rgb: np.ndarray, settings: InitSettings) -> tuple[Gaussians, dict[str, Any]]:
    moved = jitter_points(xyz, settings.jitter, settings.seed)
    gaussians = from_points(moved, rgb, sh_degree=settings.sh_degree, opacity=settings.opacity)
    return gaussians, {"jitter": settings.jitter, "jitter_seed": settings.seed}


@register_init("auto")
def auto(dataset, settings: InitSettings) -> Initialization:
    """The dataset's points when it has them, else SfM with the dataset's poses (never random)."""
    points = dataset.points
    if points is not None and len(points) >= 2:
        init, method, why = surface(dataset, settings), "surface", "the dataset's own points"
    else:
        init, method = sfm(dataset, settings), "sfm"
        have = "no point cloud" if points is None else f"{len(points)} point(s)"
        why = f"SfM with {settings.sfm_poses} poses: the dataset has {have}"
    jittered = f", jittered by {settings.jitter:g} x their spacing with seed {settings.seed}" if settings.jitter else ""
    note = f"init auto: {method} ({why}; {len(init.gaussians)} points{jittered}; init=random for random points)"
    lines = [note] + ([init.note] if init.note else [])
    return Initialization(init.gaussians, {**init.summary, "method": method, "asked": "auto"}, "; ".join(lines))


@register_init("sfm")
def sfm(dataset, settings: InitSettings) -> Initialization:
    """pycolmap on the training views (cached by content): triangulated with the dataset's
    poses (``settings.sfm_poses = "known"``) or mapped and aligned (``"estimated"``)."""
    from splatbench.sfm import cached_sfm

    root = str(dataset.root)
    say = settings.say or (lambda line: None)
    has_points = dataset.points is not None and len(dataset.points) >= 2
    way_out = "use init=surface or init=random" if has_points else "use init=random"
    try:
        run, cached = cached_sfm(dataset, seed=settings.sfm_seed, poses=settings.sfm_poses, say=say)
    except InputError as exc:
        raise InputError(f"init: 'sfm' failed on {root!r}: {exc} ({way_out})") from None
    if len(run.xyz) < 2:
        raise InputError(f"init: 'sfm' on {root!r} triangulated {len(run.xyz)} point(s), need 2 ({way_out})")
    gaussians, jitter = _from_given(run.xyz, run.rgb, settings)
    summary = {"poses": run.poses, "registered": run.registered, "total": run.total,
               "center_rmse_rel": run.center_rmse_rel, "sfm_seconds": round(run.seconds, 3), "cached": cached,
               "model": str(run.model_path), **jitter}
    if run.poses == "known":
        note = (f"SfM: {len(run.xyz)} points triangulated with the dataset's poses, seen by {run.registered}/"
                f"{run.total} training views ({'cached' if cached else 'ran'} in {run.model_path.parent})")
    else:
        note = (f"SfM: {len(run.xyz)} points, {run.registered}/{run.total} training views registered (camera-centre "
                f"RMSE {run.center_rmse_rel:.2%} of the rig radius; {'cached' if cached else 'ran'} in "
                f"{run.model_path.parent})")
    return Initialization(gaussians, summary, note)


@register_init("surface")
def surface(dataset, settings: InitSettings) -> Initialization:
    """The dataset's own points (true-surface samples of a rendered scene; a COLMAP folder's
    points3D; the Blender layout's ply_file_path), jittered by the run's seed."""
    points = dataset.points
    if points is None or len(points) < 2:
        have = "no point cloud" if points is None else f"{len(points)} point(s)"
        raise InputError(f"init: 'surface' needs the dataset's points, but {str(dataset.root)!r} has {have} "
                         f"(use init=auto or init=sfm to triangulate points, or init=random)")
    gaussians, jitter = _from_given(points.xyz, points.rgb, settings)
    return Initialization(gaussians, jitter)


# ------------------------------------------------------------------ random points
@dataclass(frozen=True)
class Region:
    """Where random points are drawn: a ball (``size`` = radius) or an axis-aligned cube
    (``size`` = half-side) around ``center`` [3]; ``chosen`` is the `REGIONS` name, ``note``
    says why when ``auto`` chose it or when it is known not to hold the scene (``warning``)."""

    chosen: str
    shape: str            # "ball", "cube" or "frusta" (``frusta``: each view's frustum between its bounds)
    center: np.ndarray    # [3] float64 (frusta: the mean of the frusta's mid-depth centres)
    size: float           # frusta: the largest far bound
    note: str | None = None
    warning: bool = False  # the note warns: the region is known not to hold such a scene
    frusta: tuple = ()    # shape "frusta": ((camera, near, far), ...)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """[n, 3] float64 points uniform in the region."""
        if self.shape == "frusta":
            pick = rng.integers(0, len(self.frusta), n)
            out = np.empty((n, 3))
            for k, (cam, near, far) in enumerate(self.frusta):
                rows = np.flatnonzero(pick == k)
                u, v = rng.random(len(rows)) * cam.width, rng.random(len(rows)) * cam.height
                z = near + (far - near) * rng.random(len(rows))
                local = np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], 1)
                out[rows] = local @ cam.rotation + cam.center  # camera -> world: R^T x + centre, row-wise
            return out
        if self.shape == "cube":
            return self.center + self.size * (2.0 * rng.random((n, 3)) - 1.0)
        direction = rng.standard_normal((n, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True).clip(1e-12)
        return self.center + self.size * np.cbrt(rng.random((n, 1))) * direction


def random_region(dataset, region: str = "auto", extent: float = 3.0) -> Region:
    """The `Region` ``init = "random"`` samples for ``region`` (one of `REGIONS`) on the
    dataset's training cameras; ``extent``: ``camera_cube``'s half-side in scene scales."""
    from splatbench.sfm import axes_meeting_point, rig_radius
    from splatbench.train.params import scene_extent

    if region not in REGIONS:
        raise InputError(f"init.region: expected one of {', '.join(REGIONS)}, got {region!r}")
    cameras = dataset.train.cameras
    centres = np.stack([c.center for c in cameras]).astype(np.float64)
    meet = axes_meeting_point(cameras) if len(cameras) >= 2 else None
    radius = rig_radius(cameras) if len(cameras) >= 2 else 0.0

    def cube() -> Region:
        return Region("camera_cube", "cube", centres.mean(0), extent * scene_extent(cameras))

    def nerf() -> Region:
        return Region("nerf_synthetic", "cube", np.zeros(3), NERF_SYNTHETIC_HALF)

    if region == "camera_cube":
        return cube()
    if region == "nerf_synthetic":
        return nerf()
    bounds = getattr(dataset, "bounds", None)
    if region == "depth_bounds" or (region == "auto" and meet is None and bounds is not None):
        if bounds is None or len(bounds) != len(cameras):
            raise InputError("init.region: 'depth_bounds' needs per-view depth bounds (LLFF's poses_bounds.npy); "
                             "this dataset has none (use init.region=auto)")
        frusta = tuple((c, float(b[0]), float(b[1])) for c, b in zip(cameras, bounds))
        mid = np.mean([c.center + c.rotation[2] * 0.5 * (b[0] + b[1]) for c, b in zip(cameras, bounds)], axis=0)
        made = Region("depth_bounds", "frusta", mid, float(bounds[:, 1].max()), frusta=frusta)
        if region == "auto":
            made = dataclasses.replace(made, note=f"init.region auto: depth_bounds (a forward-facing rig with depth "
                                                  f"bounds {bounds[:, 0].min():.3g}..{bounds[:, 1].max():.3g}): "
                                                  f"uniform in the training views' frusta between them")
        return made
    if region == "convergence":
        if meet is None:
            raise InputError("init.region: 'convergence' needs cameras whose optical axes meet in front of them; "
                             "these look one way (forward-facing) or outward (use init.region=camera_cube, or "
                             "init=sfm)")
        return _convergence(cameras, meet, radius)
    # auto
    synthetic = (dataset.layout == "blender" and (dataset.root / "transforms_train.json").is_file()
                 and meet is not None and float(np.linalg.norm(meet)) <= 0.1 * radius and 2.5 <= radius <= 6.0)
    if synthetic:
        return Region("nerf_synthetic", "cube", np.zeros(3), NERF_SYNTHETIC_HALF,
                      f"init.region auto: nerf_synthetic (NeRF-synthetic layout: the axes meet at the origin, rig "
                      f"radius {radius:.3g}): uniform in [-1.3, 1.3]^3 as graphdeco")
    if meet is not None:
        made = _convergence(cameras, meet, radius)
        return Region(made.chosen, made.shape, made.center, made.size,
                      f"init.region auto: convergence (the optical axes meet at {np.round(meet, 3).tolist()}): a "
                      f"ball of radius {made.size:.3g} there")
    made = cube()
    return Region(made.chosen, made.shape, made.center, made.size,
                  f"warning: init.region auto: the training cameras look one way (forward-facing: their optical "
                  f"axes are nearly parallel), and no region here is known to contain such a scene; started from "
                  f"gsplat's camera cube (half-side {made.size:.3g} = {extent:g} scene scales around the cameras), "
                  f"which holds only what lies within a few rig sizes of them (init=sfm triangulates the scene)",
                  warning=True)


def _convergence(cameras, meet: np.ndarray, radius: float) -> Region:
    half_fov = [min(math.atan(0.5 * c.width / c.fx), math.atan(0.5 * c.height / c.fy)) for c in cameras]
    return Region("convergence", "ball", np.asarray(meet, np.float64), radius * math.tan(float(np.median(half_fov))))


@register_init("random")
def random(dataset, settings: InitSettings) -> Initialization:
    """``settings.random_points`` points uniform in `random_region`, uniform random colours,
    drawn with the run's seed."""
    region = random_region(dataset, settings.region, settings.extent)
    rng = np.random.default_rng(settings.seed)
    xyz = region.sample(settings.random_points, rng)
    rgb = rng.random((settings.random_points, 3))
    gaussians = from_points(xyz, rgb, sh_degree=settings.sh_degree, opacity=settings.opacity)
    summary = {"region": region.chosen, "region_shape": region.shape,
               "region_center": [round(float(v), 6) for v in region.center], "region_size": round(region.size, 6)}
    return Initialization(gaussians, summary, region.note, region.warning)


__all__ = ["INITIALIZERS", "REGIONS", "InitSettings", "Initialization", "Region", "initialize", "jitter_points",
           "random_region", "register_init"]
