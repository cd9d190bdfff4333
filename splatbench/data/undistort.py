"""Undistortion of captures whose cameras have lens distortion, by pycolmap (COLMAP's undistorter).

A view with a distorted camera (`Lens`: a COLMAP camera model and its parameters) is
remapped by ``pycolmap.undistort_image`` -- COLMAP's ``image_undistorter`` with its
default options: bilinear warp, the output cropped to the pixels that saw the scene
(no blank borders), square-pixel PINHOLE intrinsics from ``pycolmap.undistort_camera``.
No remap is written here. The undistorted images (then downscaled, when asked) are
cached as PNG under ``<cache>/undistorted/<key>/`` where ``key`` hashes every source
image's bytes, every lens, the downscale and the versions of pycolmap and of this code,
so a changed photo or coefficient makes a new folder and an unchanged capture is read
back without pycolmap. The cache root is ``$SPLATBENCH_CACHE`` or ``~/.cache/splatbench``
(the capture's own folder may be read-only).

Models: ``SIMPLE_RADIAL``, ``RADIAL``, ``OPENCV``, ``FULL_OPENCV`` and ``OPENCV_FISHEYE``
(`UNDISTORTED_MODELS`); any other is refused in one line by `check_lens`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from splatbench.errors import InputError
from splatbench.fsutil import building_dir, cache_root, read_manifest, write_manifest

#: COLMAP camera models with distortion that are undistorted on load.
UNDISTORTED_MODELS = ("SIMPLE_RADIAL", "RADIAL", "OPENCV", "FULL_OPENCV", "OPENCV_FISHEYE")
#: Bump when the cached images change for the same inputs.
UNDISTORT_CACHE_VERSION = 1


@dataclass(frozen=True)
class Lens:
    """A camera with distortion, as COLMAP writes it: ``model`` and ``params`` in COLMAP's order
    (e.g. OPENCV: fx, fy, cx, cy, k1, k2, p1, p2), for ``width`` x ``height`` images."""

    model: str
    width: int
    height: int
    params: tuple[float, ...]

    def to_pycolmap(self):
        from splatbench.interrupt import import_pycolmap

        pycolmap = import_pycolmap()
        return pycolmap.Camera(model=self.model, width=self.width, height=self.height, params=list(self.params))


@dataclass(frozen=True)
class Undistorted:
    """One undistorted view: the PNG in the cache and its PINHOLE intrinsics (pixels)."""

    path: Path
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float


def check_lens(lens: Lens, where: str) -> None:
    """Refuse, in one line naming ``where``, a model pycolmap is not asked to undistort here
    or parameters that do not fit it."""
    if lens.model not in UNDISTORTED_MODELS:
        raise InputError(f"{where}: camera model {lens.model!r} cannot be undistorted here (supported: PINHOLE, "
                         f"SIMPLE_PINHOLE, {', '.join(UNDISTORTED_MODELS)}); undistort the images with COLMAP's "
                         f"image_undistorter first")
    try:
        cam = lens.to_pycolmap()
        ok = len(cam.params) == len(lens.params)
    except Exception as exc:  # pycolmap: wrong parameter count raises ValueError/RuntimeError
        raise InputError(f"{where}: {lens.model} camera with parameters {list(lens.params)}: "
                         f"pycolmap refuses it ({str(exc).strip().splitlines()[0]})") from None
    if not ok or not all(np.isfinite(lens.params)):
        raise InputError(f"{where}: {lens.model} expects {len(cam.params)} finite parameters, got {list(lens.params)}")


def undistort_views(sources: Sequence[tuple[Path, Lens]], *, downscale: int = 1,
                    say: Callable[[str], None] | None = None) -> tuple[list[Undistorted], Path, bool]:
    """Undistort every ``(image file, lens)`` with pycolmap, then downscale by ``downscale``
    (PIL bicubic, as graphdeco resizes), cached by content. Returns ``(views in the given
    order, the cache folder, whether it was reused)``. ``say`` gets one line before any work."""
    from splatbench.interrupt import import_pycolmap
    from splatbench.versions import package_version

    say = say or (lambda line: None)
    digests = []
    for path, lens in sources:
        try:
            digests.append(hashlib.sha256(Path(path).read_bytes()).hexdigest())
        except OSError as exc:
            raise InputError(f"{path}: cannot read the image ({exc.strerror})") from None
    inputs = {"format": UNDISTORT_CACHE_VERSION, "pycolmap": package_version("pycolmap"), "downscale": downscale,
              "views": [[d, lens.model, lens.width, lens.height, list(lens.params)]
                        for d, (_, lens) in zip(digests, sources)]}
    key = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:20]
    out = cache_root() / "undistorted" / key
    cached = _read_manifest(out, len(sources))
    if cached is not None:
        return cached, out, True
    say(f"undistorting {len(sources)} images with pycolmap (COLMAP's undistorter; cached in {out})")
    pycolmap = import_pycolmap()
    with building_dir(out, accept_existing=lambda p: _read_manifest(p, len(sources)) is not None) as tmp:
        records = []
        options = pycolmap.UndistortCameraOptions()  # COLMAP's defaults: crop to valid pixels
        from PIL import Image

        for k, (path, lens) in enumerate(sources):
            rgb = _read_rgb8(Path(path), lens)
            bitmap, cam = pycolmap.undistort_image(options, pycolmap.Bitmap.from_array(rgb), lens.to_pycolmap())
            image = bitmap.to_array()
            w, h, fx, fy, cx, cy = _downscaled(cam, downscale)
            if (w, h) != (int(cam.width), int(cam.height)):
                image = np.asarray(Image.fromarray(image).resize((w, h), Image.Resampling.BICUBIC))
            name = f"{k:05d}.png"
            Image.fromarray(np.ascontiguousarray(image)).save(tmp / name)
            records.append({"file": name, "source": str(path), "width": w, "height": h,
                            "fx": fx, "fy": fy, "cx": cx, "cy": cy})
        write_manifest(tmp, {"key": key, "inputs": inputs, "views": records})
    views = _read_manifest(out, len(sources))
    assert views is not None  # just written
    return views, out, False


def undistorted_cameras(sources: Sequence[tuple[Path, Lens]], *, downscale: int = 1) -> list[Undistorted]:
    """What `undistort_views` makes of ``sources``, undistorting nothing (a dry run's check,
    `splatbench.data.check_dataset`): each image's header checked as `undistort_views` checks it,
    and the PINHOLE camera of its undistorted image -- ``pycolmap.undistort_camera``, the camera
    COLMAP's image undistorter computes before it remaps -- downscaled as `undistort_views` does.
    ``path``: the source image (no file is written)."""
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()
    options = pycolmap.UndistortCameraOptions()
    out = []
    for path, lens in sources:
        _read_rgb8(Path(path), lens, decode=False)
        w, h, fx, fy, cx, cy = _downscaled(pycolmap.undistort_camera(options, lens.to_pycolmap()), downscale)
        out.append(Undistorted(Path(path), w, h, fx, fy, cx, cy))
    return out


def _downscaled(cam, downscale: int) -> tuple[int, int, float, float, float, float]:
    """(width, height, fx, fy, cx, cy) of pycolmap's PINHOLE camera ``cam`` after downscaling
    its image by ``downscale`` (rounded sides, at least 1 px; intrinsics scaled to them)."""
    fx, fy, cx, cy = (float(p) for p in cam.params)
    w, h = int(cam.width), int(cam.height)
    if downscale > 1:
        nw, nh = max(1, round(w / downscale)), max(1, round(h / downscale))
        sx, sy = nw / w, nh / h
        fx, fy, cx, cy, w, h = fx * sx, fy * sy, cx * sx, cy * sy, nw, nh
    return w, h, fx, fy, cx, cy


def _read_rgb8(path: Path, lens: Lens, *, decode: bool = True) -> np.ndarray | None:
    """The RGB pixels of a distorted photo, its header checked first (no alpha, the lens's
    size); ``decode=False``: the checks alone (None)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            if im.mode in ("RGBA", "LA", "PA"):
                raise InputError(f"{path}: an image with alpha cannot be undistorted here (its camera is "
                                 f"{lens.model}); give RGB photos")
            if im.size != (lens.width, lens.height):
                raise InputError(f"{path}: image size {im.size[0]}x{im.size[1]} disagrees with its camera "
                                 f"{lens.width}x{lens.height}")
            if not decode:
                return None
            rgb = np.asarray(im.convert("RGB"))
    except OSError as exc:
        raise InputError(f"{path}: cannot read the image ({exc})") from None
    return np.ascontiguousarray(rgb)


def _read_manifest(folder: Path, count: int) -> list[Undistorted] | None:
    """The views a finished cache folder holds (``count`` of them, every file there); None otherwise."""
    try:
        views = [Undistorted(folder / r["file"], int(r["width"]), int(r["height"]), float(r["fx"]), float(r["fy"]),
                             float(r["cx"]), float(r["cy"])) for r in (read_manifest(folder) or {})["views"]]
    except (ValueError, KeyError, TypeError):
        return None
    if len(views) != count or not all(v.path.is_file() for v in views):
        return None
    return views


__all__ = ["Lens", "Undistorted", "UNDISTORTED_MODELS", "check_lens", "undistort_views", "undistorted_cameras"]
