"""Teacher scenes: a trained 3DGS model (a PLY) rendered by splatbench's rasterizer into a dataset
(here, above the rasterizer, for the train run kind: the model layer cannot render). A teacher scene
is a run's scene (a dataset), one of the five kinds of "scene" in docs/architecture.md.

A teacher scene gives realistic appearance with exact ground truth: the cameras are a
`splatbench.framing.framing_rig` ring around the model (``views`` views at 20° above the
horizontal, about its up axis), every 8th view (``i % 8 == 0``) is held out, and the
dataset folder has the catalog scenes' layout (``images/``, ``depth/``, COLMAP
``sparse/0`` + ``points3D.ply`` + ``split.json``, Blender transforms). Its points are
unprojected from the *rendered* depth of the training views at pixels the model covers
(alpha > 0.99), as the catalog scenes unproject Mitsuba's depth: the teacher's own
Gaussians never initialise a student. Depth maps are the rasterizer's expected camera z
where alpha > 0.5, else 0 (empty: what ``background = "auto"`` averages).

Up axis: ``up`` when given, else the PLY's recorded hint (`splatbench.ply.ViewHints`),
else `splatbench.framing.DEFAULT_UP` (-y), said in a note. The folder is cached by
content (`teacher_inputs`: the PLY's bytes, views, resolution, up, the rasterizer's
version) in ``manifest.json``, as `splatbench.scenes.render_dataset` caches renders.

Example::

    ds = render_teacher("pc_guitar.ply", "data/scenes/teacher-guitar", views=64, resolution=128)
    load_dataset(ds.path).train.images.shape      # (56, 128, 128, 3)
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Sequence

import numpy as np

from splatbench.errors import InputError
from splatbench.fsutil import building_dir, manifest_hash, read_manifest, write_manifest

#: Bump when a teacher dataset changes for the same inputs.
TEACHER_VERSION = 1
#: Points unprojected from the rendered depth (as many as the catalog rigs use).
TEACHER_POINTS = 20_000
#: Every this-many-th view is a test view (as the catalog rigs and graphdeco's --eval).
TEST_EVERY = 8


@dataclass(frozen=True)
class TeacherDataset:
    """A rendered teacher scene: its folder, whether it was reused, its content hash, the up used."""

    path: Path
    cached: bool
    hash: str
    up: tuple[float, float, float]
    up_source: str   # "given", "the PLY's hint" or "assumed (-y)"
    seconds: float


def teacher_up(model: str | Path, up: Sequence[float] | None) -> tuple[tuple[float, float, float], str]:
    """The rig's up [3] and where it came from: given, the PLY's hint, or the default -y."""
    from splatbench.framing import DEFAULT_UP
    from splatbench.ply import ViewHints, read_view_hints

    if up is not None:
        return ViewHints(up=tuple(up)).up, "given"  # validated (3 finite values, not zero), normalised
    hint = read_view_hints(model).up
    if hint is not None:
        return hint, "the PLY's hint"
    return DEFAULT_UP, "assumed (-y, as COLMAP captures; give up = [x, y, z] to change it)"


def teacher_inputs(model: str | Path, *, views: int, resolution: int, up: Sequence[float]) -> dict[str, Any]:
    """What a teacher dataset depends on (hashed into ``hash``)."""
    from splatbench.versions import package_version

    path = Path(model)
    try:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the teacher model ({exc.strerror})") from None
    inputs = {"format": TEACHER_VERSION, "model_sha256": digest, "views": views, "resolution": resolution,
              "up": [float(u) for u in up], "points": TEACHER_POINTS, "drjit": package_version("drjit")}
    inputs["hash"] = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()
    return inputs


def render_teacher(model: str | Path, out: str | Path, *, views: int = 64, resolution: int = 128,
                   up: Sequence[float] | None = None, progress: bool = False) -> TeacherDataset:
    """Render the teacher ``model`` (a 3DGS PLY) on a framing rig into the dataset folder ``out``
    (reused when its manifest's hash matches). One-line `InputError` for a bad model or setting."""
    if not (isinstance(views, int) and not isinstance(views, bool) and views >= 2):
        raise InputError(f"views: expected an int >= 2 (one is held out), got {views!r}")
    if not (isinstance(resolution, int) and not isinstance(resolution, bool) and resolution >= 8):
        raise InputError(f"resolution: expected an int >= 8 (image side in pixels), got {resolution!r}")
    model, out = Path(model), Path(out)
    if not model.is_file():
        raise InputError(f"model: {str(model)!r} is not a file (give a 3DGS PLY)")
    up_, up_source = teacher_up(model, up)
    inputs = teacher_inputs(model, views=views, resolution=resolution, up=up_)
    if manifest_hash(out) == inputs["hash"]:
        seconds = float((read_manifest(out) or {}).get("seconds", 0.0))
        return TeacherDataset(out, True, inputs["hash"], up_, up_source, seconds)
    t0 = time.perf_counter()
    with building_dir(out, accept_existing=lambda p: manifest_hash(p) == inputs["hash"]) as tmp:
        _render_into(model, tmp, views, resolution, up_, progress)
        seconds = round(time.perf_counter() - t0, 3)
        write_manifest(tmp, {"format": "splatbench-teacher/1", "hash": inputs["hash"], "model": str(model),
                             "inputs": {k: v for k, v in inputs.items() if k != "hash"}, "up_source": up_source,
                             "seconds": seconds})
    return TeacherDataset(out, False, inputs["hash"], up_, up_source, seconds)


def _render_into(model: Path, folder: Path, views: int, resolution: int, up, progress: bool) -> None:
    from tqdm import tqdm

    from splatbench.framing import framing_rig
    from splatbench.gaussians import Gaussians
    from splatbench.images import to_uint8
    from splatbench.raster.api import render
    from splatbench.scenes.render import (_save_png_u8, _write_blender, _write_colmap, _write_json, _write_ply,
                                          points_from_depth)

    gaussians = Gaussians.from_ply(model)
    cameras = list(framing_rig(gaussians, views, resolution, resolution, up=up))
    names = [f"{i:04d}.png" for i in range(views)]
    test = [i for i in range(views) if i % TEST_EVERY == 0]
    train_ids = [i for i in range(views) if i % TEST_EVERY != 0]
    (folder / "images").mkdir()
    (folder / "depth").mkdir()
    images = np.zeros((views, resolution, resolution, 3), np.uint8)
    point_depths = np.zeros((views, resolution, resolution), np.float32)
    for i in tqdm(range(views), desc=f"render teacher {model.stem}", unit="view", disable=not progress, leave=False):
        res = render(gaussians, cameras[i])
        images[i] = to_uint8(res.rgb)
        depth = np.where(res.alpha > 0.5, res.depth, 0.0).astype(np.float32)
        point_depths[i] = np.where(res.alpha > 0.99, res.depth, 0.0)
        _save_png_u8(images[i], folder / "images" / names[i])
        np.save(folder / "depth" / Path(names[i]).with_suffix(".npy"), depth)
    xyz, colors, view, pixel = points_from_depth([cameras[i] for i in train_ids], point_depths[train_ids],
                                                 images[train_ids], TEACHER_POINTS, seed=0)
    if len(xyz) == 0:
        raise InputError(f"{model}: the teacher covers no pixel of its training views (alpha <= 0.99 everywhere); "
                         f"is it a 3DGS PLY with opaque Gaussians?")
    view = np.asarray(train_ids, dtype=np.int64)[view]
    plan = SimpleNamespace(cameras=cameras, names=names)  # what the writers read of a RenderPlan
    _write_colmap(folder / "sparse" / "0", plan, xyz, colors, view, pixel)
    _write_ply(folder / "points3D.ply", xyz, colors)
    for split, ids in (("train", train_ids), ("test", test)):
        _write_blender(folder / f"transforms_{split}.json", plan, ids)
    _write_json(folder / "split.json", {"train": [names[i] for i in train_ids], "test": [names[i] for i in test]})


__all__ = ["TeacherDataset", "render_teacher", "teacher_inputs", "teacher_up", "TEACHER_POINTS", "TEST_EVERY"]
