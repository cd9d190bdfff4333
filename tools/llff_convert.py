"""Convert a capture between LLFF's layout, COLMAP's and a transforms.json, masks included.

    python tools/llff_convert.py SRC DST --to colmap      # LLFF (or transforms.json) -> sparse/0 + images/
    python tools/llff_convert.py SRC DST --to blender     # -> transforms.json + images/
    python tools/llff_convert.py SRC DST --to llff        # COLMAP / transforms.json -> poses_bounds.npy + images/
    python tools/llff_convert.py SRC DST --to llff --downscale 8   # read SRC's images_8/ (LLFF: of the originals)

SRC is read by `splatbench.data.load_dataset` (every view, no split), so the cameras
written are the ones splatbench trains on; the image files are copied unchanged into
``DST/images/``, renamed to their base name. The capture's object masks (``masks/`` or
``masks_N/``, `splatbench.data.masks`), as the images read take them, are copied
unchanged into ``DST/masks/`` named after their image (``--no-masks`` leaves them out):
every layout reads them, so the converted capture trains as SRC does. DST is written in
a temporary folder beside it and renamed into place when complete (a failed conversion
leaves no DST); a DST that exists must be empty. Then check a conversion yourself:
``load_dataset(SRC)`` and ``load_dataset(DST)`` give the same cameras (to the float32
rounding of a float32 file) and the same pixels (tests/test_llff.py does so).

Lens distortion: splatbench reads a distorted COLMAP or transforms.json capture by
undistorting its photos on load; the converter copies image files unchanged, so it cannot
write a distorted capture in any layout (LLFF's [h, w, f] could not hold the distortion
anyway) and refuses one in one line: train SRC as it is. LLFF's [h, w, f] holds one focal
and the principal point at the image centre: fx != fy or an off-centre principal point is
refused for --to llff. LLFF needs near / far bounds per view; written from another layout
they are the 0.1 and 99.9 percentiles of the depths of the capture's points in that view,
as LLFF's ``imgs2poses.py`` computes them (0.9 x and 1.1 x, its margins), or, without
points, ``--near`` / ``--far``. Written to another layout, the bounds are dropped.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

import splatbench  # noqa: F401 - sets DRJIT_LIBLLVM_PATH before pycolmap loads
from splatbench.data import load_dataset
from splatbench.data.llff import POSES_FILE, row_from_camera
from splatbench.errors import InputError


#: load_dataset's messages name the config keys of `splatbench train`; here they are these flags
_FLAGS = (("set data.downscale to", "give --downscale"), ("data.downscale=", "--downscale "),
          ("set data.masks=false", "give --no-masks"), ("data.masks=false", "--no-masks"))


def _distortion(src: Path) -> str | None:
    """What in SRC describes lens distortion (None: none): a COLMAP camera model other
    than PINHOLE / SIMPLE_PINHOLE, or distortion coefficients in a transforms file."""
    from splatbench.data import PINHOLE_MODELS, colmap_folder

    sparse = colmap_folder(src)
    if sparse is not None:
        import pycolmap

        rec = pycolmap.Reconstruction(str(sparse))
        models = sorted({c.model_name for c in rec.cameras.values()} - set(PINHOLE_MODELS))
        return f"COLMAP camera model {', '.join(models)}" if models else None
    for name in ("transforms.json", "transforms_train.json", "transforms_test.json"):
        if (src / name).is_file():
            meta = json.loads((src / name).read_text(encoding="utf-8-sig"))
            for node in [meta, *meta.get("frames", [])]:
                keys = [k for k in ("k1", "k2", "k3", "k4", "p1", "p2") if node.get(k)]
                if keys:
                    return f"{name}: distortion {', '.join(keys)}"
    return None


def convert(src: Path, dst: Path, to: str, downscale: int = 1, near: float | None = None,
            far: float | None = None, masks: bool = True) -> list[str]:
    """Write SRC's capture to DST in layout ``to`` (whole or not at all); the lines to print."""
    if dst.exists() and (not dst.is_dir() or any(dst.iterdir())):
        raise InputError(f"{dst}: not empty (the converter writes a new folder; give a new or empty DST)")
    lens = _distortion(src)
    if lens:
        raise InputError(f"{src}: {lens}: the converter copies image files unchanged and cannot write a distorted "
                         f"capture (LLFF's [h, w, f] cannot hold distortion; splatbench undistorts a COLMAP or "
                         f"transforms.json capture only as it loads it): train SRC as it is")
    try:
        ds = load_dataset(src, test_every=0, downscale=downscale, masks=masks)
    except InputError as exc:
        text = str(exc)
        for key, flag in _FLAGS:
            text = text.replace(key, flag)
        raise InputError(text) from None
    views = ds.train
    cameras, names = views.cameras, views.names
    if to == "llff":  # every view must fit a poses_bounds row (row_from_camera says why not), before any file
        for cam, rel in zip(cameras, names):
            try:
                row_from_camera(cam, 1.0, 2.0)  # the bounds are checked on their own, below
            except InputError as exc:
                raise InputError(f"{rel}: {exc} (convert to colmap or blender instead)") from None
    base = [Path(rel).name for rel in names]
    if len(set(base)) != len(base):
        raise InputError(f"{src}: two images share a file name in different folders; rename them first")
    from PIL import Image

    from splatbench.data.masks import Masks

    def size_of(rel: str) -> tuple[int, int]:
        with Image.open(src / rel) as im:
            return im.size

    mask_files: list[str] = []
    if ds.masks:
        if ", " in ds.masks:
            raise InputError(f"{src}: its images take masks from several folders ({ds.masks}); give --no-masks or "
                             f"keep one mask folder")
        finder = Masks(src, True, lambda line: None)
        mask_files = [finder.file(ds.masks, rel) for rel in names]
    for cam, rel, mrel in zip(cameras, names, mask_files or [None] * len(names)):
        for file in (rel, mrel):
            if file is not None and size_of(file) != (cam.width, cam.height):  # resized on load: not what was read
                w, h = size_of(file)
                raise InputError(f"--downscale {downscale}: {file} is {w}x{h}, the view read is "
                                 f"{cam.width}x{cam.height} (the converter copies files, it does not resize: "
                                 f"choose a --downscale with its own images_N/ and masks_N/ folders)")
    if len({c.width for c in cameras}) > 1 or len({c.height for c in cameras}) > 1:
        raise InputError(f"{src}: images of several sizes")
    bounds = _bounds(ds, near, far) if to == "llff" else None  # refused before anything is written
    out = [f"{ds.layout} -> {to}: {len(cameras)} views of {cameras[0].width}x{cameras[0].height}"]
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{dst.name}.partial-", dir=dst.parent))
    try:
        out += _write(tmp, src, to, ds, base, bounds, mask_files)
        if dst.exists():
            dst.rmdir()  # empty (checked above); a rename replaces no folder
        tmp.rename(dst)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if masks and not ds.masks:
        out.append("no masks/ or masks_N/ in SRC: none copied")
    return out


