"""Structure from motion with pycolmap on a dataset's training views, aligned to its true frame.

The pipeline is the one 3DGS users run (COLMAP): SIFT features, exhaustive matching,
incremental mapping. It sees the *training* images only, on the CPU. Several models
can come back (views that do not connect); the largest (most registered images) is
kept. Its frame is arbitrary, so a similarity transform (`umeyama`, least squares on
the camera centres of the registered views) maps it onto the dataset's ground-truth
frame; the residual is the camera-centre RMSE reported beside the number of
registered views. The aligned model is written as COLMAP binaries to
``<dataset>/sfm/0/{cameras,images,points3D}.bin`` (with ``<dataset>/sfm/database.db``).

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

import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.fsutil import cache_root, replace_dir
from splatbench.safeio import read_npz

#: Folder under the dataset that receives the model (``sfm/0/*.bin``) and the database.
SFM_DIR = "sfm"


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


def rig_radius(cameras: Sequence[Camera]) -> float:
    """The radius of a camera rig: median distance from the centres to where the optical axes meet.

    The meeting point is the least-squares point nearest to every optical axis. When the
    axes are nearly parallel (a forward-facing rig: the point is ill-defined), the RMS
    distance of the centres from their centroid is returned instead.
    """
    if len(cameras) < 2:
        raise InputError(f"cameras: a rig radius needs at least 2 cameras, got {len(cameras)}")
    centres = np.stack([c.center for c in cameras])
    axes = np.stack([c.rotation[2] for c in cameras])  # camera z (viewing direction) in world axes
    proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
    lhs = proj.sum(0)
    if np.linalg.eigvalsh(lhs / len(cameras))[0] > 0.05:
        meet = np.linalg.solve(lhs, np.einsum("nij,nj->i", proj, centres))
        return float(np.median(np.linalg.norm(centres - meet, axis=1)))
    return float(np.sqrt(np.mean(np.sum((centres - centres.mean(0)) ** 2, axis=1))))


# --------------------------------------------------------------------------- run
@dataclass(frozen=True)
class SfmRun:
    """The largest SfM model of a dataset's training views, aligned to the true frame.

    Fields::

        registered     training views registered in the kept model
        total          training views given to SfM
        center_rmse    RMSE of the registered camera centres after alignment (world units)
        rig_radius     `rig_radius` of the true training cameras (world units)
        xyz, rgb       [M, 3] float64 points (true frame), [M, 3] uint8 colours
        alignment      `Similarity` from the model's frame to the true frame
        model_path     folder of the aligned model (cameras.bin, images.bin, points3D.bin)
        models         number of models the mapper returned
        registered_names  names (relative to the dataset root) of the registered views
        seconds        wall time of extraction + matching + mapping + alignment
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

    @property
    def center_rmse_rel(self) -> float:
        """``center_rmse / rig_radius``."""
        return self.center_rmse / self.rig_radius


