"""Multi-view datasets in the COLMAP, Blender (NeRF synthetic / nerfstudio) or LLFF layout.

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
  Image names stay inside the image folder and name one image each; camera sizes are
  checked before pycolmap works on them. PINHOLE / SIMPLE_PINHOLE cameras are used as
  they are; SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV and OPENCV_FISHEYE images are
  undistorted on load (below); any other model is refused in one line. Registered images
  are sorted by name. Split: ``split.json`` (``{"train": [names], "test": [names]}``,
  written by splatbench) when present, else every ``test_every``-th image (``i %
  test_every == 0``) is a test view, as 3DGS's ``--eval`` does.
* **Blender** -- ``transforms_train.json`` (+ ``transforms_test.json``; the given split)
  or a single nerfstudio ``transforms.json`` (every ``test_every``-th frame, sorted by
  file path, is a test view). ``file_path`` is relative to the folder, with or without
  its extension (NeRF synthetic's ``"./train/r_0"`` finds ``train/r_0.png``).
  Intrinsics: nerfstudio's / instant-ngp's ``fl_x, fl_y, cx, cy, w, h`` (top level or per
  frame) or ``camera_angle_x``; distortion ``k1 k2 k3 k4 p1 p2`` (top level or per frame)
  with ``camera_model`` OPENCV (the default when coefficients are given, as instant-ngp
  writes them: k1 k2 p1 p2, plus k3 as COLMAP's FULL_OPENCV; k4 has no OpenCV-model
  meaning and is refused) or OPENCV_FISHEYE (k1..k4; p1 p2 refused). Keys splatbench does
  not use (instant-ngp's ``aabb_scale``, ``sharpness``, ...) are ignored with a note.
  Points from ``ply_file_path`` when given. ``file_path`` and ``ply_file_path`` must be
  non-empty relative paths that stay inside the folder (no absolute path, no ``..`` above
  it; symlinks inside the folder are followed, so images may live on another disk); a
  frame naming the image of an earlier frame is refused (an image in both
  ``transforms_train.json`` and ``transforms_test.json`` gets a note); a file holding a key
  twice, a number beyond float64 or no frames is refused; a UTF-8 byte-order mark is read.

* **LLFF** -- ``poses_bounds.npy`` beside ``images/`` / ``images_N/`` (`splatbench.data.llff`:
  N x 17 rows in the order of the sorted image names, rotation columns [down, right, back],
  [h, w, f] of the originals, near and far). ``downscale`` N is relative to the originals:
  ``images_N/`` when it exists, else the nearest finer folder reduced by area averaging.
  The near/far bounds of the training views are ``Dataset.bounds``. Every 8th image by name is a test
  view. docs/captures.md has the table of layouts.

Masks, in every layout: ``masks/`` / ``masks_N/`` beside the images (`splatbench.data.masks`:
by stem with an optional ``_mask``, ``images_N/`` taking ``masks_N/``) become the views'
alphas (``masks=False`` ignores them, with a note); ``Dataset.masks`` names the folder.

Distortion: images whose camera has lens distortion are undistorted by pycolmap (COLMAP's
undistorter: bilinear remap, cropped to the pixels that saw the scene) into a cache folder
keyed by content, and returned with the PINHOLE intrinsics of the result
(`splatbench.data.undistort`); a note says so. Downscaling (``downscale=N``): the
images are resized by 1/N (PIL bicubic, as graphdeco's ``-r N``), or read from an
``images_N/`` folder beside ``images/`` when one exists (graphdeco's and Mip-NeRF 360's
copies; distorted captures are undistorted from the full images instead); the cameras
are scaled to the result. A note is added when the images' long side exceeds 1,600 px
at downscale 1 (graphdeco shrinks images wider than 1,600 px; splatbench keeps what it is given).

Real captures are opaque: nothing is composited under RGB photos (unless masks give them an alpha).

Images are held as stored, 8-bit (``Split.pixels``, uint8: a quarter of float32's
memory; NeRF-synthetic lego's 300 RGBA views at 800x800 are 0.77 GB instead of 3.1 GB),
and converted one view at a time: ``Split.image(i)`` is the view as float32 in [0, 1]
(8-bit sRGB value / 255), an RGBA view composited on ``background`` then (the same float32
operations, in the same order, as compositing at load time: bit-identical), its alpha
``Split.alpha(i)``. ``Split.images`` / ``Split.alphas`` stack every view as float32 (for
small datasets and tests; training and evaluation read view by view). Depth maps are
read from ``depth/<image path without its first folder>.npy`` (camera z) when the
dataset has a ``depth/`` folder. Every problem (missing file, image size that
disagrees with its camera, unsupported camera model) is a one-line `InputError`
naming the file and the field.

`check_dataset` runs the same loader on image headers alone (no pixel decoded, nothing
resized or undistorted, no cache written): the same one-line errors, and the layout,
view counts and served image size (`DatasetCheck`): what ``splatbench run --dry-run`` checks.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from splatbench.cameras import Camera
from splatbench.guards import check_image_size
from splatbench.data.colmap_bounds import check_colmap_binary, check_colmap_text
from splatbench.data.llff import POSES_FILE
from splatbench.data.masks import Masks, area_resize, blank, combine, folder_factor
from splatbench.data.undistort import Lens, check_lens
from splatbench.errors import InputError
from splatbench.ply import read_ply_data
from splatbench.safeio import image_header, npy_shape, read_image_with_alpha, read_npy

LAYOUTS = ("auto", "colmap", "blender", "llff")
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
    """The views of one split, in a fixed order (V views of H x W pixels).

    Pixels are held as stored (8-bit files as uint8) and converted per view by `image`
    and `alpha` (module doc); a split built from float images (rendered in memory) holds
    them as they are."""

    pixels: np.ndarray                # [V, H, W, 3] uint8 (value / 255, sRGB as stored) or float32 in [0, 1]
    cameras: list[Camera]             # V cameras, OpenCV axes (see splatbench.cameras)
    depths: np.ndarray | None         # [V, H, W] float32 camera z, 0 where nothing was hit; None if absent
    names: list[str]                  # V image paths relative to the dataset root
    alpha_pixels: np.ndarray | None = None  # [V, H, W] uint8 (value / 255) or float32 opacity of RGBA sources;
                                      # None for RGB images
    composite: np.ndarray | None = None  # [3] float32 background the views are composited on by `image`
                                      # (RGBA sources at full size); None: the pixels are final

    def __post_init__(self) -> None:
        v = len(self.cameras)
        if self.pixels.ndim != 4 or self.pixels.shape[0] != v or self.pixels.shape[3] != 3 or len(self.names) != v:
            raise InputError(f"split: expected images [V, H, W, 3] with V = {v} cameras and names, got "
                             f"{list(self.pixels.shape)} and {len(self.names)} names")
        for extra, label in ((self.pixels, "images"), (self.alpha_pixels, "alphas")):
            if extra is not None and extra.dtype != np.uint8 and extra.dtype.kind != "f":
                raise InputError(f"split: {label} dtype {extra.dtype}, expected uint8 or float")
        for extra, label in ((self.depths, "depths"), (self.alpha_pixels, "alphas")):
            if extra is not None and extra.shape != self.pixels.shape[:3]:
                raise InputError(f"split: {label} shape {list(extra.shape)} differs from images "
                                 f"{list(self.pixels.shape[:3])}")
        if self.composite is not None and self.alpha_pixels is None:
            raise InputError("split: a composite background without alphas")

    def __len__(self) -> int:
        return len(self.cameras)

    @property
    def image_size(self) -> tuple[int, int]:
        """(H, W) of every view."""
        return int(self.pixels.shape[1]), int(self.pixels.shape[2])

    def image(self, i: int) -> np.ndarray:
        """View ``i`` as float32 [H, W, 3] in [0, 1] (a new array; RGBA composited)."""
        alpha = self.alpha(i) if self.composite is not None else None
        return _as_float(self.pixels[i], alpha, self.composite)

    def alpha(self, i: int) -> np.ndarray | None:
        """The opacity of view ``i``, float32 [H, W] in [0, 1] (None for RGB images)."""
        return None if self.alpha_pixels is None else _unit(self.alpha_pixels[i])

    @property
    def images(self) -> np.ndarray:
        """Every view, float32 [V, H, W, 3] (V H W 12 bytes: training reads `image`)."""
        if len(self) == 0:
            return np.zeros((0, *self.pixels.shape[1:]), np.float32)
        return np.stack([self.image(i) for i in range(len(self))])

    @property
    def alphas(self) -> np.ndarray | None:
        """Every view's opacity, float32 [V, H, W] (None for RGB images)."""
        return None if self.alpha_pixels is None else _unit(self.alpha_pixels)


