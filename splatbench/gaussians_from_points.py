"""Gaussians from points: the initial Gaussians of a training, from a point cloud, SfM,
uniform random points, or the true surfaces.

The constructors themselves; training picks one by name (`TrainConfig.init`) through
`splatbench.train.initializers`, which calls these.

Every initialiser ends in `from_points`: one isotropic Gaussian per point, scales
from the mean squared distance to the 3 nearest neighbours, opacity 0.1, SH DC from
the point colour (graphdeco-inria's ``create_from_pcd``).

========================================  ===============================================
``from_points(points, colors)``           a given point cloud (e.g. ``Dataset.points``)
``from_sfm(dataset, *, seed)``            pycolmap SfM on the training views, aligned to
                                          the true frame (`splatbench.sfm`): the 3DGS
                                          default for captured scenes
``from_random(lo, hi, n, *, seed)``       uniform in a box, random colours: 3DGS's
                                          default for Blender (NeRF-synthetic) scenes
``from_surface(scene_or_dataset, n, *,    points on the true geometry of the Mitsuba
seed)``                                   scene: a dense initialisation standing in for
                                          dense point maps (MASt3R and the like)
========================================  ===============================================
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from splatbench.errors import InputError
from splatbench.gaussians import SH_BASES_OF_DEGREE, SH_C0, Gaussians
from splatbench.guards import as_float_array, check_sh_degree, check_shape

#: Lower bound on the mean squared neighbour distance (graphdeco's ``clamp_min(dist2, 1e-7)``).
MIN_DIST2 = 1e-7


def knn_mean_sq_dist(points: np.ndarray, k: int = 3) -> np.ndarray:
    """[M] float64 mean squared distance from each point to its ``k`` nearest *other* points.

    Duplicated points count as neighbours at distance 0. With fewer than ``k + 1``
    points, all the other points are used.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    m = len(pts)
    k_eff = min(k, m - 1)
    if k_eff < 1:
        raise InputError(f"points: need at least 2 points for neighbour distances, got {m}")
    dist, _ = cKDTree(pts).query(pts, k=k_eff + 1)
    # column 0 is a zero distance (the point itself, or an exact duplicate of it):
    # dropping it removes exactly one zero, which is the point itself.
    return np.mean(dist[:, 1:] ** 2, axis=1)


def from_points(points: Any, colors: Any, *, sh_degree: int = 3, opacity: float = 0.1) -> Gaussians:
    """Seed one isotropic Gaussian per point, as graphdeco-inria's ``create_from_pcd``.

    Args:
        points: [M, 3] positions (M >= 2).
        colors: [M, 3] RGB, uint8 in 0..255 or float in [0, 1].
        sh_degree: SH degree 0..3 of the result; bands above 0 start at zero.
        opacity: initial opacity in (0, 1); stored as its logit.

    Returns:
        `Gaussians` with ``means = points``, ``sh[:, 0] = (rgb - 0.5) / C0`` (so the
        degree-0 colour ``C0·sh0 + 0.5`` is ``rgb``), ``log_scales = log(sqrt(d2))``
        on all three axes, where ``d2 = max(mean squared distance to the 3 nearest
        other points, 1e-7)`` (graphdeco clamps the mean *squared* distance), identity
        quaternions (1, 0, 0, 0) and ``opacity_logits = logit(opacity)``.
    """
    sizes: dict[str, int] = {}
    pts = as_float_array("points", points, ("M", 3), sizes, dtype=np.float64)
    col = np.asarray(colors)
    check_shape("colors", col.shape, ("M", 3), sizes)
    if col.dtype == np.uint8:
        rgb = col.astype(np.float64) / 255.0
    elif np.issubdtype(col.dtype, np.floating):
        rgb = as_float_array("colors", col, ("M", 3), sizes, dtype=np.float64)
        bad = (rgb < 0) | (rgb > 1)
        if bad.any():
            where = np.unravel_index(int(np.argmax(bad)), bad.shape)
            raise InputError(f"colors: float colours must be in [0, 1], got {rgb[where]!r} "
                             f"at index {[int(i) for i in where]}")
    else:
        raise InputError(f"colors: expected uint8 or float in [0, 1], got dtype {col.dtype}")
    degree = check_sh_degree("sh_degree", sh_degree)
    o = float(opacity) if isinstance(opacity, (int, float, np.floating, np.integer)) else math.nan
    if not 0 < o < 1:
        raise InputError(f"opacity: expected a number in (0, 1), got {opacity!r}")

    m = len(pts)
    dist2 = np.maximum(knn_mean_sq_dist(pts), MIN_DIST2)
    log_scales = np.repeat(np.log(np.sqrt(dist2))[:, None], 3, axis=1)
    sh = np.zeros((m, SH_BASES_OF_DEGREE[degree], 3), dtype=np.float64)
    sh[:, 0, :] = (rgb - 0.5) / SH_C0
    quats = np.zeros((m, 4))
    quats[:, 0] = 1.0
    return Gaussians(
        means=pts,
        log_scales=log_scales,
        quats=quats,
        opacity_logits=np.full(m, math.log(o / (1 - o))),
        sh=sh,
    )