def run_sfm(dataset: Any, *, seed: int = 0, single_thread: bool = True, known_intrinsics: bool = True,
            out: str | Path | None = None, verbose: bool = False) -> SfmRun:
    """SIFT + exhaustive matching + incremental mapping on the training views of ``dataset``.

    Args:
        dataset: a `splatbench.data.Dataset` or a dataset folder (any layout
            `load_dataset` reads); its training cameras are the ground truth.
        seed: random seed of pycolmap (RANSAC, mapper).
        single_thread: one thread everywhere (deterministic); False uses all cores.
        known_intrinsics: give COLMAP the true PINHOLE intrinsics, fixed (see module doc).
        out: output folder; default ``<dataset>/sfm``. Replaced atomically.
        verbose: keep COLMAP's INFO log on stderr (default: fatal messages only; a failure is an InputError).

    Returns:
        `SfmRun` (the model is written to ``<out>/0``).

    Raises:
        InputError: fewer than 3 training views, or no model with 3 registered views.
    """
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()

    from splatbench.data import Dataset, load_dataset

    ds = dataset if isinstance(dataset, Dataset) else load_dataset(dataset)
    if not (isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0):
        raise InputError(f"seed: expected an int >= 0, got {seed!r}")
    train = ds.train
    if len(train) < 3:
        raise InputError(f"dataset: SfM needs at least 3 training views, got {len(train)}")
    root = Path(ds.root)
    out_dir = Path(out) if out is not None else root / SFM_DIR
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    truth = dict(zip(train.names, train.cameras))
    threads = 1 if single_thread else -1
    t0 = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=out_dir.parent))
    log_level = pycolmap.logging.minloglevel
    if not verbose:
        pycolmap.logging.minloglevel = 3  # fatal only: a failure is our one-line InputError
    try:
        database = tmp / "database.db"
        pycolmap.set_random_seed(seed)
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = "PINHOLE"
        if known_intrinsics:
            cam0 = train.cameras[0]
            reader.camera_params = ",".join(repr(float(v)) for v in (cam0.fx, cam0.fy, cam0.cx, cam0.cy))
        extraction = pycolmap.FeatureExtractionOptions()
        extraction.num_threads = threads
        extraction.use_gpu = False
        pycolmap.extract_features(database, root, image_names=list(train.names),
                                  camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                                  extraction_options=extraction, device=pycolmap.Device.cpu)
        matching = pycolmap.FeatureMatchingOptions()
        matching.num_threads = threads
        matching.use_gpu = False
        pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
        options = pycolmap.IncrementalPipelineOptions()
        options.num_threads = threads
        options.random_seed = seed
        options.mapper.num_threads = threads
        options.mapper.random_seed = seed
        options.triangulation.random_seed = seed
        options.ba_refine_focal_length = not known_intrinsics
        options.ba_refine_principal_point = False
        options.ba_refine_extra_params = False
        options.mapper.abs_pose_refine_focal_length = not known_intrinsics
        options.mapper.abs_pose_refine_extra_params = False
        models = pycolmap.incremental_mapping(database, root, tmp / "models", options=options)
        if not models:
            raise InputError(f"{root}: SfM registered no model (too few matches between the training views)")
        rec = max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D()))
        registered = sorted((im for im in rec.images.values() if im.has_pose), key=lambda im: im.name)
        names = [im.name for im in registered]
        if len(registered) < 3:
            raise InputError(f"{root}: the largest SfM model has {len(registered)} registered views (need 3)")
        unknown = [n for n in names if n not in truth]
        if unknown:
            raise InputError(f"{root}: SfM registered {unknown[0]!r}, which is not a training view")
        est = np.stack([np.asarray(im.projection_center(), np.float64) for im in registered])
        gt = np.stack([truth[n].center for n in names])
        sim = umeyama(est, gt)
        rec.transform(sim.to_pycolmap())
        aligned = np.stack([np.asarray(rec.image(im.image_id).projection_center(), np.float64)
                            for im in registered])
        rmse = float(np.sqrt(np.mean(np.sum((aligned - gt) ** 2, axis=1))))
        model_dir = tmp / "0"
        model_dir.mkdir()
        rec.write_binary(str(model_dir))
        shutil.rmtree(tmp / "models", ignore_errors=True)
        points = [p for _, p in sorted(rec.points3D.items())]
        xyz = np.array([p.xyz for p in points], np.float64).reshape(-1, 3)
        rgb = np.array([p.color for p in points], np.uint8).reshape(-1, 3)
        seconds = time.perf_counter() - t0
        replace_dir(tmp, out_dir)
    finally:
        pycolmap.logging.minloglevel = log_level
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return SfmRun(len(registered), len(train), rmse, rig_radius(train.cameras), xyz, rgb, sim, out_dir / "0",
                  len(models), names, seconds)




# ------------------------------------------------------------------- content cache
#: Bump when `run_sfm`'s output changes for the same inputs (invalidates cached models).
SFM_CACHE_VERSION = 1
#: The cached run's points beside the model (its numbers are in the folder's manifest.json).
SFM_POINTS = "points.npz"


def sfm_inputs(dataset: Any, *, seed: int = 0, known_intrinsics: bool = True) -> dict[str, Any]:
    """What a cached SfM run depends on: every training image's bytes (sha256) and true
    camera (the alignment target; the intrinsics COLMAP is given), the options, and the
    versions of pycolmap and of this code. Test views are not inputs."""
    import hashlib
    import json
    from importlib import metadata

    from splatbench.data import Dataset, load_dataset

    ds = dataset if isinstance(dataset, Dataset) else load_dataset(dataset)
    root = Path(ds.root)
    views = {}
    for name, cam in zip(ds.train.names, ds.train.cameras):
        try:
            digest = hashlib.sha256((root / name).read_bytes()).hexdigest()
        except OSError as exc:
            raise InputError(f"{root / name}: cannot read the training image for SfM ({exc.strerror})") from None
        views[name] = {"sha256": digest, "camera": [cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy,
                                                    *np.asarray(cam.world_to_camera, np.float64).ravel().tolist()]}
    try:
        pycolmap_version = metadata.version("pycolmap")
    except metadata.PackageNotFoundError:
        pycolmap_version = "unknown"
    inputs = {"format": SFM_CACHE_VERSION, "seed": seed, "known_intrinsics": known_intrinsics,
              "single_thread": True, "pycolmap": pycolmap_version, "views": views}
    inputs["hash"] = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()
    return inputs


