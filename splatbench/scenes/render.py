"""Render a catalog scene into a dataset folder with Mitsuba 3 (``llvm_ad_rgb``).

Dataset folder (both layouts side by side; see ``scenes/README.md``)::

    images/0000.png ...        8-bit sRGB, every view (train and test), in rig order
    depth/0000.npy ...         float32 [H, W] camera z of the surface seen at each pixel
                               centre; 0 where the ray hits nothing
    transforms_train.json      Blender / nerfstudio layout; file_path "images/0000.png"
    transforms_test.json         (with the extension), ply_file_path "points3D.ply"
    sparse/0/*.bin             COLMAP: one PINHOLE camera, every image with its true pose,
                               points3D on the true surfaces with their colours
    points3D.ply               the same points (x, y, z float64; red, green, blue uint8)
    split.json                 {"train": [...], "test": [...]} COLMAP image names
    manifest.json              content hash of scene files + settings + renderer (plus the scene
                               name and folder, view counts, render time); written last

Decisions:

* Colour: Mitsuba renders linear RGB with a box pixel filter (each pixel integrates its
  own footprint); it is clipped to [0, 1] and encoded with the sRGB transfer function.
* Depth: a second pass with the ``aov`` integrator's ``depth`` (the ray distance ``t``)
  and a stratified sampler without jitter, one sample at each pixel centre. Mitsuba's
  perspective sensor starts rays on the near plane, so camera z is
  ``t·cos θ + near`` where ``cos θ = 1/|((u-cx)/fx, (v-cy)/fy, 1)|`` (checked
  against an analytic tilted plane in ``tests/test_scenes.py``).
* Points: pixels of the *training* views whose depth agrees with their 4 neighbours
  (no silhouette edges) are unprojected with their depth, a seeded random subset of
  ``rig.points``; colour is the pixel's sRGB value. Each point keeps one observation
  (its source pixel) in the COLMAP track. Test views never contribute.
* Test views may get more samples (``test_spp``, default ``spp``): their Monte Carlo noise
  is error no model can fit, a floor under every test PSNR. Training views keep ``spp``
  and their seeds (a view's seed does not depend on its spp), so their images do not change.
* The cache key hashes every file of the scene folder, the resolved settings
  (resolution, views, test indices, spp, seed, points; ``test_spp`` only when it differs
  from ``spp``, so datasets made before it existed keep their key) and the renderer identity
  (`RENDERER_VERSION`, splatbench and Mitsuba versions). An existing dataset with the
  same hash is reused; anything else renders into a temporary sibling folder that is
  renamed into place once complete.

Example::

    from splatbench.scenes import render_dataset
    result = render_dataset("diffuse", resolution=64)
    result.path, result.cached        # Path('data/scenes/diffuse-64'), False (the rig's views and spp)
    render_dataset("diffuse", resolution=64, views=8, spp=16).path   # Path('data/scenes/diffuse-64-v8-s16')
    render_dataset("glossy", resolution=128, views=64, spp=64, test_spp=2048)  # cleaner test targets
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.fsutil import MANIFEST, building_dir, json_text, manifest_hash, read_manifest, write_manifest
from splatbench.mitsuba_loader import MITSUBA_VARIANT, mitsuba
from splatbench.scenes.catalog import SceneSpec, get_scene, parse_resolution
from splatbench.scenes.folders import default_out, describe_replaced
from splatbench.versions import package_version

#: Bump when the renderer's output changes for the same inputs (invalidates caches).
RENDERER_VERSION = 1
DATASET_FORMAT = "splatbench-dataset/1"
#: Largest number of samples (pixels × spp) in one Mitsuba launch; more are split into passes.
MAX_SAMPLES_PER_PASS = 1 << 22
#: Relative depth jump to a 4-neighbour that marks a pixel as a silhouette edge (no point there).
EDGE_REL_DEPTH = 0.02


def load_mitsuba_scene(scene: SceneSpec | str | Path, extra_dirs: Iterable[str | Path] = ()):
    """The loaded ``mi.Scene`` (variant ``llvm_ad_rgb``) of a catalog scene, name or folder.

    ``scene.shapes()`` lists its shapes (see `sample_surface`); ``scene.integrator()``
    is the scene's integrator (Mitsuba's default ``path`` when the file declares none).
    """
    spec = scene if isinstance(scene, SceneSpec) else get_scene(scene, extra_dirs)
    mi = mitsuba()
    try:
        return mi.load_file(str(spec.scene_file))
    except Exception as exc:  # Mitsuba reports parse errors as RuntimeError with a long trace
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{spec.scene_file}: Mitsuba cannot load it ({first})") from None


def linear_to_srgb(rgb: Any) -> np.ndarray:
    """Linear RGB -> sRGB-encoded values in [0, 1] (IEC 61966-2-1; input clipped, NaN -> 0)."""
    x = np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64)), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_to_linear(srgb: Any) -> np.ndarray:
    """Inverse of `linear_to_srgb` on [0, 1]."""
    x = np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _sensor(camera: Camera, sampler: dict):
    mi = mitsuba()
    return mi.load_dict({**camera.to_mitsuba(), "sampler": sampler})


def render_rgb(mi_scene, camera: Camera, *, spp: int, seed: int = 0) -> np.ndarray:
    """[H, W, 3] float32 linear RGB of ``mi_scene`` seen by ``camera`` (the scene's integrator).

    Split into passes of at most `MAX_SAMPLES_PER_PASS` samples (memory), averaged.
    """
    mi = mitsuba()
    sensor = _sensor(camera, {"type": "independent", "sample_count": spp})
    passes = max(1, math.ceil(camera.width * camera.height * spp / MAX_SAMPLES_PER_PASS))
    per_pass = math.ceil(spp / passes)
    acc = np.zeros((camera.height, camera.width, 3), dtype=np.float64)
    done = 0
    while done < spp:
        k = min(per_pass, spp - done)
        image = mi.render(mi_scene, sensor=sensor, spp=k, seed=(seed * 64 + done // per_pass) & 0xFFFFFFFF)
        acc += np.asarray(image, dtype=np.float64)[..., :3] * k
        done += k
    return (acc / spp).astype(np.float32)


def render_depth(mi_scene, camera: Camera) -> np.ndarray:
    """[H, W] float32 camera z of the first surface hit through each pixel centre; 0 on a miss."""
    mi = mitsuba()
    sensor = _sensor(camera, {"type": "stratified", "sample_count": 1, "jitter": False})
    aov = mi.load_dict({"type": "aov", "aovs": "dd.y:depth"})
    t = np.asarray(mi.render(mi_scene, sensor=sensor, integrator=aov, spp=1), dtype=np.float64)[..., 0]
    j, i = np.meshgrid(np.arange(camera.width) + 0.5, np.arange(camera.height) + 0.5)
    cos = 1.0 / np.sqrt(((j - camera.cx) / camera.fx) ** 2 + ((i - camera.cy) / camera.fy) ** 2 + 1.0)
    return np.where(t > 0, t * cos + camera.near, 0.0).astype(np.float32)


# --------------------------------------------------------------------------- points
def points_from_depth(cameras: Sequence[Camera], depths: np.ndarray, images: np.ndarray, n: int, *,
                      seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unproject a seeded random subset of ``n`` interior pixels of the given views.

    ``depths`` [V, H, W] camera z (0 = no surface), ``images`` [V, H, W, 3] uint8.
    Pixels whose depth differs by more than `EDGE_REL_DEPTH` (relative) from a
    4-neighbour, or whose neighbour is empty, are silhouette edges and skipped.
    Returns ``(xyz [M, 3] float64, rgb [M, 3] uint8, view [M] int64, pixel [M, 2] int64
    (column, row))``, sorted by view then pixel.
    """
    d = np.asarray(depths, dtype=np.float64)
    pad = np.pad(d, ((0, 0), (1, 1), (1, 1)))
    ok = d > 0
    for nb in (pad[:, :-2, 1:-1], pad[:, 2:, 1:-1], pad[:, 1:-1, :-2], pad[:, 1:-1, 2:]):
        ok &= (nb > 0) & (np.abs(nb - d) <= EDGE_REL_DEPTH * d)
    flat = np.flatnonzero(ok)
    if len(flat) > n:
        flat = np.sort(np.random.default_rng(seed).choice(flat, size=n, replace=False))
    view, row, col = np.unravel_index(flat, d.shape)
    xyz = np.zeros((len(flat), 3))
    for v in np.unique(view):
        cam, sel = cameras[v], view == v
        z = d[v, row[sel], col[sel]]
        pc = np.stack([(col[sel] + 0.5 - cam.cx) / cam.fx * z, (row[sel] + 0.5 - cam.cy) / cam.fy * z, z], axis=1)
        xyz[sel] = (pc - cam.translation) @ cam.rotation  # R^T (p_cam - t)
    rgb = np.asarray(images)[view, row, col]
    return xyz, rgb.astype(np.uint8), view.astype(np.int64), np.stack([col, row], axis=1).astype(np.int64)


# ----------------------------------------------------------------------------- plans
@dataclass(frozen=True)
class RenderPlan:
    """Everything that determines a dataset: the scene, the cameras and the settings."""

    scene: SceneSpec
    cameras: list[Camera]
    test: tuple[int, ...]     # indices of held-out views
    spp: int                  # samples per pixel of the training views
    seed: int
    points: int
    names: list[str] = field(default_factory=list)  # image file names, in view order
    test_spp: int | None = None  # samples per pixel of the test views; None: spp

    def view_spp(self, index: int) -> int:
        """Samples per pixel of view ``index``: ``test_spp`` for a test view (when set), else ``spp``."""
        return self.test_spp if self.test_spp is not None and index in self.test else self.spp

    @property
    def resolution(self) -> tuple[int, int]:
        return self.cameras[0].width, self.cameras[0].height

    def settings(self) -> dict[str, Any]:
        settings = {"resolution": list(self.resolution), "views": len(self.cameras), "test": list(self.test),
                    "spp": self.spp, "seed": self.seed, "points": self.points}
        if self.test_spp is not None and self.test_spp != self.spp:  # absent otherwise: old keys stay valid
            settings["test_spp"] = self.test_spp
        return settings

    def inputs(self) -> dict[str, Any]:
        """What the cache hashes: scene files (sha256), settings and renderer identity."""
        files = {p.relative_to(self.scene.folder).as_posix(): _sha256(p.read_bytes()) for p in self.scene.files()}
        renderer = {"renderer_version": RENDERER_VERSION, "variant": MITSUBA_VARIANT,
                    "splatbench": package_version("splatbench"), "mitsuba": package_version("mitsuba")}
        return {"scene": self.scene.name, "files": files, "settings": self.settings(), "renderer": renderer}

    def hash(self) -> str:
        return _sha256(json.dumps(self.inputs(), sort_keys=True).encode())


def plan_render(scene: SceneSpec | str | Path, *, resolution: Any = None, views: int | None = None,
                spp: int | None = None, test_spp: int | None = None,
                extra_dirs: Iterable[str | Path] = ()) -> RenderPlan:
    """Resolve a scene and the overrides into a `RenderPlan`.

    ``resolution``: an int (the width; the height keeps the rig's aspect ratio), ``"WxH"``
    or ``(W, H)``. ``views``: the total number of views; every 8th (``i % 8 == 0``) is
    then a test view. Without it the rig's ``train_views`` / ``test_views`` apply.
    ``spp``: samples per pixel (default: the rig's); ``test_spp``: those of the test
    views (default: ``spp``; a value equal to ``spp`` is the same plan as none).
    """
    spec = scene if isinstance(scene, SceneSpec) else get_scene(scene, extra_dirs)
    rig = spec.rig
    res = rig.resolution if resolution is None else parse_resolution(resolution, rig.resolution, "--resolution")
    if views is not None and not (isinstance(views, int) and views > 0):
        raise InputError(f"--views: expected a positive int, got {views!r}")
    if spp is not None and not (isinstance(spp, int) and spp > 0):
        raise InputError(f"--spp: expected a positive int, got {spp!r}")
    if test_spp is not None and not (isinstance(test_spp, int) and not isinstance(test_spp, bool) and test_spp > 0):
        raise InputError(f"--test-spp: expected a positive int, got {test_spp!r}")
    cameras = rig.cameras(views, res)
    digits = max(4, len(str(len(cameras) - 1)))
    names = [f"{i:0{digits}d}.png" for i in range(len(cameras))]
    train_spp = rig.spp if spp is None else spp
    return RenderPlan(spec, cameras, tuple(rig.test_indices(views)), train_spp, rig.seed, rig.points, names,
                      None if test_spp == train_spp else test_spp)


@dataclass(frozen=True)
class RenderedDataset:
    """Outcome of `render_dataset`."""

    path: Path        # the dataset folder
    cached: bool      # True when an existing dataset with the same hash was reused
    seconds: float    # render time of this call (0 when cached)
    train: int        # number of training views
    test: int         # number of test views
    hash: str         # the content hash in manifest.json
    replaced: str = ""  # one line saying what an overwritten dataset held (`describe_replaced`); "" if none


def render_dataset(scene: SceneSpec | str | Path, out: str | Path | None = None, *, resolution: Any = None,
                   views: int | None = None, spp: int | None = None, test_spp: int | None = None,
                   force: bool = False, progress: bool = True,
                   extra_dirs: Iterable[str | Path] = ()) -> RenderedDataset:
    """Render ``scene`` into the dataset folder ``out`` unless it already holds the same render.

    ``out`` defaults to `default_out` (``data/scenes/<name>-<W>`` at the rig's views and
    spp, else a name with them: ``<name>-<W>-v<views>-s<spp>[-t<test_spp>]``). A folder that
    exists but holds no ``manifest.json`` (and is not empty) is never replaced: `InputError`;
    one that holds another dataset is, and ``replaced`` says what it held.
    ``force`` renders even when the cache matches. ``progress`` shows a bar over views.
    ``spp`` / ``test_spp``: samples per pixel of the training / test views (`plan_render`).
    """
    plan = plan_render(scene, resolution=resolution, views=views, spp=spp, test_spp=test_spp, extra_dirs=extra_dirs)
    out = Path(out) if out is not None else default_out(plan)
    digest = plan.hash()
    n_test = len(plan.test)
    n_train = len(plan.cameras) - n_test
    existing = read_manifest(out)
    if existing is not None and existing.get("hash") == digest and not force:
        return RenderedDataset(out, True, 0.0, n_train, n_test, digest)
    if out.exists() and (not out.is_dir() or (existing is None and any(out.iterdir()))):
        raise InputError(f"--out: {str(out)!r} exists and is not a splatbench dataset (no {MANIFEST}); "
                         f"refusing to replace it")
    replaced = "" if existing is None else describe_replaced(out, existing, {**plan.inputs(), "hash": digest})
    # keep a folder someone else finished meanwhile if it is the same render
    with building_dir(out, accept_existing=lambda path: manifest_hash(path) == digest) as tmp:
        t0 = time.perf_counter()
        _render_into(plan, tmp, progress)
        seconds = time.perf_counter() - t0
        write_manifest(tmp, {"format": DATASET_FORMAT, "hash": digest, **plan.inputs(),
                             "scene_folder": str(plan.scene.folder), "train": n_train, "test": n_test,
                             "render_seconds": round(seconds, 3), "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
    return RenderedDataset(out, False, seconds, n_train, n_test, digest, replaced)


# ----------------------------------------------------------------------- internals
def _render_into(plan: RenderPlan, folder: Path, progress: bool) -> None:
    from tqdm import tqdm

    from splatbench.images import to_uint8

    mi_scene = load_mitsuba_scene(plan.scene)
    (folder / "images").mkdir()
    (folder / "depth").mkdir()
    n = len(plan.cameras)
    test = set(plan.test)
    train_ids = [i for i in range(n) if i not in test]
    w, h = plan.resolution
    train_images = np.zeros((len(train_ids), h, w, 3), dtype=np.uint8)
    train_depths = np.zeros((len(train_ids), h, w), dtype=np.float32)
    slot = {v: k for k, v in enumerate(train_ids)}
    bar = tqdm(range(n), desc=f"render {plan.scene.name}", unit="view", disable=not progress, leave=False)
    for i in bar:
        cam = plan.cameras[i]
        rgb = to_uint8(linear_to_srgb(render_rgb(mi_scene, cam, spp=plan.view_spp(i),
                                                 seed=plan.seed * 1_000_003 + i)))
        depth = render_depth(mi_scene, cam)
        _save_png_u8(rgb, folder / "images" / plan.names[i])
        np.save(folder / "depth" / Path(plan.names[i]).with_suffix(".npy"), depth)
        if i in slot:
            train_images[slot[i]], train_depths[slot[i]] = rgb, depth
    train_cams = [plan.cameras[i] for i in train_ids]
    xyz, colors, view, pixel = points_from_depth(train_cams, train_depths, train_images, plan.points, seed=plan.seed)
    view = np.asarray(train_ids, dtype=np.int64)[view] if len(view) else view  # index among all views
    _write_colmap(folder / "sparse" / "0", plan, xyz, colors, view, pixel)
    _write_ply(folder / "points3D.ply", xyz, colors)
    for split, ids in (("train", train_ids), ("test", sorted(test))):
        _write_blender(folder / f"transforms_{split}.json", plan, ids)
    _write_json(folder / "split.json", {"train": [plan.names[i] for i in train_ids],
                                        "test": [plan.names[i] for i in sorted(test)]})


def _save_png_u8(rgb: np.ndarray, path: Path) -> None:
    from PIL import Image

    Image.fromarray(rgb).save(path, format="PNG")


def _write_colmap(folder: Path, plan: RenderPlan, xyz: np.ndarray, colors: np.ndarray, view: np.ndarray,
                  pixel: np.ndarray) -> None:
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()

    folder.mkdir(parents=True)
    rec = pycolmap.Reconstruction()
    camera, _ = plan.cameras[0].to_colmap()
    camera.camera_id = 1
    rec.add_camera_with_trivial_rig(camera)
    index_in_view = np.zeros(len(view), dtype=np.int64)
    for i, (cam, name) in enumerate(zip(plan.cameras, plan.names)):
        sel = np.flatnonzero(view == i)
        index_in_view[sel] = np.arange(len(sel))
        keypoints = pixel[sel].astype(np.float64) + 0.5  # pixel centres
        image = pycolmap.Image(name=name, keypoints=keypoints.reshape(-1, 2), camera_id=1, image_id=i + 1)
        rec.add_image_with_trivial_frame(image, cam.to_colmap()[1])
    for p, c, v, k in zip(xyz, colors, view, index_in_view):
        track = pycolmap.Track()
        track.add_element(int(v) + 1, int(k))
        rec.add_point3D(p, track, c)
    rec.write(str(folder))


def _write_ply(path: Path, xyz: np.ndarray, colors: np.ndarray) -> None:
    from plyfile import PlyData, PlyElement

    vertex = np.zeros(len(xyz), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"),
                                       ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for k, axis in enumerate("xyz"):
        vertex[axis] = xyz[:, k]
    for k, channel in enumerate(("red", "green", "blue")):
        vertex[channel] = colors[:, k]
    PlyData([PlyElement.describe(vertex, "vertex")]).write(str(path))


def _write_blender(path: Path, plan: RenderPlan, ids: list[int]) -> None:
    first = plan.cameras[0]
    _, angle_x = first.to_blender()
    frames = []
    for i in ids:
        frame, _ = plan.cameras[i].to_blender()
        frames.append({"file_path": f"images/{plan.names[i]}", "transform_matrix": frame["transform_matrix"]})
    _write_json(path, {"camera_angle_x": angle_x, "camera_model": "PINHOLE", "fl_x": first.fx, "fl_y": first.fy,
                       "cx": first.cx, "cy": first.cy, "w": first.width, "h": first.height,
                       "ply_file_path": "points3D.ply", "frames": frames})


def _write_json(path: Path, data: Any) -> None:
    """Indented JSON with lists of numbers (matrix rows, resolutions) kept on one line (`json_text`)."""
    path.write_text(json_text(data), encoding="utf-8")


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()