# --------------------------------------------------------------------- from_random
def _seed(seed: Any) -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed: expected an int >= 0, got {seed!r}")
    return int(seed)


def _count(n: Any) -> int:
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 2:
        raise InputError(f"n: expected an int >= 2 (neighbour distances need two points), got {n!r}")
    return int(n)


def from_random(bounds_min: Any, bounds_max: Any, n: int, *, seed: int, sh_degree: int = 3) -> Gaussians:
    """``n`` Gaussians at uniform random points of the box ``[bounds_min, bounds_max]``, random colours.

    What 3DGS does for Blender scenes, which come without SfM points (graphdeco-inria
    uses 100,000 points in ``[-1.3, 1.3]^3``). Colours are uniform in [0, 1] per channel.

    Args:
        bounds_min, bounds_max: [3] box corners, ``bounds_min < bounds_max`` on every axis.
        n: number of Gaussians (>= 2).
        seed: seed of the point and colour draws (same seed, same Gaussians).
        sh_degree: SH degree 0..3 of the result (bands above 0 start at zero).
    """
    sizes: dict[str, int] = {}
    lo = as_float_array("bounds_min", bounds_min, (3,), sizes, dtype=np.float64)
    hi = as_float_array("bounds_max", bounds_max, (3,), sizes, dtype=np.float64)
    if not np.all(lo < hi):
        raise InputError(f"bounds_min, bounds_max: expected bounds_min < bounds_max on every axis, got "
                         f"{lo.tolist()} and {hi.tolist()}")
    rng = np.random.default_rng(_seed(seed))
    m = _count(n)
    points = lo + (hi - lo) * rng.random((m, 3))
    colors = rng.random((m, 3))
    return from_points(points, colors, sh_degree=sh_degree)


# -------------------------------------------------------------------- from_surface
#: Relative depth tolerance of the visibility test of `from_surface`'s image colours.
VISIBILITY_REL_DEPTH = 0.02
COLOR_SOURCES = ("auto", "image", "albedo")