def _write(dst: Path, src: Path, to: str, ds, base: list[str], bounds: np.ndarray | None,
           mask_files: list[str]) -> list[str]:
    """Write the converted capture into the new folder ``dst``; the lines to print."""
    cameras, names = ds.train.cameras, ds.train.names
    out = []
    (dst / "images").mkdir()
    for rel, name in zip(names, base):
        shutil.copyfile(src / rel, dst / "images" / name)
    if mask_files:
        (dst / "masks").mkdir()
        for mrel, name in zip(mask_files, base):
            shutil.copyfile(src / mrel, dst / "masks" / (Path(name).stem + Path(mrel).suffix))
        out.append(f"copied {len(mask_files)} masks from {ds.masks}/ to masks/ (named after their images; every "
                   f"layout reads them as the views' alphas)")
    if to == "llff":
        rows = np.stack([row_from_camera(c, *b) for c, b in zip(cameras, bounds)])
        order = np.argsort(base)  # LLFF's rows follow the sorted image names
        np.save(dst / POSES_FILE, rows[order].astype(np.float64), allow_pickle=False)
        out.append(f"wrote {POSES_FILE} ({len(rows)} rows) and images/; near/far "
                   f"{float(bounds[:, 0].min()):.4g}..{float(bounds[:, 1].max()):.4g}")
    elif to == "colmap":
        import pycolmap

        rec = pycolmap.Reconstruction()
        for i, (cam, name) in enumerate(zip(cameras, base), start=1):
            pc, pose = cam.to_colmap()
            pc.camera_id = i
            rec.add_camera_with_trivial_rig(pc)
            rec.add_image_with_trivial_frame(pycolmap.Image(name=name, camera_id=i, image_id=i), pose)
        (dst / "sparse" / "0").mkdir(parents=True)
        rec.write(str(dst / "sparse" / "0"))
        out.append("wrote sparse/0 (PINHOLE cameras, no points: init=sfm triangulates them) and images/")
    else:
        frames = []
        for cam, name in zip(cameras, base):
            frame, _ = cam.to_blender()
            frame.update(fl_x=cam.fx, fl_y=cam.fy, cx=cam.cx, cy=cam.cy, w=cam.width, h=cam.height)
            frames.append({"file_path": f"images/{name}", **frame})
        (dst / "transforms.json").write_text(json.dumps({"frames": frames}, indent=1) + "\n")
        out.append("wrote transforms.json (nerfstudio's per-frame fl_x, fl_y, cx, cy, w, h) and images/")
    return out


