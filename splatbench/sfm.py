"""Structure from motion with pycolmap on a dataset's training views, in its true frame.

The pipeline is the one 3DGS users run (COLMAP): SIFT features and exhaustive matching
on the *training* images only, as the dataset serves them (undistorted and downscaled as
loaded, written to a scratch folder, so they match the dataset's PINHOLE cameras), on the
CPU. Then, by ``poses``:

* ``"known"`` -- the dataset's poses and intrinsics are given to COLMAP's point
  triangulator (``pycolmap.triangulate_points``) and held fixed: only points are
  estimated, as practitioners do for a capture with known poses (instant-ngp's
  ``transforms.json``, a rendered scene). Fails only when too few features match.
* ``"estimated"`` -- incremental mapping (poses estimated); several models can come back
  (views that do not connect) and the largest (most registered images) is kept. Its frame
  is arbitrary, so a similarity transform (`umeyama`, least squares on the camera centres
  of the registered views) maps it onto the dataset's frame; the residual is the
  camera-centre RMSE reported beside the number of registered views.

The model is written as COLMAP binaries to ``<out>/0/{cameras,images,points3D}.bin``
(image names: the dataset's), with ``<out>/database.db``; `cached_sfm` keeps it in the
cache, never in the dataset folder.

Determinism: ``single_thread=True`` runs extraction, matching and mapping on one
thread with ``pycolmap.set_random_seed(seed)`` and the mapper's ``random_seed``, so
the same dataset and seed give the same model.

Intrinsics: ``known_intrinsics=True`` (the default) gives COLMAP the dataset's
PINHOLE calibration and keeps it fixed in bundle adjustment, as for any calibrated
rig; ``False`` lets COLMAP estimate one shared PINHOLE camera, as for a raw capture.

Example::

    from splatbench.sfm import run_sfm
    run = run_sfm("data/scenes/textured-256", seed=0)
    run.registered, run.total, run.center_rmse / run.rig_radius, run.model_path
"""

from __future__ import annotations

import dataclasses
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.fsutil import building_dir, cache_root, manifest_hash, read_manifest, write_manifest
from splatbench.safeio import read_npz