def _unit(values: np.ndarray) -> np.ndarray:
    """uint8 values / 255 as float32 (the loader's one conversion), float as float32."""
    return values.astype(np.float32) / 255.0 if values.dtype == np.uint8 else np.asarray(values, np.float32)


def _as_float(rgb: np.ndarray, alpha: np.ndarray | None, background: np.ndarray | None) -> np.ndarray:
    """``rgb`` [H, W, 3] (uint8 or float) as float32 in [0, 1], composited on ``background``
    with ``alpha`` (float32 [H, W]) when both are given: ``rgb a + bg (1 - a)``."""
    data = _unit(rgb)
    if alpha is None or background is None:
        return data
    return data * alpha[..., None] + background * (1 - alpha[..., None])


@dataclass(frozen=True)
class Dataset:
    """A loaded dataset: train and test splits, optional points, where it came from."""

    name: str                  # the folder name
    train: Split
    test: Split
    points: PointCloud | None  # COLMAP points3D, or the Blender layout's ply_file_path; None if absent
    root: Path                 # the dataset folder
    layout: str                # "colmap", "blender" or "llff"
    notes: tuple[str, ...] = ()  # what loading did that the user should know (undistortion, ignored keys)
    masks: str = ""            # the mask folder the views' alphas were read from ("masks_8"); "" when none was
    bounds: np.ndarray | None = None  # [V, 2] float64 near, far depth of each training view (LLFF's bounds);
                                      # None when the layout gives none


@dataclass(frozen=True)
class DatasetCheck:
    """What `check_dataset` found: the dataset `load_dataset` would return, without its pixels."""

    name: str                  # the folder name
    layout: str                # "colmap", "blender" or "llff"
    train_views: int
    test_views: int
    width: int                 # of the views as served (after downscale and undistortion); 0 without views
    height: int
    masks: str                 # the mask folder the views' alphas would be read from; "" when none
    notes: tuple[str, ...]     # load_dataset's notes (the undistortion's says it was not run)


def load_dataset(path: str | Path, *, layout: str = "auto", test_every: int = 8, images_dir: str = "images",
                 background: Sequence[float] = (0.0, 0.0, 0.0), downscale: int = 1, masks: bool = True,
                 say: Callable[[str], None] | None = None) -> Dataset:
    """Load a COLMAP, Blender or LLFF dataset folder into typed train/test splits.

    ``layout``: ``"auto"`` (COLMAP when ``sparse/`` exists, else Blender when a
    transforms file does, else LLFF when ``poses_bounds.npy`` does), ``"colmap"``,
    ``"blender"`` or ``"llff"``. ``masks``: read ``masks/`` / ``masks_N/`` as the
    views' alphas, in every layout (False: ignore them, with a note). ``test_every``: hold out every n-th view when the dataset gives no
    split (0: no test views). ``images_dir`` (COLMAP only): the image folder, e.g.
    ``"images_4"`` of Mip-NeRF 360; when it is not ``"images"`` the cameras are scaled to
    the image size. ``background``: RGB in [0, 1] under RGBA images. ``downscale``: an
    int >= 1 dividing the image size (``images_N/`` is read when present). ``say`` gets
    one line before anything slow (undistortion); the same lines are in ``Dataset.notes``.
    """
    return _load(path, layout, test_every, images_dir, background, downscale, masks, say, headers_only=False)