def _bounds(ds, near: float | None, far: float | None) -> np.ndarray:
    """[V, 2] near, far per view: given, the source's own (LLFF), or from its points (imgs2poses.py)."""
    views = ds.train.cameras
    if near is not None or far is not None:
        if near is None or far is None:
            raise InputError("--near, --far: give both")
        return np.tile([near, far], (len(views), 1))
    if ds.bounds is not None:
        return ds.bounds
    if ds.points is None or len(ds.points) == 0:
        raise InputError("bounds: the capture has no points to take LLFF's near/far depth bounds from; give "
                         "--near and --far")
    out = []
    for cam in views:
        _, z = cam.project(ds.points.xyz)
        z = z[z > 0]
        if len(z) == 0:
            raise InputError(f"bounds: no point lies in front of a camera at {cam.center.tolist()}; give --near "
                             f"and --far")
        out.append([0.9 * np.percentile(z, 0.1), 1.1 * np.percentile(z, 99.9)])
    return np.array(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="llff_convert.py", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Convert a capture between LLFF's layout (poses_bounds.npy + images/), COLMAP's (sparse/0/ + "
                    "images/) and a transforms.json, copying its masks/ or masks_N/ along, so that it loads to the "
                    "same cameras and trains the same.",
        epilog="The image and mask files are copied unchanged (no resizing, no undistortion): a capture with lens "
               "distortion is refused (train it as it is; splatbench undistorts it on load). --to llff needs "
               "fx = fy and the principal point at the image centre. DST is written whole or not at all.")
    parser.add_argument("src", type=Path, metavar="SRC", help="the capture folder to read (any layout splatbench "
                        "reads: COLMAP, transforms.json, LLFF)")
    parser.add_argument("dst", type=Path, metavar="DST", help="the folder to write: new or empty")
    parser.add_argument("--to", choices=("llff", "colmap", "blender"), required=True,
                        help="the layout to write: llff (poses_bounds.npy), colmap (sparse/0/, PINHOLE cameras, no "
                             "points), blender (transforms.json with per-frame intrinsics)")
    parser.add_argument("--downscale", type=int, default=1, metavar="N",
                        help="read SRC's images reduced by N (LLFF: of the original size in poses_bounds.npy, from "
                             "images_N/; COLMAP / transforms.json: from images_N/); the files read must exist at "
                             "that size, as they are copied (default 1)")
    parser.add_argument("--near", type=float, help="with --far, every view's near depth bound for --to llff "
                        "(default: from the capture's points, or its own bounds when SRC is LLFF)")
    parser.add_argument("--far", type=float, help="with --near, every view's far depth bound for --to llff")
    parser.add_argument("--no-masks", action="store_true", help="do not read or copy SRC's masks/ or masks_N/")
    args = parser.parse_args(argv)
    try:
        for line in convert(args.src, args.dst, args.to, args.downscale, args.near, args.far,
                            masks=not args.no_masks):
            print(line)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