# ----------------------------------------------------------------- alignment maths
@dataclass(frozen=True)
class Similarity:
    """``x -> scale * rotation @ x + translation`` (rotation [3, 3] proper, scale > 0)."""

    scale: float
    rotation: np.ndarray     # [3, 3] float64
    translation: np.ndarray  # [3] float64

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points [M, 3] (float64)."""
        return self.scale * np.asarray(points, np.float64) @ self.rotation.T + self.translation

    def to_pycolmap(self) -> Any:
        """The same transform as a ``pycolmap.Sim3d`` (new_from_old_world)."""
        from splatbench.interrupt import import_pycolmap

        pycolmap = import_pycolmap()

        return pycolmap.Sim3d(self.scale, pycolmap.Rotation3d(self.rotation), self.translation.reshape(3, 1))


def umeyama(src: np.ndarray, dst: np.ndarray) -> Similarity:
    """Least-squares similarity with ``dst ~ s R src + t`` (Umeyama 1991).

    ``src``, ``dst``: [M, 3] corresponding points, M >= 3 and not all on one line.
    With ``Sigma = (dst - mean)^T (src - mean) / M = U D V^T``, ``R = U S V^T`` with
    ``S = diag(1, 1, det(U) det(V))`` (a rotation, never a reflection),
    ``s = tr(D S) / var(src)`` and ``t = mean(dst) - s R mean(src)``.
    """
    a = np.asarray(src, np.float64)
    b = np.asarray(dst, np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape != b.shape:
        raise InputError(f"umeyama: expected src and dst [M, 3] of equal shape, got {list(a.shape)} and "
                         f"{list(b.shape)}")
    if len(a) < 3:
        raise InputError(f"umeyama: need at least 3 point pairs, got {len(a)}")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise InputError("umeyama: non-finite coordinates")
    mu_a, mu_b = a.mean(0), b.mean(0)
    xa, xb = a - mu_a, b - mu_b
    var_a = float(np.mean(np.sum(xa * xa, axis=1)))
    sigma = xb.T @ xa / len(a)
    u, d, vt = np.linalg.svd(sigma)
    sv = np.linalg.svd(xa, compute_uv=False)
    if var_a <= 0 or sv[1] <= 1e-9 * max(sv[0], 1e-300):
        raise InputError("umeyama: the source points are (nearly) collinear; the rotation is undefined")
    s_fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(u) * np.linalg.det(vt)) or 1.0])
    rot = u @ s_fix @ vt
    scale = float(np.trace(np.diag(d) @ s_fix) / var_a)
    return Similarity(scale, rot, mu_b - scale * rot @ mu_a)


#: `axes_meeting_point`: the smallest eigenvalue of mean(I - a a^T) over the optical axes a
#: below which the axes count as parallel (about 13 degrees of spread: sin^2 ~ 0.05).
PARALLEL_AXES = 0.05


def axes_meeting_point(cameras: Sequence[Camera]) -> np.ndarray | None:
    """The point nearest every optical axis (least squares), [3] float64, or None.

    With ``a_i`` the viewing directions and ``c_i`` the centres, the point minimises
    ``sum_i |(I - a_i a_i^T)(x - c_i)|^2``. None when the axes are nearly parallel (the
    smallest eigenvalue of ``mean(I - a a^T)`` is below `PARALLEL_AXES`: a forward-facing
    rig, where the point is ill-defined) or when it lies behind most cameras (an
    outward-looking rig).
    """
    if len(cameras) < 2:
        raise InputError(f"cameras: a meeting point of optical axes needs at least 2 cameras, got {len(cameras)}")
    centres = np.stack([c.center for c in cameras]).astype(np.float64)
    axes = np.stack([c.rotation[2] for c in cameras]).astype(np.float64)  # camera z (viewing direction), world
    proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
    lhs = proj.sum(0)
    if np.linalg.eigvalsh(lhs / len(cameras))[0] <= PARALLEL_AXES:
        return None
    meet = np.linalg.solve(lhs, np.einsum("nij,nj->i", proj, centres))
    in_front = np.einsum("ni,ni->n", meet[None] - centres, axes) > 0
    return meet if in_front.mean() > 0.5 else None


def rig_radius(cameras: Sequence[Camera]) -> float:
    """The radius of a camera rig: median distance from the centres to where the optical axes meet.

    The meeting point is `axes_meeting_point`. When it is undefined (a forward-facing or
    outward-looking rig), the RMS distance of the centres from their centroid is returned instead.
    """
    if len(cameras) < 2:
        raise InputError(f"cameras: a rig radius needs at least 2 cameras, got {len(cameras)}")
    centres = np.stack([c.center for c in cameras])
    meet = axes_meeting_point(cameras)
    if meet is not None:
        return float(np.median(np.linalg.norm(centres - meet, axis=1)))
    return float(np.sqrt(np.mean(np.sum((centres - centres.mean(0)) ** 2, axis=1))))


# --------------------------------------------------------------------------- run
#: How SfM gets its camera poses (`cached_sfm`'s ``poses``): "known" = the dataset's,
#: fixed, points triangulated (`triangulate`); "estimated" = incremental mapping, then
#: aligned to the dataset's frame (`run_sfm`).
POSE_MODES = ("known", "estimated")


@dataclass(frozen=True)
class SfmRun:
    """The SfM points of a dataset's training views, in the dataset's (true) frame.

    Fields::

        registered     training views in the kept model (poses "known": views that see at
                       least one triangulated point)
        total          training views given to SfM
        center_rmse    RMSE of the registered camera centres after alignment (world units;
                       poses "known": what triangulation left of the given centres, ~0)
        rig_radius     `rig_radius` of the true training cameras (world units)
        xyz, rgb       [M, 3] float64 points (true frame), [M, 3] uint8 colours
        alignment      `Similarity` from the model's frame to the true frame (identity for known poses)
        model_path     folder of the model (cameras.bin, images.bin, points3D.bin)
        models         number of models the mapper returned (1 for known poses)
        registered_names  names (relative to the dataset root) of the registered views
        seconds        wall time of extraction + matching + mapping/triangulation + alignment
        poses          "estimated" (incremental mapping + alignment) or "known" (triangulation)
    """

    registered: int
    total: int
    center_rmse: float
    rig_radius: float
    xyz: np.ndarray
    rgb: np.ndarray
    alignment: Similarity
    model_path: Path
    models: int
    registered_names: list[str]
    seconds: float
    poses: str = "estimated"

    @property
    def center_rmse_rel(self) -> float:
        """``center_rmse / rig_radius``."""
        return self.center_rmse / self.rig_radius


def _load(dataset: Any) -> Any:
    from splatbench.data import Dataset, load_dataset

    return dataset if isinstance(dataset, Dataset) else load_dataset(dataset)


def _write_views(train: Any, folder: Path) -> list[str]:
    """The training images as the dataset serves them (undistorted, downscaled, 8-bit) as
    PNGs ``<k>.png`` in ``folder``: what SfM sees, matching the dataset's PINHOLE cameras."""
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for k, image in enumerate(train.images):
        name = f"{k:05d}.png"
        Image.fromarray(np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)).save(folder / name)
        names.append(name)
    return names