def check_dataset(path: str | Path, *, layout: str = "auto", test_every: int = 8, images_dir: str = "images",
                  downscale: int = 1, masks: bool = True) -> DatasetCheck:
    """`load_dataset`'s checks, cheaply: the same code reading file names, image headers and
    the small files (poses, transforms, a COLMAP model, depth maps' headers) but decoding no
    pixel, resizing nothing and undistorting nothing (a distorted camera's undistorted size is
    pycolmap's camera alone, `splatbench.data.undistort.undistorted_cameras`); no cache is
    written. Raises the one `InputError` line `load_dataset` would raise for the same folder
    and options (a wrong layout, counts that disagree, a missing or misnamed mask, a downscale
    no image folder serves, an image whose size disagrees with its camera), except what only
    decoding finds (a damaged pixel stream). What a dry run checks (``splatbench run --dry-run``)."""
    ds = _load(path, layout, test_every, images_dir, (0.0, 0.0, 0.0), downscale, masks, None, headers_only=True)
    views = ds.train if len(ds.train) else ds.test
    height, width = views.image_size if len(views) else (0, 0)
    return DatasetCheck(ds.name, ds.layout, len(ds.train), len(ds.test), width, height, ds.masks, ds.notes)


def _load(path: str | Path, layout: str, test_every: int, images_dir: str, background: Sequence[float],
          downscale: int, masks: bool, say: Callable[[str], None] | None, *, headers_only: bool) -> Dataset:
    """`load_dataset`, or with ``headers_only`` its checks alone (`check_dataset`): the
    views' pixels are then read-only zeros of their size that take no memory."""
    root = Path(path)
    if not root.is_dir():
        raise InputError(f"dataset: {str(root)!r} is not a dataset folder (it does not exist or is a file); give a "
                         "capture folder in a layout splatbench reads (COLMAP's sparse/0/ + images/, Blender's or "
                         "instant-ngp's transforms*.json, LLFF's poses_bounds.npy + images/), or render one with "
                         "`splatbench scenes render NAME`")
    if layout not in LAYOUTS:
        raise InputError(f"layout: expected one of {', '.join(LAYOUTS)}, got {layout!r}")
    if not (isinstance(test_every, int) and not isinstance(test_every, bool) and test_every >= 0):
        raise InputError(f"test_every: expected an int >= 0, got {test_every!r}")
    if not (isinstance(downscale, int) and not isinstance(downscale, bool) and downscale >= 1):
        raise InputError(f"downscale: expected an int >= 1, got {downscale!r}")
    bg = np.asarray(background, dtype=np.float32).reshape(-1)
    if bg.shape != (3,) or not np.all((bg >= 0) & (bg <= 1)):
        raise InputError(f"background: expected 3 values in [0, 1], got {list(background)}")
    if layout == "auto":
        if colmap_folder(root) is not None or (root / "sparse").is_dir():
            layout = "colmap"
        elif any((root / f).is_file() for f in ("transforms_train.json", "transforms.json")):
            layout = "blender"
        elif (root / POSES_FILE).is_file():
            layout = "llff"
        else:
            raise InputError(f"dataset: {str(root)!r} holds neither a COLMAP model (sparse/0/), Blender transforms "
                             f"(transforms_train.json or transforms.json) nor LLFF's {POSES_FILE}: not a capture "
                             f"folder; give the folder that holds one of them")
    if not isinstance(masks, bool):
        raise InputError(f"masks: expected true or false, got {masks!r}")
    load = _Load(root, bg, downscale, say or (lambda line: None), headers_only)
    load.masks = Masks(root, masks, load.note, headers_only=headers_only)
    if layout == "colmap":
        dataset = _load_colmap(root, test_every, images_dir, load)
        if (root / POSES_FILE).is_file():
            load.note(f"{POSES_FILE} is here too: read the COLMAP model (its points start training; "
                      f"data.layout=llff reads {POSES_FILE} instead)")
    elif layout == "llff":
        dataset = _load_llff(root, test_every, load)
    else:
        dataset = _load_blender(root, test_every, load)
    used = load.masks.finish()
    return dataclasses.replace(dataset, masks=used, notes=tuple(load.finish_notes(dataset)))


