"""Multi-view datasets in the COLMAP or Blender (NeRF synthetic / nerfstudio) layout.

`load_dataset` reads a folder written by ``splatbench scenes render`` or by other tools
and returns typed train and test splits::

    ds = load_dataset("data/scenes/diffuse-128")              # layout="auto": COLMAP first
    ds.train.images.shape, len(ds.train.cameras)              # (21, 128, 128, 3), 21
    ds.test.depths.shape if ds.test.depths is not None else None
    ds.points.xyz.shape, ds.points.rgb.dtype                  # (M, 3), uint8

Layouts:

* **COLMAP** -- ``sparse/0/`` (or ``sparse/``, as ``image_undistorter`` writes it) with
  ``cameras``, ``images`` and ``points3D`` (``.bin`` or ``.txt``, read by pycolmap, with
  or without COLMAP 3.12's ``rigs``/``frames``), images under ``images/<name>``.
  Cameras must be PINHOLE or SIMPLE_PINHOLE (undistorted). Registered images are
  sorted by name. Split: ``split.json`` (``{"train": [names], "test": [names]}``,
  written by splatbench) when present, else every ``test_every``-th image (``i %
  test_every == 0``) is a test view, as 3DGS's ``--eval`` does.
* **Blender** -- ``transforms_train.json`` (+ ``transforms_test.json``; the given split)
  or a single nerfstudio ``transforms.json`` (every ``test_every``-th frame, sorted by
  file path, is a test view). ``file_path`` is relative to the folder, with or without
  its extension (NeRF synthetic's ``"./train/r_0"`` finds ``train/r_0.png``).
  Intrinsics: nerfstudio's ``fl_x, fl_y, cx, cy, w, h`` (top level or per frame) or
  ``camera_angle_x``; ``camera_model`` PINHOLE / SIMPLE_PINHOLE, or OPENCV with zero
  distortion. Points from ``ply_file_path`` when given.

Images are returned as stored (8-bit sRGB values / 255, float32); RGBA images are
composited on ``background`` and their alpha kept in ``Split.alphas``. Depth maps are
read from ``depth/<image path without its first folder>.npy`` (camera z) when the
dataset has a ``depth/`` folder. Every problem (missing file, image size that
disagrees with its camera, unsupported camera model) is a one-line `InputError`
naming the file and the field.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from splatbench.cameras import Camera
from splatbench.data.colmap_bounds import check_colmap_binary, check_colmap_text
from splatbench.errors import InputError
from splatbench.ply import read_ply_data
from splatbench.safeio import read_image_with_alpha, read_npy

LAYOUTS = ("auto", "colmap", "blender")
#: COLMAP camera models accepted as they are (no distortion).
PINHOLE_MODELS = ("PINHOLE", "SIMPLE_PINHOLE")
_DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")


@dataclass(frozen=True)
class PointCloud:
    """A coloured point cloud (SfM points or points on the true surfaces)."""

    xyz: np.ndarray   # [M, 3] float64 world positions
    rgb: np.ndarray   # [M, 3] uint8 colours

    def __post_init__(self) -> None:
        if self.xyz.ndim != 2 or self.xyz.shape[1] != 3 or self.rgb.shape != self.xyz.shape:
            raise InputError(f"points: expected xyz [M, 3] and rgb [M, 3], got {list(self.xyz.shape)} "
                             f"and {list(self.rgb.shape)}")
        bad = int((~np.isfinite(self.xyz)).any(axis=1).sum())
        if bad:
            raise InputError(f"points: x, y, z of {bad} of {len(self.xyz)} points are not finite")

    def __len__(self) -> int:
        return len(self.xyz)


@dataclass(frozen=True)
class Split:
    """The views of one split, in a fixed order (V views of H x W pixels)."""

    images: np.ndarray                # [V, H, W, 3] float32 in [0, 1], sRGB values as stored
    cameras: list[Camera]             # V cameras, OpenCV axes (see splatbench.cameras)
    depths: np.ndarray | None         # [V, H, W] float32 camera z, 0 where nothing was hit; None if absent
    names: list[str]                  # V image paths relative to the dataset root
    alphas: np.ndarray | None = None  # [V, H, W] float32 opacity of RGBA sources; None for RGB images

    def __post_init__(self) -> None:
        v = len(self.cameras)
        if self.images.ndim != 4 or self.images.shape[0] != v or self.images.shape[3] != 3 or len(self.names) != v:
            raise InputError(f"split: expected images [V, H, W, 3] with V = {v} cameras and names, got "
                             f"{list(self.images.shape)} and {len(self.names)} names")
        for extra, label in ((self.depths, "depths"), (self.alphas, "alphas")):
            if extra is not None and extra.shape != self.images.shape[:3]:
                raise InputError(f"split: {label} shape {list(extra.shape)} differs from images "
                                 f"{list(self.images.shape[:3])}")

    def __len__(self) -> int:
        return len(self.cameras)


@dataclass(frozen=True)
class Dataset:
    """A loaded dataset: train and test splits, optional points, where it came from."""

    name: str                  # the folder name
    train: Split
    test: Split
    points: PointCloud | None  # COLMAP points3D, or the Blender layout's ply_file_path; None if absent
    root: Path                 # the dataset folder
    layout: str                # "colmap" or "blender"


def load_dataset(path: str | Path, *, layout: str = "auto", test_every: int = 8, images_dir: str = "images",
                 background: Sequence[float] = (0.0, 0.0, 0.0)) -> Dataset:
    """Load a COLMAP or Blender dataset folder into typed train/test splits.

    ``layout``: ``"auto"`` (COLMAP when ``sparse/`` exists, else Blender), ``"colmap"``
    or ``"blender"``. ``test_every``: hold out every n-th view when the dataset gives no
    split (0: no test views). ``images_dir`` (COLMAP only): the image folder, e.g.
    ``"images_4"`` of Mip-NeRF 360; when it is not ``"images"`` the cameras are scaled to
    the image size. ``background``: RGB in [0, 1] under RGBA images.
    """
    root = Path(path)
    if not root.is_dir():
        raise InputError(f"dataset: {str(root)!r} is not a dataset folder (it does not exist or is a file); give a "
                         "COLMAP or Blender folder, or render one with `splatbench scenes render NAME`")
    if layout not in LAYOUTS:
        raise InputError(f"layout: expected one of {', '.join(LAYOUTS)}, got {layout!r}")
    if not (isinstance(test_every, int) and not isinstance(test_every, bool) and test_every >= 0):
        raise InputError(f"test_every: expected an int >= 0, got {test_every!r}")
    bg = np.asarray(background, dtype=np.float32).reshape(-1)
    if bg.shape != (3,) or not np.all((bg >= 0) & (bg <= 1)):
        raise InputError(f"background: expected 3 values in [0, 1], got {list(background)}")
    if layout == "auto":
        if _colmap_folder(root) is not None or (root / "sparse").is_dir():
            layout = "colmap"
        elif any((root / f).is_file() for f in ("transforms_train.json", "transforms.json")):
            layout = "blender"
        else:
            raise InputError(f"dataset: {str(root)!r} holds neither a COLMAP model (sparse/0/) "
                             f"nor Blender transforms (transforms_train.json or transforms.json)")
    if layout == "colmap":
        return _load_colmap(root, test_every, images_dir, bg)
    return _load_blender(root, test_every, bg)


# ------------------------------------------------------------------------- COLMAP
def _colmap_folder(root: Path) -> Path | None:
    for sub in (root / "sparse" / "0", root / "sparse"):
        if any((sub / f"cameras.{ext}").is_file() for ext in ("bin", "txt")):
            return sub
    return None


def _load_colmap(root: Path, test_every: int, images_dir: str, bg: np.ndarray) -> Dataset:
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()

    sparse = _colmap_folder(root)
    if sparse is None:
        raise InputError(f"{root / 'sparse' / '0' / 'cameras.bin'}: missing (no COLMAP model in sparse/0/ or sparse/)")
    ext = "bin" if (sparse / "cameras.bin").is_file() else "txt"
    for part in ("cameras", "images", "points3D"):
        if not (sparse / f"{part}.{ext}").is_file():
            raise InputError(f"{sparse / f'{part}.{ext}'}: missing")
    if ext == "bin":
        check_colmap_binary(sparse)  # every count against the bytes that follow, before pycolmap allocates
    else:
        check_colmap_text(sparse)
    try:
        rec = pycolmap.Reconstruction(str(sparse))
    except Exception as exc:  # pycolmap raises ValueError/RuntimeError with a source location
        raise InputError(f"{sparse}: pycolmap cannot read the model ({str(exc).strip().splitlines()[0]})") from None
    rel_sparse = sparse.relative_to(root).as_posix()
    for cam_id, cam in sorted(rec.cameras.items()):
        if cam.model_name not in PINHOLE_MODELS:
            raise InputError(f"{rel_sparse}/cameras.{ext}: camera {cam_id} model: expected "
                             f"{' or '.join(PINHOLE_MODELS)}, got {cam.model_name!r} (undistort the images first)")
    images = sorted((im for im in rec.images.values() if im.has_pose), key=lambda im: im.name)
    if not images:
        raise InputError(f"{rel_sparse}/images.{ext}: no registered images")
    views = []
    for im in images:
        try:
            camera = Camera.from_colmap(rec.cameras[im.camera_id], im)
        except InputError as exc:  # e.g. a truncated cameras.bin read as zero focal lengths
            raise InputError(f"{sparse / f'cameras.{ext}'}: camera {im.camera_id} of image {im.name!r}: {exc} "
                             f"(a damaged model? export it from COLMAP again)") from None
        rel = f"{images_dir}/{im.name}"
        rgb, alpha = _read_image(root, rel, bg, f"named by {rel_sparse}/images.{ext}")
        camera = _fit_camera(camera, rgb, rel, scale_ok=images_dir != "images")
        views.append((rel, camera, rgb, alpha))
    names = [im.name for im in images]
    split_file = root / "split.json"
    if split_file.is_file():
        train_ids, test_ids = _given_split(split_file, names)
    else:
        test_ids = list(range(0, len(names), test_every)) if test_every else []
        train_ids = sorted(set(range(len(names))) - set(test_ids))
    points = None
    if rec.num_points3D():
        pts = [p for _, p in sorted(rec.points3D.items())]  # by point3D id
        try:
            points = PointCloud(np.array([p.xyz for p in pts], dtype=np.float64).reshape(-1, 3),
                                np.array([p.color for p in pts], dtype=np.uint8).reshape(-1, 3))
        except InputError as exc:
            raise InputError(f"{sparse / f'points3D.{ext}'}: {exc}") from None
    return Dataset(root.resolve().name, _split(root, [views[i] for i in train_ids]),
                   _split(root, [views[i] for i in test_ids]), points, root, "colmap")


def _given_split(path: Path, names: list[str]) -> tuple[list[int], list[int]]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"{path.name}: cannot read it as JSON ({exc})") from None
    index = {n: i for i, n in enumerate(names)}
    out = []
    for key in ("train", "test"):
        listed = data.get(key) if isinstance(data, dict) else None
        if not isinstance(listed, list):
            raise InputError(f"{path.name}: {key}: expected a list of image names, got {listed!r}")
        for n in listed:
            if n not in index:
                raise InputError(f"{path.name}: {key}: image {n!r} is not a registered image of the model")
        out.append(sorted(index[n] for n in listed))
    return out[0], out[1]


def _fit_camera(camera: Camera, rgb: np.ndarray, rel: str, scale_ok: bool) -> Camera:
    h, w = rgb.shape[:2]
    if (w, h) == (camera.width, camera.height):
        return camera
    if scale_ok:
        scaled = camera.scaled(w / camera.width)
        if (scaled.width, scaled.height) == (w, h):
            return scaled
    raise InputError(f"{rel}: image size {w}x{h} disagrees with its camera {camera.width}x{camera.height}")


# ------------------------------------------------------------------------ Blender
def _load_blender(root: Path, test_every: int, bg: np.ndarray) -> Dataset:
    train_file, test_file, single = (root / "transforms_train.json", root / "transforms_test.json",
                                     root / "transforms.json")
    points = None
    if train_file.is_file():
        train_meta, test_meta = _read_json(train_file), _read_json(test_file) if test_file.is_file() else None
        train = _blender_views(root, train_file.name, train_meta, bg)
        test = _blender_views(root, test_file.name, test_meta, bg) if test_meta is not None else []
        for meta, file in ((train_meta, train_file), (test_meta, test_file)):
            if points is None and meta is not None and "ply_file_path" in meta:
                points = _read_ply(root, file.name, meta["ply_file_path"])
    elif single.is_file():
        meta = _read_json(single)
        views = _blender_views(root, single.name, meta, bg)
        order = sorted(range(len(views)), key=lambda i: views[i][0])
        views = [views[i] for i in order]
        train = [v for i, v in enumerate(views) if not (test_every and i % test_every == 0)]
        test = [v for i, v in enumerate(views) if test_every and i % test_every == 0]
        if "ply_file_path" in meta:
            points = _read_ply(root, single.name, meta["ply_file_path"])
    else:
        raise InputError(f"{root / 'transforms_train.json'}: missing (nor is there a transforms.json)")
    return Dataset(root.resolve().name, _split(root, train), _split(root, test), points, root, "blender")


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"{path}: cannot read it ({exc.strerror})") from None
    except ValueError as exc:
        raise InputError(f"{path.name}: invalid JSON ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise InputError(f"{path.name}: frames: expected a list of frames")
    return data


def _blender_views(root: Path, file: str, meta: dict, bg: np.ndarray) -> list:
    shared = {k: v for k, v in meta.items() if k != "frames"}
    views = []
    for k, frame in enumerate(meta["frames"]):
        where = f"{file}: frames[{k}]"
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            raise InputError(f"{where}: expected a dict with 'file_path' and 'transform_matrix'")
        merged = {**shared, **frame}
        _check_blender_model(where, merged)
        rel = _resolve_image(root, where, str(frame["file_path"]))
        rgb, alpha = _read_image(root, rel, bg, f"named by {file}")
        h, w = rgb.shape[:2]
        if ("w" in merged or "h" in merged) and (merged.get("w"), merged.get("h")) != (w, h):
            raise InputError(f"{rel}: image size {w}x{h} disagrees with its camera "
                             f"{merged.get('w')}x{merged.get('h')} (w, h of {file})")
        try:
            camera = Camera.from_blender(merged, merged.get("camera_angle_x"), w, h)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        views.append((rel, camera, rgb, alpha))
    return views


def _check_blender_model(where: str, merged: dict) -> None:
    model = merged.get("camera_model", "PINHOLE")
    if model in PINHOLE_MODELS:
        return
    if model == "OPENCV" and all(float(merged.get(k, 0.0)) == 0.0 for k in _DISTORTION_KEYS):
        return
    raise InputError(f"{where}: camera_model: expected PINHOLE, SIMPLE_PINHOLE or OPENCV without distortion, "
                     f"got {model!r}" + (" with distortion" if model == "OPENCV" else ""))


def _resolve_image(root: Path, where: str, file_path: str) -> str:
    candidate = Path(file_path)
    tries = [candidate] if candidate.suffix.lower() in (".png", ".jpg", ".jpeg", ".exr") else []
    tries += [candidate.with_name(candidate.name + ".png"), candidate]
    for t in tries:
        if (root / t).is_file():
            return (root / t).relative_to(root).as_posix()
    raise InputError(f"{where}: file_path {file_path!r}: no such image (tried "
                     f"{', '.join(sorted({t.as_posix() for t in tries}))})")


def _read_ply(root: Path, file: str, rel: str) -> PointCloud:
    path = root / rel
    if not path.is_file():
        raise InputError(f"{file}: ply_file_path: {rel!r} does not exist")
    ply = read_ply_data(path, rel)  # counts checked against the file's size
    try:
        vertex = ply["vertex"]
        xyz = np.stack([np.asarray(vertex[a], dtype=np.float64) for a in "xyz"], axis=1)
        names = vertex.data.dtype.names
        if all(c in names for c in ("red", "green", "blue")):
            rgb = np.stack([np.asarray(vertex[c]) for c in ("red", "green", "blue")], axis=1).astype(np.uint8)
        else:
            rgb = np.full(xyz.shape, 128, dtype=np.uint8)
    except (KeyError, ValueError, OSError, TypeError) as exc:
        raise InputError(f"{rel}: cannot read the point cloud ({exc})") from None
    try:
        return PointCloud(xyz, rgb)
    except InputError as exc:
        raise InputError(f"{rel}: {exc}") from None


# ------------------------------------------------------------------------ shared
def _read_image(root: Path, rel: str, bg: np.ndarray, context: str) -> tuple[np.ndarray, np.ndarray | None]:
    path = root / rel
    if not path.is_file():
        raise InputError(f"{rel}: missing ({context})")
    arr, has_alpha = read_image_with_alpha(path, what=rel)  # decompression bombs refused
    data = arr.astype(np.float32) / 255.0
    if not has_alpha:
        return data, None
    alpha = data[..., 3]
    return data[..., :3] * alpha[..., None] + bg * (1 - alpha[..., None]), alpha


def _depth_path(root: Path, rel: str) -> Path:
    parts = Path(rel).parts
    inner = Path(*parts[1:]) if len(parts) > 1 else Path(parts[0])
    return root / "depth" / inner.with_suffix(".npy")


def _split(root: Path, views: list) -> Split:
    names = [v[0] for v in views]
    cameras = [v[1] for v in views]
    if not views:
        return Split(np.zeros((0, 0, 0, 3), np.float32), [], None, [])
    h, w = views[0][2].shape[:2]
    for rel, _, rgb, _ in views:
        if rgb.shape[:2] != (h, w):
            raise InputError(f"{rel}: image size {rgb.shape[1]}x{rgb.shape[0]} differs from {names[0]}'s {w}x{h} "
                             f"(a split needs one image size)")
    images = np.stack([v[2] for v in views]).astype(np.float32)
    alphas = None
    if any(v[3] is not None for v in views):
        alphas = np.stack([v[3] if v[3] is not None else np.ones((h, w), np.float32) for v in views])
    depths = None
    if (root / "depth").is_dir():
        maps = []
        for rel in names:
            path = _depth_path(root, rel)
            if not path.is_file():
                raise InputError(f"{path.relative_to(root).as_posix()}: missing (depth/ holds depth maps, "
                                 f"but none for {rel})")
            d = read_npy(path, what=path.relative_to(root).as_posix())
            if d.dtype.kind not in "fiu":
                raise InputError(f"{path.relative_to(root).as_posix()}: depth dtype {d.dtype}, expected float32")
            if d.shape != (h, w):
                raise InputError(f"{path.relative_to(root).as_posix()}: depth shape {list(d.shape)} disagrees "
                                 f"with its image {h}x{w}")
            maps.append(d.astype(np.float32))
        depths = np.stack(maps)
    return Split(images, cameras, depths, names, alphas)


__all__ = ["Dataset", "Split", "PointCloud", "load_dataset", "LAYOUTS", "PINHOLE_MODELS"]