def _extract_and_match(pycolmap: Any, train: Any, tmp: Path, *, threads: int,
                       known_intrinsics: bool) -> tuple[Path, Path, list[str]]:
    """SIFT on the served training views and exhaustive matching into ``tmp/database.db``;
    with ``known_intrinsics`` every view's database camera is the dataset's PINHOLE one
    (one COLMAP camera per view), else one shared PINHOLE camera for COLMAP to estimate."""
    images = tmp / "images"
    names = _write_views(train, images)
    database = tmp / "database.db"
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = threads
    extraction.use_gpu = False
    mode = pycolmap.CameraMode.PER_IMAGE if known_intrinsics else pycolmap.CameraMode.SINGLE
    pycolmap.extract_features(database, images, image_names=names, camera_mode=mode, reader_options=reader,
                              extraction_options=extraction, device=pycolmap.Device.cpu)
    if known_intrinsics:
        by_name = dict(zip(names, train.cameras))
        db = pycolmap.Database.open(database)
        try:
            for im in db.read_all_images():
                cam = by_name[im.name]
                db.update_camera(pycolmap.Camera(model="PINHOLE", width=cam.width, height=cam.height,
                                                 params=[cam.fx, cam.fy, cam.cx, cam.cy], camera_id=im.camera_id))
        finally:
            db.close()
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = threads
    matching.use_gpu = False
    pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
    return database, images, names


def run_sfm(dataset: Any, *, seed: int = 0, single_thread: bool = True, known_intrinsics: bool = True,
            poses: str = "estimated", out: str | Path | None = None, verbose: bool = False,
            say: Callable[[str], None] | None = None) -> SfmRun:
    """SfM on the training views of ``dataset``: SIFT, exhaustive matching, then either
    incremental mapping aligned to the true frame (``poses="estimated"``) or triangulation
    with the dataset's poses fixed (``poses="known"``, `pycolmap.triangulate_points`).

    SfM sees the training images as the dataset serves them (`_write_views`: undistorted
    and downscaled as loaded, so they match the dataset's PINHOLE cameras), never the
    files in the capture folder.

    Args:
        dataset: a `splatbench.data.Dataset` or a dataset folder (any layout
            `load_dataset` reads); its training cameras are the ground truth.
        seed: random seed of pycolmap (RANSAC, mapper).
        single_thread: one thread everywhere (deterministic); False uses all cores.
        known_intrinsics: give COLMAP the true PINHOLE intrinsics, fixed (see module doc);
            always True with ``poses="known"``.
        poses: "estimated" or "known" (`POSE_MODES`).
        out: output folder, replaced atomically. None: the content cache (`cached_sfm`, which
            reuses an earlier run of the same inputs), never the dataset folder, which is the
            user's and may be read-only; a multi-threaded run (not deterministic, so not
            cached) needs an ``out``.
        verbose: keep COLMAP's INFO log on stderr (default: fatal messages only; a failure is an InputError).
        say: with ``out`` None, the cache's one line (`cached_sfm`: reusing, or running into it).

    Returns:
        `SfmRun` (the model is written to ``<out>/0``).

    Raises:
        InputError: fewer than 3 training views; no model with 3 registered views
            (estimated poses); no point triangulated (known poses).
    """
    ds = _load(dataset)
    _check_sfm_options(ds, seed=seed, known_intrinsics=known_intrinsics, poses=poses)
    if out is None:
        if not single_thread:
            raise InputError("out: a multi-threaded SfM run is not deterministic, so it is not cached: give an "
                             "output folder (nothing is written into the dataset folder)")
        return cached_sfm(ds, seed=seed, known_intrinsics=known_intrinsics, poses=poses, say=say)[0]
    out_dir = Path(out)
    with building_dir(out_dir) as tmp:
        run = _sfm_into(tmp, ds, seed=seed, threads=1 if single_thread else -1, known_intrinsics=known_intrinsics,
                        poses=poses, verbose=verbose)
    return dataclasses.replace(run, model_path=out_dir / "0")