def sfm_cache_dir(inputs: dict[str, Any]) -> Path:
    """Where `cached_sfm` keeps the SfM run of these `sfm_inputs`: ``<cache root>/sfm/<hash>``
    (the cache root is ``$SPLATBENCH_CACHE``, else ``~/.cache/splatbench``)."""
    return cache_root() / "sfm" / inputs["hash"][:20]


def cached_sfm(dataset: Any, *, seed: int = 0, known_intrinsics: bool = True,
               say: Callable[[str], None] | None = None) -> tuple[SfmRun, bool]:
    """`run_sfm` (single-threaded, deterministic) on the training views, reused while its inputs are unchanged.

    The model, its points and a manifest (the `sfm_inputs` hash and the run's numbers)
    live in `sfm_cache_dir` (``$SPLATBENCH_CACHE/sfm/<hash>``, beside the undistorted
    images; never in the dataset folder, which is the user's and may be read-only). When
    the manifest's hash matches, the run is read back (no pycolmap); otherwise SfM runs
    into a temporary sibling folder that replaces that folder atomically
    (`splatbench.fsutil.replace_dir`), as the scene renders are cached. Returns ``(run, cached)``; ``run.seconds`` is that of the original run.
    ``say`` gets one line before anything slow: ``SfM: reusing DIR`` or ``SfM: running
    pycolmap on N training views (cached in DIR)``.

    Raises:
        InputError: the dataset cannot be read, or SfM registers no usable model.
    """
    import json

    from splatbench.data import Dataset, load_dataset
    from splatbench.scenes.render import MANIFEST, read_manifest

    ds = dataset if isinstance(dataset, Dataset) else load_dataset(dataset)
    inputs = sfm_inputs(ds, seed=seed, known_intrinsics=known_intrinsics)
    out = sfm_cache_dir(inputs)
    out.parent.mkdir(parents=True, exist_ok=True)
    manifest = read_manifest(out)
    say = say or (lambda line: None)
    if manifest is not None and manifest.get("hash") == inputs["hash"] and (out / SFM_POINTS).is_file():
        say(f"SfM: reusing {out}")
        return _read_cached(out, manifest), True
    say(f"SfM: running pycolmap on {len(ds.train)} training views (cached in {out})")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.run-", dir=out.parent))
    try:
        run = run_sfm(ds, seed=seed, single_thread=True, known_intrinsics=known_intrinsics, out=tmp / SFM_DIR)
        np.savez(tmp / SFM_DIR / SFM_POINTS, xyz=run.xyz, rgb=run.rgb)
        record = {"hash": inputs["hash"], "inputs": {k: v for k, v in inputs.items() if k != "hash"},
                  "registered": run.registered, "total": run.total, "center_rmse": run.center_rmse,
                  "rig_radius": run.rig_radius, "models": run.models, "registered_names": run.registered_names,
                  "seconds": run.seconds, "scale": run.alignment.scale,
                  "rotation": run.alignment.rotation.tolist(), "translation": run.alignment.translation.tolist()}
        (tmp / SFM_DIR / MANIFEST).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        replace_dir(tmp / SFM_DIR, out,
                    accept_existing=lambda path: (read_manifest(path) or {}).get("hash") == inputs["hash"])
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return _read_cached(out, read_manifest(out) or {}), False


def _read_cached(folder: Path, manifest: dict[str, Any]) -> SfmRun:
    try:
        points = read_npz(folder / SFM_POINTS, what=f"{folder / SFM_POINTS}")
        xyz, rgb = points["xyz"].astype(np.float64), points["rgb"].astype(np.uint8)
        m = manifest
        return SfmRun(int(m["registered"]), int(m["total"]), float(m["center_rmse"]), float(m["rig_radius"]),
                      xyz, rgb, Similarity(float(m["scale"]), np.asarray(m["rotation"], np.float64),
                                           np.asarray(m["translation"], np.float64)),
                      folder / "0", int(m["models"]), list(m["registered_names"]), float(m["seconds"]))
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise InputError(f"{folder}: unreadable cached SfM model ({type(exc).__name__}: {exc}); delete the "
                         f"folder to rerun SfM") from None