def from_surface(scene_or_dataset: Any, n: int, *, seed: int, sh_degree: int = 3, colors: str = "auto",
                 extra_dirs: Iterable[str | Path] = ()) -> Gaussians:
    """``n`` Gaussians at points sampled uniformly by area on the scene's true surfaces.

    A dense initialisation from exact geometry, standing in for the dense point maps
    (MASt3R and the like) that are the usual alternative to sparse SfM. Each
    non-emitter shape of ``mi.Scene.shapes()`` gets a multinomial share of ``n`` by
    area, then ``shape.sample_position`` with seeded uniform samples: the points of
    `splatbench.scenes.sample_surface` for the same seed (the one implementation, which
    takes the shapes in a load-order-independent order).

    Args:
        scene_or_dataset: a loaded ``mi.Scene``; a catalog scene name or folder; or a
            dataset rendered by ``splatbench scenes render`` (a `splatbench.data.Dataset`
            or its folder), whose ``manifest.json`` names the scene and the folder it was
            rendered from (its files must be unchanged since the render).
        n: number of Gaussians (>= 2).
        seed: seed of the surface sampling.
        sh_degree: SH degree 0..3 of the result.
        colors: ``"image"``: the sRGB colour of the point in the training view that sees
            it most frontally (visible where the view's depth map agrees within
            `VISIBILITY_REL_DEPTH`), as SfM colours are; points no view sees fall back to
            the albedo. ``"albedo"``: the BSDF's diffuse reflectance at the point
            (``bsdf.eval_diffuse_reflectance``), sRGB-encoded, clipped to [0, 1].
            ``"auto"``: ``"image"`` for a dataset with depth maps, else ``"albedo"``.
        extra_dirs: extra scene folders for catalog look-ups (as ``--scenes-dir``); when
            given, a dataset's scene is looked up by name there (and in the catalog)
            instead of in the folder its manifest records.
    """
    if colors not in COLOR_SOURCES:
        raise InputError(f"colors: expected one of {', '.join(COLOR_SOURCES)}, got {colors!r}")
    m = _count(n)
    mi_scene, dataset = _resolve_scene(scene_or_dataset, tuple(extra_dirs))
    has_depth = dataset is not None and dataset.train.depths is not None and len(dataset.train) > 0
    if colors == "image" and not has_depth:
        raise InputError("colors: 'image' needs a dataset with depth maps (depth/*.npy) and training views")
    source = ("image" if has_depth else "albedo") if colors == "auto" else colors
    xyz, normals, rgb = _surface_samples(mi_scene, m, _seed(seed))
    if source == "image":
        from_views, seen = _image_colors(dataset.train, xyz, normals)
        rgb[seen] = from_views[seen]
    return from_points(xyz, np.clip(rgb, 0.0, 1.0), sh_degree=sh_degree)


def _resolve_scene(obj: Any, extra_dirs: tuple) -> tuple[Any, Any]:
    """``(mi.Scene, Dataset or None)`` from a scene, a scene name/folder, or a rendered dataset."""
    from splatbench.data import Dataset, load_dataset
    from splatbench.scenes import get_scene, load_mitsuba_scene, read_manifest

    if hasattr(obj, "shapes") and callable(obj.shapes):
        return obj, None
    if isinstance(obj, Dataset):
        dataset = obj
    elif isinstance(obj, (str, Path)) and read_manifest(obj) is not None:
        dataset = load_dataset(obj)
    elif isinstance(obj, (str, Path)):
        return load_mitsuba_scene(get_scene(obj, extra_dirs)), None
    else:
        raise InputError(f"scene_or_dataset: expected a mi.Scene, a scene name or folder, or a dataset, "
                         f"got {type(obj).__name__}")
    manifest = read_manifest(dataset.root)
    if manifest is None or "scene" not in manifest:
        raise InputError(f"{dataset.root}: no manifest.json naming its scene (only datasets rendered by "
                         f"`splatbench scenes render` know their geometry); pass the scene instead")
    folder = manifest.get("scene_folder")
    if not extra_dirs and isinstance(folder, str) and Path(folder).is_dir():
        spec = get_scene(Path(folder))  # the folder the dataset was rendered from
    else:
        spec = get_scene(manifest["scene"], extra_dirs)
    import hashlib

    now = {f.relative_to(spec.folder).as_posix(): hashlib.sha256(f.read_bytes()).hexdigest() for f in spec.files()}
    if manifest.get("files") is not None and manifest["files"] != now:
        raise InputError(f"{dataset.root}: the files of scene {manifest['scene']!r} ({spec.folder}) changed since "
                         f"the dataset was rendered; render it again")
    return load_mitsuba_scene(spec), dataset