def _check_sfm_options(ds: Any, *, seed: int, known_intrinsics: bool, poses: str) -> None:
    if not (isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0):
        raise InputError(f"seed: expected an int >= 0, got {seed!r}")
    if poses not in POSE_MODES:
        raise InputError(f"poses: expected one of {', '.join(POSE_MODES)}, got {poses!r}")
    if poses == "known" and not known_intrinsics:
        raise InputError("known_intrinsics: triangulating with known poses uses the known intrinsics too")
    if len(ds.train) < 3:
        raise InputError(f"dataset: SfM needs at least 3 training views, got {len(ds.train)}")


def _sfm_into(tmp: Path, ds: Any, *, seed: int, threads: int, known_intrinsics: bool, poses: str,
              verbose: bool) -> SfmRun:
    """`run_sfm`'s work (options checked) into the empty folder ``tmp``: the model in ``tmp/0``,
    the database beside it; the scratch folders removed."""
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()
    root = Path(ds.root)
    train = ds.train
    t0 = time.perf_counter()
    log_level = pycolmap.logging.minloglevel
    if not verbose:
        pycolmap.logging.minloglevel = 3  # fatal only: a failure is our one-line InputError
    try:
        pycolmap.set_random_seed(seed)
        database, images, names = _extract_and_match(pycolmap, train, tmp, threads=threads,
                                                     known_intrinsics=known_intrinsics)
        to_dataset = dict(zip(names, train.names))
        if poses == "known":
            rec, models = _triangulate(pycolmap, train, database, images, names, tmp, seed, threads), 1
        else:
            rec, models = _map(pycolmap, database, images, tmp, seed, threads, known_intrinsics, root)
        registered = sorted((im for im in rec.images.values() if im.has_pose
                             and (poses == "estimated" or im.num_points3D > 0)), key=lambda im: im.name)
        if poses == "estimated" and len(registered) < 3:
            raise InputError(f"{root}: the largest SfM model has {len(registered)} registered views (need 3)")
        if poses == "known" and rec.num_points3D() == 0:
            raise InputError(f"{root}: SfM with the known poses triangulated no point (too few matches between "
                             f"the training views)")
        truth = dict(zip(names, train.cameras))
        est = np.stack([np.asarray(im.projection_center(), np.float64) for im in registered])
        gt = np.stack([truth[im.name].center for im in registered])
        sim = umeyama(est, gt) if poses == "estimated" else Similarity(1.0, np.eye(3), np.zeros(3))
        if poses == "estimated":
            rec.transform(sim.to_pycolmap())
        aligned = np.stack([np.asarray(rec.image(im.image_id).projection_center(), np.float64)
                            for im in registered])
        rmse = float(np.sqrt(np.mean(np.sum((aligned - gt) ** 2, axis=1))))
        for im in rec.images.values():  # the model names the dataset's views, not SfM's copies
            im.name = to_dataset[im.name]
        model_dir = tmp / "0"
        model_dir.mkdir()
        rec.write_binary(str(model_dir))
        for scratch in ("models", "triangulated", "images"):
            shutil.rmtree(tmp / scratch, ignore_errors=True)
        points = [p for _, p in sorted(rec.points3D.items())]
        xyz = np.array([p.xyz for p in points], np.float64).reshape(-1, 3)
        rgb = np.array([p.color for p in points], np.uint8).reshape(-1, 3)
        seconds = time.perf_counter() - t0
    finally:
        pycolmap.logging.minloglevel = log_level
    return SfmRun(len(registered), len(train), rmse, rig_radius(train.cameras), xyz, rgb, sim, model_dir,
                  models, [im.name for im in registered], seconds, poses)