class _Load:
    """What every loader shares: the options, the notes, and the views waiting for undistortion."""

    def __init__(self, root: Path, bg: np.ndarray, downscale: int, say: Callable[[str], None],
                 headers_only: bool = False) -> None:
        self.root, self.bg, self.downscale, self.say = root, bg, downscale, say
        self.headers_only = headers_only  # `check_dataset`: image headers read, no pixel decoded (`blank`)
        self.notes: list[str] = []
        self.pending: list[tuple[list, int, str, Camera, Lens]] = []  # (views, index, rel, posed camera, lens)
        self.masks: Masks  # the capture's object masks (set by load_dataset)

    def note(self, line: str) -> None:
        if line not in self.notes:
            self.notes.append(line)
            self.say(line)

    def image_dir(self, images_dir: str) -> str:
        """``images_N`` instead of ``images`` when downscaling and the folder exists."""
        alt = f"{images_dir}_{self.downscale}"
        if self.downscale > 1 and images_dir == "images" and (self.root / alt).is_dir():
            self.note(f"downscale {self.downscale}: reading {alt}/ (the capture's own downscaled copies, "
                      f"as graphdeco reads them)")
            return alt
        return images_dir

    def view(self, rel: str, camera: Camera, context: str, *, scale_ok: bool = False, resize: bool = True) -> tuple:
        """(rel, camera, rgb, alpha, final) of an undistorted image: the camera fitted to
        the file (scaled to it when ``scale_ok``), its mask (if the capture has masks) made
        its alpha, then both downscaled when ``resize``. ``rgb`` and ``alpha`` are uint8;
        ``final``: rgb needs no compositing (an RGB image, or RGBA composited before
        downscaling, as graphdeco resizes the composited image)."""
        rgb, alpha = _read_image(self.root, rel, context, self.headers_only)
        if self.masks.enabled:  # at the file's size: images_N/ takes masks_N/ (or a finer folder, reduced)
            folder = Path(rel).parts[0] if len(Path(rel).parts) > 1 else ""
            factor = folder_factor(folder) if folder.startswith("images") else 1
            mfolder = self.masks.folder_for(factor, f"{folder or rel}/ (images reduced by {factor})")
            size = (rgb.shape[1], rgb.shape[0])
            mask = self.masks.read(self.masks.file(mfolder, rel), rel, size,
                                   size if self.masks.folders.get(factor) == mfolder else None)
            alpha = self.combine(alpha, mask)
        camera = _fit_camera(camera, rgb, rel, scale_ok=scale_ok)
        if not resize or self.downscale == 1:
            return rel, camera, rgb, alpha, alpha is None
        camera = camera.scaled(1 / self.downscale)
        if alpha is not None and not self.headers_only:  # composited at full size, quantised to 8 bits, then resized
            composited = _as_float(rgb, _unit(alpha), self.bg)
            rgb = np.clip(np.rint(composited * 255.0), 0, 255).astype(np.uint8)
        rgb = self.resize(rgb, camera.width, camera.height)
        alpha = None if alpha is None else self.resize(alpha, camera.width, camera.height)
        return rel, camera, rgb, alpha, True

    def resize(self, image: np.ndarray, width: int, height: int, *, area: bool = False) -> np.ndarray:
        """``image`` resized to ``width`` x ``height`` (`area_resize` when ``area``, else PIL
        bicubic); headers only: zeros of that size."""
        if self.headers_only:
            return blank((height, width, *image.shape[2:]))
        return area_resize(image, width, height) if area else _resize(image, width, height)

    def combine(self, alpha: np.ndarray | None, mask: np.ndarray) -> np.ndarray:
        """`combine` of a photo's alpha and its mask (headers only: zeros of the mask's size)."""
        return blank(mask.shape) if self.headers_only else combine(alpha, mask)

    def defer(self, views: list, rel: str, camera: Camera, lens: Lens) -> None:
        """Leave a slot in ``views`` for an image to undistort (`finish` fills it)."""
        if self.masks.enabled:
            self.masks.refuse_distortion(rel, lens.model)
        views.append(None)
        self.pending.append((views, len(views) - 1, rel, camera, lens))

    def finish(self) -> None:
        """Undistort every deferred view (one cached pycolmap pass) and fill its slot."""
        if not self.pending:
            return
        from splatbench.data.undistort import undistort_views, undistorted_cameras

        models = sorted({p[4].model for p in self.pending})
        sources = [(self.root / p[2], p[4]) for p in self.pending]
        if self.headers_only:
            done, folder, cached = undistorted_cameras(sources, downscale=self.downscale), None, False
        else:
            done, folder, cached = undistort_views(sources, downscale=self.downscale, say=self.say)
        for (_, _, rel, _, lens), u in zip(self.pending, done):
            # COLMAP's undistorter crops to the pixels that saw the scene: a real lens keeps most of them
            # (the fox's OPENCV lens: about 98 % of each side at downscale 8); coefficients that leave
            # under a quarter of a side describe no lens, and the views would be trained at a few pixels
            kept_w, kept_h = u.width * self.downscale / lens.width, u.height * self.downscale / lens.height
            if min(kept_w, kept_h) < 0.25:
                raise InputError(f"{rel}: undistorting its {lens.model} camera {list(lens.params)[4:]} keeps "
                                 f"{u.width * self.downscale}x{u.height * self.downscale} of {lens.width}x"
                                 f"{lens.height} pixels (implausible distortion coefficients; check them)")
        first = done[0]
        self.note(f"{len(done)} images with {'/'.join(models)} lens distortion "
                  f"{'would be ' if folder is None else ''}undistorted by pycolmap (COLMAP's "
                  f"undistorter, cropped to valid pixels: {first.width}x{first.height} PINHOLE"
                  f"{f' after downscale {self.downscale}' if self.downscale > 1 else ''}, focal "
                  f"{first.fx:.6g} x {first.fy:.6g} px); "
                  + ("not run: a dry check" if folder is None else f"{'reused' if cached else 'cached in'} {folder}"))
        for (views, i, rel, camera, _), u in zip(self.pending, done):
            if self.headers_only:
                rgb, alpha = blank((u.height, u.width, 3)), None
            else:
                rgb, alpha = _read_image(u.path.parent, u.path.name, f"undistorted from {rel}")
            if alpha is not None:  # composited as read (float); the alpha is not kept
                rgb = _as_float(rgb, _unit(alpha), self.bg)
            views[i] = (rel, Camera(u.width, u.height, u.fx, u.fy, u.cx, u.cy, camera.world_to_camera,
                                    camera.near, camera.far), rgb, None, True)
        self.pending = []

    def finish_notes(self, dataset: Dataset) -> list[str]:
        views = dataset.train if len(dataset.train) else dataset.test
        if self.downscale == 1 and len(views) and max(views.image_size) > 1600:
            h, w = views.image_size
            would = "would shrink these" if w > 1600 else "would keep these (it checks the width only)"
            self.note(f"images are {w}x{h}: the long side exceeds 1600 px (graphdeco's train.py shrinks images wider "
                      f"than 1600 px to 1600 and {would}); splatbench keeps them (data.downscale=N trains smaller)")
        return self.notes