def _surface_samples(mi_scene, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(xyz [n, 3], normals [n, 3], albedo [n, 3] sRGB-encoded)`` from `splatbench.scenes.sample_surface`."""
    from splatbench.scenes import linear_to_srgb, sample_surface

    pts = sample_surface(mi_scene, n, seed=seed, albedo=True)
    return pts.xyz, pts.normals, linear_to_srgb(pts.albedo)


def _image_colors(split, xyz: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rgb [M, 3] in [0, 1], seen [M] bool)``: colour in the most frontal view that sees each point."""
    m = len(xyz)
    best = np.full(m, -np.inf)
    rgb = np.zeros((m, 3))
    for cam, image, depth in zip(split.cameras, split.images, split.depths):
        uv, z = cam.project(xyz)
        ok = (z > cam.near) & np.isfinite(uv).all(axis=1)
        col = np.floor(np.where(ok, uv[:, 0], -1)).astype(np.int64)
        row = np.floor(np.where(ok, uv[:, 1], -1)).astype(np.int64)
        ok &= (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
        idx = np.flatnonzero(ok)
        d = depth[row[idx], col[idx]].astype(np.float64)
        visible = (d > 0) & (np.abs(d - z[idx]) <= VISIBILITY_REL_DEPTH * z[idx])
        idx = idx[visible]
        to_cam = cam.center - xyz[idx]
        cos = np.sum(normals[idx] * to_cam, axis=1) / np.linalg.norm(to_cam, axis=1)
        cos = np.abs(cos)  # two-sided surfaces: either side may face the camera
        better = cos > best[idx]
        take = idx[better]
        best[take] = cos[better]
        rgb[take] = image[row[take], col[take]]
    return rgb, np.isfinite(best)


# ------------------------------------------------------------------------ from_sfm
@dataclass(frozen=True)
class SfmResult:
    """Gaussians seeded from an SfM model of a dataset's training views (`from_sfm`).

    Fields::

        gaussians     one Gaussian per SfM point, in the dataset's (true) frame
        registered    training views registered in the kept (largest) model
        total         training views given to SfM
        center_rmse   RMSE of the registered camera centres after the similarity
                      alignment, in world units (`center_rmse_rel`: over the rig radius)
        model_path    folder of the aligned COLMAP model (in the content cache, `splatbench.sfm.sfm_cache_dir`)
        rig_radius    radius of the true training rig (`splatbench.sfm.rig_radius`)
    """

    gaussians: Gaussians
    registered: int
    total: int
    center_rmse: float
    model_path: Path
    rig_radius: float

    @property
    def center_rmse_rel(self) -> float:
        """Camera-centre RMSE as a fraction of the rig radius."""
        return self.center_rmse / self.rig_radius


def from_sfm(dataset: Any, *, seed: int = 0, single_thread: bool = True, sh_degree: int = 3,
             known_intrinsics: bool = True) -> SfmResult:
    """Run SfM on the training views of ``dataset`` and seed one Gaussian per 3D point.

    `splatbench.sfm.run_sfm` does the work (pycolmap SIFT, exhaustive matching,
    incremental mapping, CPU only; largest model; similarity alignment on camera
    centres); the aligned model lives in the content cache (`splatbench.sfm.cached_sfm`, which
    reuses an earlier run of the same inputs), never in the dataset folder.
    ``single_thread=True`` with a fixed ``seed`` is deterministic; ``single_thread=False`` is
    not, so it is not cached and refused here (`run_sfm` with an ``out`` folder runs it).
    Points keep their SfM colours.

    Args:
        dataset: a `splatbench.data.Dataset` or a dataset folder.
        seed: pycolmap's random seed.
        single_thread: one thread everywhere (deterministic).
        sh_degree: SH degree 0..3 of the result.
        known_intrinsics: give COLMAP the true intrinsics, fixed (see `splatbench.sfm`).
    """
    from splatbench.sfm import run_sfm

    run = run_sfm(dataset, seed=_seed(seed), single_thread=single_thread, known_intrinsics=known_intrinsics)
    if len(run.xyz) < 2:
        raise InputError(f"{run.model_path}: the SfM model has {len(run.xyz)} points (need 2)")
    gaussians = from_points(run.xyz, run.rgb, sh_degree=sh_degree)
    return SfmResult(gaussians, run.registered, run.total, run.center_rmse, run.model_path, run.rig_radius)