def _pipeline_options(pycolmap: Any, seed: int, threads: int) -> Any:
    """COLMAP's incremental pipeline options with every seed and thread count set (mapping and
    triangulation alike: the same seed and threads give the same model)."""
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = threads
    options.random_seed = seed
    options.mapper.num_threads = threads
    options.mapper.random_seed = seed
    options.triangulation.random_seed = seed
    return options


def _map(pycolmap: Any, database: Path, images: Path, tmp: Path, seed: int, threads: int, known_intrinsics: bool,
         root: Path) -> tuple[Any, int]:
    """Incremental mapping; the largest model (most registered views) and the number of models."""
    options = _pipeline_options(pycolmap, seed, threads)
    options.ba_refine_focal_length = not known_intrinsics
    options.ba_refine_principal_point = False
    options.ba_refine_extra_params = False
    options.mapper.abs_pose_refine_focal_length = not known_intrinsics
    options.mapper.abs_pose_refine_extra_params = False
    models = pycolmap.incremental_mapping(database, images, tmp / "models", options=options)
    if not models:
        raise InputError(f"{root}: SfM registered no model (too few matches between the training views)")
    return max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D())), len(models)


def _triangulate(pycolmap: Any, train: Any, database: Path, images: Path, names: list[str], tmp: Path, seed: int,
                 threads: int) -> Any:
    """COLMAP's point_triangulator: a reconstruction with the dataset's cameras and poses
    (the database's image and camera ids), its matches triangulated with the poses and
    intrinsics held fixed (bundle adjustment moves the points only)."""
    by_name = dict(zip(names, train.cameras))
    rec = pycolmap.Reconstruction()
    db = pycolmap.Database.open(database)
    try:
        db_images = sorted(db.read_all_images(), key=lambda im: im.image_id)
        db_cameras = {c.camera_id: c for c in db.read_all_cameras()}
    finally:
        db.close()
    for im in db_images:
        cam = by_name[im.name]
        rec.add_camera_with_trivial_rig(db_cameras[im.camera_id])
        w2c = np.asarray(cam.world_to_camera, np.float64)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(w2c[:3, :3]), w2c[:3, 3].reshape(3, 1))
        rec.add_image_with_trivial_frame(pycolmap.Image(name=im.name, camera_id=im.camera_id, image_id=im.image_id),
                                         pose)
    options = _pipeline_options(pycolmap, seed, threads)
    (tmp / "triangulated").mkdir()
    out = pycolmap.triangulate_points(rec, database, images, tmp / "triangulated", options=options,
                                      refine_intrinsics=False)
    out.extract_colors_for_all_images(str(images))
    return out




# ------------------------------------------------------------------- content cache
#: Bump when `run_sfm`'s output changes for the same inputs (invalidates cached models).
#: 2: SfM sees the served (undistorted, downscaled) training images; poses "known" added.
SFM_CACHE_VERSION = 2
#: The cached run's points beside the model (its numbers are in the folder's manifest.json).
SFM_POINTS = "points.npz"


def sfm_inputs(dataset: Any, *, seed: int = 0, known_intrinsics: bool = True, poses: str = "estimated"
               ) -> dict[str, Any]:
    """What a cached SfM run depends on: every training image as the dataset serves it
    (sha256 of its 8-bit pixels, which SfM sees) and its true camera (the alignment target;
    the intrinsics COLMAP is given; the known poses), the options, and the versions of
    pycolmap and of this code. Test views are not inputs."""
    import hashlib
    import json
    from importlib import metadata

    ds = _load(dataset)
    views = {}
    for name, cam, image in zip(ds.train.names, ds.train.cameras, ds.train.images):
        pixels = np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)
        views[name] = {"sha256": hashlib.sha256(pixels.tobytes() + str(pixels.shape).encode()).hexdigest(),
                       "camera": [cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy,
                                  *np.asarray(cam.world_to_camera, np.float64).ravel().tolist()]}
    try:
        pycolmap_version = metadata.version("pycolmap")
    except metadata.PackageNotFoundError:
        pycolmap_version = "unknown"
    inputs = {"format": SFM_CACHE_VERSION, "seed": seed, "known_intrinsics": known_intrinsics, "poses": poses,
              "single_thread": True, "pycolmap": pycolmap_version, "views": views}
    inputs["hash"] = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()
    return inputs