def _resize(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` [H, W(, C)] uint8 resized by PIL bicubic (graphdeco's PIL resize), uint8."""
    from PIL import Image

    return np.asarray(Image.fromarray(image).resize((width, height), Image.Resampling.BICUBIC))


# ------------------------------------------------------------------------- COLMAP
def colmap_folder(root: Path) -> Path | None:
    """The folder of the dataset folder ``root``'s COLMAP model (``sparse/0/`` or ``sparse/``, the
    first holding ``cameras.bin`` or ``cameras.txt``); None when it has none."""
    for sub in (root / "sparse" / "0", root / "sparse"):
        if any((sub / f"cameras.{ext}").is_file() for ext in ("bin", "txt")):
            return sub
    return None


def _load_colmap(root: Path, test_every: int, images_dir: str, load: _Load) -> Dataset:
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()

    sparse = colmap_folder(root)
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
        for part in ("cameras", "images", "points3D"):  # COLMAP ends every line with a newline
            data = (sparse / f"{part}.txt").read_bytes()
            if data and not data.endswith(b"\n"):
                last = data.rstrip().rsplit(b"\n", 1)[-1].decode("utf-8", "replace")
                load.note(f"{sparse.relative_to(root).as_posix()}/{part}.txt: its last line has no newline (a "
                          f"truncated copy? it reads {last[-40:]!r})")
    try:
        rec = pycolmap.Reconstruction(str(sparse))
    except Exception as exc:  # pycolmap raises ValueError/RuntimeError with a source location
        raise InputError(f"{sparse}: pycolmap cannot read the model ({str(exc).strip().splitlines()[0]})") from None
    rel_sparse = sparse.relative_to(root).as_posix()
    lenses: dict[int, Lens] = {}
    for cam_id, cam in sorted(rec.cameras.items()):
        # pycolmap reads "-6" as 2^64 - 6: undistort_camera would walk that many border pixels
        check_image_size(int(cam.width), int(cam.height), field=f"{rel_sparse}/cameras.{ext}: camera {cam_id}: "
                         f"width, height", memory=False)
        if cam.model_name not in PINHOLE_MODELS:
            lens = Lens(cam.model_name, int(cam.width), int(cam.height), tuple(float(p) for p in cam.params))
            check_lens(lens, f"{rel_sparse}/cameras.{ext}: camera {cam_id}")
            lenses[cam_id] = lens
    images = sorted((im for im in rec.images.values() if im.has_pose), key=lambda im: im.name)
    if not images:
        raise InputError(f"{rel_sparse}/images.{ext}: no registered images")
    named: dict[str, int] = {}
    for im in images:
        where = f"{rel_sparse}/images.{ext}: image {im.image_id}"
        _inside(root / images_dir, where, "name", im.name, f"image names are relative to {images_dir}/",
                folder="the image folder")
        if im.name in named:
            raise InputError(f"{where}: name {im.name!r} is also the name of image {named[im.name]} (two records "
                             f"of one photo; keep one)")
        named[im.name] = im.image_id
    folder = load.image_dir(images_dir) if len(lenses) < len(rec.cameras) else images_dir
    views: list = []
    for im in images:
        cam = rec.cameras[im.camera_id]
        lens = lenses.get(im.camera_id)
        if lens is not None:  # the photo's size first: undistort_camera's work grows with the camera's size
            rel = f"{images_dir}/{im.name}"
            size = _image_size(root, rel, f"named by {rel_sparse}/images.{ext}")
            if size != (lens.width, lens.height):
                raise InputError(f"{rel}: image size {size[0]}x{size[1]} disagrees with its camera "
                                 f"{lens.width}x{lens.height} (camera {im.camera_id} of {rel_sparse}/cameras.{ext})")
        try:  # the pose (and, for a pinhole camera, the intrinsics)
            camera = Camera.from_colmap(cam if lens is None else pycolmap.undistort_camera(
                pycolmap.UndistortCameraOptions(), cam), im)
        except InputError as exc:  # e.g. a truncated cameras.bin read as zero focal lengths
            raise InputError(f"{sparse / f'cameras.{ext}'}: camera {im.camera_id} of image {im.name!r}: {exc} "
                             f"(a damaged model? export it from COLMAP again)") from None
        if lens is not None:
            rel = f"{images_dir}/{im.name}"
            if not (root / rel).is_file():
                raise InputError(f"{rel}: missing (named by {rel_sparse}/images.{ext})")
            load.defer(views, rel, camera, lens)
            continue
        rel = f"{folder}/{im.name}"
        views.append(load.view(rel, camera, f"named by {rel_sparse}/images.{ext}", scale_ok=folder != "images",
                               resize=folder == images_dir))
    load.finish()
    names = [im.name for im in images]
    split_file = root / "split.json"
    if split_file.is_file():
        train_ids, test_ids = _given_split(split_file, names)
    else:
        test_ids = list(range(0, len(names), test_every)) if test_every else []
        train_ids = sorted(set(range(len(names))) - set(test_ids))
        if test_every:
            load.note(f"no split.json: every {test_every}th image by sorted name is a test view ({len(test_ids)} "
                      f"test, {len(train_ids)} train; as graphdeco's --eval)")
    points = None
    if rec.num_points3D():
        pts = [p for _, p in sorted(rec.points3D.items())]  # by point3D id
        try:
            points = PointCloud(np.array([p.xyz for p in pts], dtype=np.float64).reshape(-1, 3),
                                np.array([p.color for p in pts], dtype=np.uint8).reshape(-1, 3))
        except InputError as exc:
            raise InputError(f"{sparse / f'points3D.{ext}'}: {exc}") from None
    return Dataset(root.resolve().name, _split(root, [views[i] for i in train_ids], load),
                   _split(root, [views[i] for i in test_ids], load), points, root, "colmap")


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
def _load_blender(root: Path, test_every: int, load: _Load) -> Dataset:
    train_file, test_file, single = (root / "transforms_train.json", root / "transforms_test.json",
                                     root / "transforms.json")
    points = None
    if train_file.is_file():
        train_meta = _read_json(train_file)
        test_meta = _read_json(test_file, frames_required=False) if test_file.is_file() else None
        train = _blender_views(root, train_file.name, train_meta, load)
        test = _blender_views(root, test_file.name, test_meta, load) if test_meta is not None else []
        load.finish()
        both = sorted({v[0] for v in train} & {v[0] for v in test})
        if both:
            load.note(f"{len(both)} images are both training and test views ({', '.join(both[:3])}"
                      f"{', ...' if len(both) > 3 else ''}, named by {train_file.name} and {test_file.name}): "
                      f"their test scores measure fitting, not novel views")
        for meta, file in ((train_meta, train_file), (test_meta, test_file)):
            if points is None and meta is not None and "ply_file_path" in meta:
                points = _read_ply(root, file.name, meta["ply_file_path"])
    elif single.is_file():
        meta = _read_json(single)
        views = _blender_views(root, single.name, meta, load)
        load.finish()
        order = sorted(range(len(views)), key=lambda i: views[i][0])
        views = [views[i] for i in order]
        train = [v for i, v in enumerate(views) if not (test_every and i % test_every == 0)]
        test = [v for i, v in enumerate(views) if test_every and i % test_every == 0]
        if test_every and views:
            load.note(f"{single.name} gives no split: every {test_every}th image by sorted name is a test view "
                      f"({len(test)} test, {len(train)} train; as graphdeco's --eval)")
        if "ply_file_path" in meta:
            points = _read_ply(root, single.name, meta["ply_file_path"])
    else:
        raise InputError(f"{root / 'transforms_train.json'}: missing (nor is there a transforms.json)")
    return Dataset(root.resolve().name, _split(root, train, load), _split(root, test, load), points, root,
                   "blender")


# --------------------------------------------------------------------------- LLFF
def _load_llff(root: Path, test_every: int, load: _Load) -> Dataset:
    """``poses_bounds.npy`` with ``images/`` / ``images_N/`` (and ``masks/`` / ``masks_N/``):
    `splatbench.data.llff`. ``downscale`` N is relative to the poses' original size, as
    gsplat's ``data_factor``: ``images_N/`` when it exists, else the nearest finer
    ``images_M/`` reduced by N/M by area averaging; masks likewise (`splatbench.data.masks`)."""
    from splatbench.data import llff
    n = load.downscale
    image_folders = llff.folders(root, "images")
    if not image_folders:
        raise InputError(f"{root / POSES_FILE}: no images/ or images_N/ folder beside it (LLFF's layout keeps "
                         f"the photos there)")
    factor = n if n in image_folders else max((m for m in image_folders if m < n), default=None)
    folder = image_folders[factor if factor is not None else min(image_folders)]
    names = llff.image_files(root / folder)
    if not names:
        raise InputError(f"{folder}/: no images ({', '.join(llff.IMAGE_SUFFIXES)}) beside {POSES_FILE}")
    poses = root / POSES_FILE
    rows = llff.read_poses_bounds(poses, len(names), folder)
    height, width, focal = rows[0, [4, 9, 14]]
    if factor is None:
        raise InputError(f"data.downscale={n}: no image folder serves it ({POSES_FILE}'s images are "
                         f"{width:.0f}x{height:.0f}; available factors {', '.join(map(str, image_folders))} "
                         f"from {', '.join(f + '/' for f in image_folders.values())}, and a folder is reduced, never "
                         f"enlarged); set data.downscale to one of them or larger")
    masks = load.masks
    mask_folder = masks.folder_for(n, f"data.downscale={n}") if masks.enabled else ""
    views, bounds = [], []
    for i, name in enumerate(names):
        rel = f"{folder}/{name}"
        camera, near, far = llff.camera_from_row(rows[i], f"{poses}: row {i} ({rel})")
        rgb, alpha = _read_image(root, rel, f"listed in {folder}/", load.headers_only)
        rgb_size = (rgb.shape[1], rgb.shape[0])
        read = _fit_camera(camera, rgb, rel, scale_ok=True)  # the folder's size; focal scaled to it
        target = read if factor == n else camera.scaled(1 / n)
        size = (target.width, target.height)
        rgb = rgb if rgb.shape[1::-1] == size else load.resize(rgb, *size, area=True)
        alpha = alpha if alpha is None or alpha.shape[::-1] == size else load.resize(alpha, *size, area=True)
        if mask_folder:  # the mask folder of the image folder's own factor holds masks of its images' size
            exact = rgb_size if masks.folders.get(factor) == mask_folder else None
            alpha = load.combine(alpha, masks.read(masks.file(mask_folder, rel), rel, size, exact))
        views.append((rel, target, rgb, alpha, alpha is None))  # alpha composited per view (Split.image)
        bounds.append((near, far))
    first = views[0][1]
    load.note(f"LLFF layout: {POSES_FILE}, {len(names)} views of {width:.0f}x{height:.0f} originals (focal "
              f"{focal:.6g} px); {folder}/ read" + (f" at {first.width}x{first.height}" if factor == n else
              f" and reduced by {n / factor:g} to {first.width}x{first.height} by area averaging (no images_{n}/; "
              f"data.downscale={n} of the originals)") + f", focal scaled to {first.fx:.6g} px")
    order = list(range(len(views)))
    test_ids = [i for i in order if test_every and i % test_every == 0]
    train_ids = [i for i in order if not (test_every and i % test_every == 0)]
    if test_every:
        load.note(f"{POSES_FILE} gives no split: every {test_every}th image by sorted name is a test view "
                  f"({len(test_ids)} test, {len(train_ids)} train; as graphdeco's --eval)")
    return Dataset(root.resolve().name, _split(root, [views[i] for i in train_ids], load),
                   _split(root, [views[i] for i in test_ids], load), None, root, "llff",
                   bounds=np.array([bounds[i] for i in train_ids], np.float64).reshape(-1, 2))


def _read_json(path: Path, *, frames_required: bool = True) -> dict:
    """The JSON object of a transforms file: UTF-8 (a byte-order mark allowed), each key once,
    every number within float range, ``frames`` a list (non-empty when ``frames_required``)."""
    def pairs(items: list[tuple[str, object]]) -> dict:
        out: dict = {}
        for key, value in items:
            if key in out:
                raise InputError(f"{path.name}: key {key!r} is given twice in one object (which one is meant? "
                                 f"keep one)")
            out[key] = value
        return out

    def number(text: str) -> float:
        value = float(text)
        if not math.isfinite(value):  # 1e400: beyond float64, not "Infinity" (written as a word)
            raise InputError(f"{path.name}: number {text[:40]!r}{'...' if len(text) > 40 else ''} is beyond "
                             f"float64's range")
        return value

    def integer(text: str) -> int | float:
        if len(text.lstrip("-")) > 308:  # beyond float64's range: no field splatbench reads can hold it
            raise InputError(f"{path.name}: integer of {len(text)} digits is beyond float64's range")
        return int(text)

    try:
        data = json.loads(path.read_bytes().decode("utf-8-sig"), object_pairs_hook=pairs, parse_float=number,
                          parse_int=integer)
    except OSError as exc:
        raise InputError(f"{path}: cannot read it ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path.name}: not UTF-8 text (byte {exc.start}); save it as UTF-8 JSON") from None
    except RecursionError:
        raise InputError(f"{path.name}: JSON nested too deeply to be a transforms file") from None
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(f"{path.name}: invalid JSON ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise InputError(f"{path.name}: expected a JSON object with a 'frames' list, got a {type(data).__name__}")
    if not isinstance(data.get("frames"), list):
        raise InputError(f"{path.name}: frames: expected a list of frames, got {_short(data.get('frames'))}")
    if frames_required and not data["frames"]:
        raise InputError(f"{path.name}: frames: the list is empty (a capture needs at least one view)")
    return data


def _short(value: object) -> str:
    """``repr(value)`` cut to 60 characters, for one-line messages about values from a file."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


#: transforms.json keys read (top level or per frame); others are ignored with a note.
_BLENDER_KEYS = frozenset({"frames", "file_path", "transform_matrix", "camera_angle_x", "camera_angle_y", "fl_x",
                           "fl_y", "cx", "cy", "w", "h", "camera_model", "ply_file_path", *_DISTORTION_KEYS})

#: the numeric scalars among them (JSON numbers only: "1375.52", true or null are refused)
_BLENDER_NUMBERS = ("camera_angle_x", "camera_angle_y", "fl_x", "fl_y", "cx", "cy", "w", "h", *_DISTORTION_KEYS)


def _blender_views(root: Path, file: str, meta: dict, load: _Load) -> list:
    shared = {k: v for k, v in meta.items() if k != "frames"}
    ignored = set(shared) - _BLENDER_KEYS
    views: list = []
    seen: dict[str, int] = {}  # image -> the frame that named it first
    for k, frame in enumerate(meta["frames"]):
        where = f"{file}: frames[{k}]"
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            raise InputError(f"{where}: expected a dict with 'file_path' and 'transform_matrix'")
        ignored |= set(frame) - _BLENDER_KEYS  # and what is read at the top level only:
        ignored |= {f"frames[].{key}" for key in ("frames", "ply_file_path") if key in frame}
        merged = {**shared, **frame}
        rel = _resolve_image(root, where, frame["file_path"])
        if rel in seen:
            raise InputError(f"{where}: file_path {_short(frame['file_path'])} names {rel}, as frames[{seen[rel]}] "
                             f"does (a duplicated frame; keep one)")
        seen[rel] = k
        for key in _BLENDER_NUMBERS:  # at the boundary: a string or flag is never read as a number
            if key in merged and (merged[key] is None or isinstance(merged[key], (bool, str, list, dict))):
                raise InputError(f"{where if key in frame else file}: {key}: expected a number, got "
                                 f"{'null' if merged[key] is None else _short(merged[key])}")
        w, h = _image_size(root, rel, f"named by {file}")
        if ("w" in merged or "h" in merged) and (merged.get("w"), merged.get("h")) != (w, h):
            raise InputError(f"{rel}: image size {w}x{h} disagrees with its camera "
                             f"{merged.get('w')}x{merged.get('h')} (w, h of {file})")
        try:
            camera = Camera.from_blender(merged, merged.get("camera_angle_x"), w, h)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        lens = _blender_lens(where, merged, camera)
        if lens is not None:
            load.defer(views, rel, camera, lens)
            continue
        parts = Path(rel).parts
        folder = load.image_dir(parts[0]) if len(parts) > 1 else parts[0]
        alt = Path(folder, *parts[1:]).as_posix()
        views.append(load.view(alt, camera, f"named by {file}", scale_ok=alt != rel, resize=alt == rel))
    if ignored:
        load.note(f"{file}: ignored keys {', '.join(sorted(ignored))} (not used by splatbench)")
    return views


def _blender_lens(where: str, merged: dict, camera: Camera) -> Lens | None:
    """The frame's distorted camera as COLMAP names it, None when it has no distortion;
    a one-line `InputError` for what COLMAP's models cannot express."""
    coef = {}
    for key in _DISTORTION_KEYS:
        try:
            if isinstance(merged.get(key), (bool, str)):  # float(True) is 1.0, float("0.1") 0.1: not numbers
                raise TypeError
            coef[key] = float(merged.get(key, 0.0))
        except (TypeError, ValueError):
            raise InputError(f"{where}: {key}: expected a number, got {merged.get(key)!r}") from None
        if not np.isfinite(coef[key]):
            raise InputError(f"{where}: {key}: expected a finite number, got {merged.get(key)!r}")
    given = [k for k in _DISTORTION_KEYS if coef[k] != 0.0]
    model = merged.get("camera_model", "OPENCV" if given else "PINHOLE")
    pinhole = (camera.fx, camera.fy, camera.cx, camera.cy)
    size = (camera.width, camera.height)
    if model in PINHOLE_MODELS:
        if given:
            raise InputError(f"{where}: camera_model {model} with distortion {', '.join(given)}: a pinhole camera "
                             f"has none (set camera_model to OPENCV or OPENCV_FISHEYE, or remove the coefficients)")
        return None
    if model == "OPENCV":
        if coef["k4"]:
            raise InputError(f"{where}: k4: an OPENCV camera has no k4 term (COLMAP's and OpenCV's k4 divides, "
                             f"nerfstudio's multiplies r^8); undistort the images first")
        if not given:
            return None
        k1, k2, k3, p1, p2 = (coef[k] for k in ("k1", "k2", "k3", "p1", "p2"))
        if k3:
            return Lens("FULL_OPENCV", *size, (*pinhole, k1, k2, p1, p2, k3, 0.0, 0.0, 0.0))
        return Lens("OPENCV", *size, (*pinhole, k1, k2, p1, p2))
    if model == "OPENCV_FISHEYE":
        if coef["p1"] or coef["p2"]:
            raise InputError(f"{where}: p1, p2: an OPENCV_FISHEYE camera has no tangential terms")
        return Lens("OPENCV_FISHEYE", *size, (*pinhole, coef["k1"], coef["k2"], coef["k3"], coef["k4"]))
    raise InputError(f"{where}: camera_model: expected PINHOLE, SIMPLE_PINHOLE, OPENCV or OPENCV_FISHEYE, "
                     f"got {model!r}")


def _image_size(root: Path, rel: str, context: str) -> tuple[int, int]:
    from PIL import Image

    if not (root / rel).is_file():
        raise InputError(f"{rel}: missing ({context})")
    try:
        with Image.open(root / rel) as im:
            return im.size
    except (OSError, Image.DecompressionBombError) as exc:
        raise InputError(f"{rel}: cannot read the image ({exc})") from None


def _inside(root: Path, where: str, field: str, value: object, fix: str, folder: str = "the capture folder") -> Path:
    """``value`` as a relative path inside ``root``: a non-empty string, not absolute, no
    ``..`` that leaves the folder, no NUL; one `InputError` line naming ``where`` and
    ``field`` otherwise. (Symlinks inside the folder are followed: a capture may keep its
    images on another disk.)"""
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"{where}: {field}: expected a path relative to the capture folder, got {_short(value)}")
    if "\0" in value or len(value) > 4096:
        raise InputError(f"{where}: {field}: {_short(value)} is not a file path")
    norm = os.path.normpath(value)
    if any(len(part.encode("utf-8", "surrogatepass")) > 255 for part in norm.split("/")):
        raise InputError(f"{where}: {field}: {_short(value)} has a name longer than file systems allow (255 bytes)")
    if os.path.isabs(value) or value.startswith("~") or norm == ".." or norm.startswith("../"):
        raise InputError(f"{where}: {field}: {_short(value)} leaves {folder} {str(root)!r} "
                         f"(files of a capture are read from inside it only; {fix})")
    if norm == ".":
        raise InputError(f"{where}: {field}: {_short(value)} names {folder}, not a file")
    return Path(norm)


def _resolve_image(root: Path, where: str, file_path: object) -> str:
    candidate = _inside(root, where, "file_path", file_path, "copy the images into the capture folder and name "
                        "them relative to it")
    tries = [candidate] if candidate.suffix.lower() in (".png", ".jpg", ".jpeg", ".exr") else []
    tries += [candidate.with_name(candidate.name + ".png"), candidate]
    for t in tries:
        try:
            if (root / t).is_file():
                return t.as_posix()
        except OSError as exc:  # e.g. a name longer than the file system allows
            raise InputError(f"{where}: file_path {_short(file_path)}: {exc.strerror}") from None
    raise InputError(f"{where}: file_path {_short(file_path)}: no such image (tried "
                     f"{', '.join(sorted({t.as_posix() for t in tries}))})")


def _read_ply(root: Path, file: str, value: object) -> PointCloud:
    rel = _inside(root, file, "ply_file_path", value, "copy the point cloud into the capture folder").as_posix()
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
def _read_image(root: Path, rel: str, context: str, headers_only: bool = False
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """(rgb [H, W, 3], alpha [H, W] or None) of an image file, uint8 as stored (``headers_only``:
    `blank` of the header's size)."""
    path = root / rel
    if not path.is_file():
        raise InputError(f"{rel}: missing ({context})")
    if headers_only:
        width, height, has_alpha = image_header(path, what=rel)  # decompression bombs refused
        return blank((height, width, 3)), blank((height, width)) if has_alpha else None
    arr, has_alpha = read_image_with_alpha(path, what=rel)  # decompression bombs refused
    if not has_alpha:
        return arr, None
    return np.ascontiguousarray(arr[..., :3]), np.ascontiguousarray(arr[..., 3])


def _depth_path(root: Path, rel: str) -> Path:
    parts = Path(rel).parts
    inner = Path(*parts[1:]) if len(parts) > 1 else Path(parts[0])
    return root / "depth" / inner.with_suffix(".npy")


def _split(root: Path, views: list, load: _Load) -> Split:
    names = [v[0] for v in views]
    cameras = [v[1] for v in views]
    if not views:
        return Split(np.zeros((0, 0, 0, 3), np.uint8), [], None, [])
    h, w = views[0][2].shape[:2]
    for rel, _, rgb, _, _ in views:
        if rgb.shape[:2] != (h, w):
            raise InputError(f"{rel}: image size {rgb.shape[1]}x{rgb.shape[0]} differs from {names[0]}'s {w}x{h} "
                             f"(a split needs one image size)")
    alphas = None
    if load.headers_only and any(v[3] is not None for v in views):
        alphas = blank((len(views), h, w))
    elif any(v[3] is not None for v in views):  # a view without alpha is opaque: 255 composites to itself exactly
        alphas = np.stack([v[3] if v[3] is not None else np.full((h, w), 255, np.uint8) for v in views])
    raw = any(v[3] is not None and not v[4] for v in views)  # RGBA at full size: composited by Split.image
    composed = any(v[3] is not None and v[4] for v in views)  # RGBA composited before downscaling
    composite = load.bg if raw else None
    if load.headers_only:
        images = blank((len(views), h, w, 3))
    elif any(v[2].dtype != np.uint8 for v in views) or (raw and composed):
        # a split mixing final and to-be-composited RGBA views, or holding float pixels: float32 now
        images = np.stack([_as_float(v[2], None if v[4] else _unit(v[3]), load.bg) for v in views])
        composite = None
    else:
        images = np.stack([v[2] for v in views])
    depths = None
    if (root / "depth").is_dir() and load.downscale > 1:
        load.note(f"depth/: depth maps not loaded at downscale {load.downscale} (they are not resampled)")
    elif (root / "depth").is_dir():
        maps = []
        for rel in names:
            path = _depth_path(root, rel)
            if not path.is_file():
                raise InputError(f"{path.relative_to(root).as_posix()}: missing (depth/ holds depth maps, "
                                 f"but none for {rel})")
            what = path.relative_to(root).as_posix()
            shape, dtype = npy_shape(path, what=what)  # the header, checked against the file's size
            if dtype.kind not in "fiu":
                raise InputError(f"{what}: depth dtype {dtype}, expected float32")
            if shape != (h, w):
                raise InputError(f"{what}: depth shape {list(shape)} disagrees with its image {h}x{w}")
            if not load.headers_only:
                maps.append(read_npy(path, what=what).astype(np.float32))
        depths = blank((len(names), h, w)) if load.headers_only else np.stack(maps)
    return Split(images, cameras, depths, names, alphas, composite)


__all__ = ["Dataset", "DatasetCheck", "Split", "PointCloud", "load_dataset", "check_dataset", "LAYOUTS",
           "PINHOLE_MODELS"]