def sfm_cache_dir(inputs: dict[str, Any]) -> Path:
    """Where `cached_sfm` keeps the SfM run of these `sfm_inputs`: ``<cache root>/sfm/<hash>``
    (the cache root is ``$SPLATBENCH_CACHE``, else ``~/.cache/splatbench``)."""
    return cache_root() / "sfm" / inputs["hash"][:20]


def cached_sfm(dataset: Any, *, seed: int = 0, known_intrinsics: bool = True, poses: str = "estimated",
               say: Callable[[str], None] | None = None) -> tuple[SfmRun, bool]:
    """`run_sfm` (single-threaded, deterministic) on the training views, reused while its inputs are unchanged.

    The model, its points and a manifest (the `sfm_inputs` hash and the run's numbers)
    live in `sfm_cache_dir` (``$SPLATBENCH_CACHE/sfm/<hash>``, beside the undistorted
    images; never in the dataset folder, which is the user's and may be read-only). When
    the manifest's hash matches, the run is read back (no pycolmap); otherwise SfM runs
    into a temporary sibling folder that replaces that folder atomically
    (`splatbench.fsutil.building_dir`), as every content-keyed folder is built. Returns
    ``(run, cached)``; ``run.seconds`` is that of the original run.
    ``say`` gets one line before anything slow: ``SfM: reusing DIR`` or ``SfM: running
    pycolmap on N training views (cached in DIR)``.

    Raises:
        InputError: the dataset cannot be read, or SfM registers no usable model.
    """
    ds = _load(dataset)
    inputs = sfm_inputs(ds, seed=seed, known_intrinsics=known_intrinsics, poses=poses)
    out = sfm_cache_dir(inputs)
    say = say or (lambda line: None)

    def current(folder: Path) -> bool:
        return manifest_hash(folder) == inputs["hash"] and (folder / SFM_POINTS).is_file()

    if current(out):
        say(f"SfM: reusing {out}")
        return _read_cached(out, read_manifest(out) or {}), True
    _check_sfm_options(ds, seed=seed, known_intrinsics=known_intrinsics, poses=poses)
    how = "triangulating with the known poses" if poses == "known" else "incremental mapping"
    say(f"SfM: running pycolmap ({how}) on {len(ds.train)} training views (cached in {out})")
    with building_dir(out, accept_existing=current) as tmp:
        run = _sfm_into(tmp, ds, seed=seed, threads=1, known_intrinsics=known_intrinsics, poses=poses,
                        verbose=False)
        np.savez(tmp / SFM_POINTS, xyz=run.xyz, rgb=run.rgb)
        write_manifest(tmp, {"hash": inputs["hash"], "inputs": {k: v for k, v in inputs.items() if k != "hash"},
                             "registered": run.registered, "total": run.total, "center_rmse": run.center_rmse,
                             "rig_radius": run.rig_radius, "models": run.models,
                             "registered_names": run.registered_names, "seconds": run.seconds,
                             "scale": run.alignment.scale, "poses": run.poses,
                             "rotation": run.alignment.rotation.tolist(),
                             "translation": run.alignment.translation.tolist()})
    return _read_cached(out, read_manifest(out) or {}), False


def _read_cached(folder: Path, manifest: dict[str, Any]) -> SfmRun:
    try:
        points = read_npz(folder / SFM_POINTS, what=f"{folder / SFM_POINTS}")
        xyz, rgb = points["xyz"].astype(np.float64), points["rgb"].astype(np.uint8)
        m = manifest
        return SfmRun(int(m["registered"]), int(m["total"]), float(m["center_rmse"]), float(m["rig_radius"]),
                      xyz, rgb, Similarity(float(m["scale"]), np.asarray(m["rotation"], np.float64),
                                           np.asarray(m["translation"], np.float64)),
                      folder / "0", int(m["models"]), list(m["registered_names"]), float(m["seconds"]),
                      str(m.get("poses", "estimated")))
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise InputError(f"{folder}: unreadable cached SfM model ({type(exc).__name__}: {exc}); delete the "
                         f"folder to rerun SfM") from None
