"""Convert a capture between LLFF's layout and COLMAP's or a transforms.json (issue 40 item 3).

    python tools/llff_convert.py SRC DST --to colmap      # LLFF (or transforms.json) -> sparse/0 + images/
    python tools/llff_convert.py SRC DST --to blender     # -> transforms.json + images/
    python tools/llff_convert.py SRC DST --to llff        # COLMAP / transforms.json -> poses_bounds.npy + images/
    python tools/llff_convert.py SRC DST --to llff --downscale 8   # read SRC's images_8/ (LLFF: of the originals)

SRC is read by `splatbench.data.load_dataset` (every view, no split, masks ignored), so
the cameras written are the ones splatbench trains on; the image files are copied
unchanged into ``DST/images/``, renamed to their base name. Then check a conversion
yourself: ``load_dataset(SRC)`` and ``load_dataset(DST)`` give the same cameras (to the
float32 rounding of a float32 file) and the same pixels (tests/test_llff.py does so).

LLFF's [h, w, f] holds one focal, the principal point at the image centre and no lens
distortion: a capture with distortion, fx != fy or an off-centre principal point is
refused in one line (undistort it first: ``splatbench train`` does so in its cache). LLFF
needs near / far bounds per view; written from another layout they are the 0.1 and 99.9
percentiles of the depths of the capture's points in that view, as LLFF's
``imgs2poses.py`` computes them (0.9 x and 1.1 x, its margins), or, without points,
``--near`` / ``--far``. Written to another layout, the bounds are dropped. Masks are not
converted (copy ``masks_N/`` beside ``images/`` yourself: LLFF and COLMAP folders read
them by stem).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np

import splatbench  # noqa: F401 - sets DRJIT_LIBLLVM_PATH before pycolmap loads
from splatbench.data import load_dataset
from splatbench.data.llff import POSES_FILE, row_from_camera
from splatbench.errors import InputError


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
            far: float | None = None) -> list[str]:
    """Write SRC's capture to DST in layout ``to``; the lines to print."""
    if dst.exists() and any(dst.iterdir()):
        raise InputError(f"{dst}: not empty (the converter writes a new folder)")
    lens = _distortion(src)
    if lens:
        raise InputError(f"{src}: {lens}: LLFF's [h, w, f] holds no distortion and the converter copies images "
                         f"unchanged; undistort the capture first")
    ds = load_dataset(src, test_every=0, downscale=downscale, masks=False)
    views = ds.train
    cameras, names = views.cameras, views.names
    for cam, rel in zip(cameras, names):
        if cam.fx != cam.fy:
            raise InputError(f"{rel}: fx {cam.fx!r} != fy {cam.fy!r}: LLFF's [h, w, f] holds one focal")
        if (cam.cx, cam.cy) != (cam.width / 2, cam.height / 2):
            raise InputError(f"{rel}: principal point ({cam.cx}, {cam.cy}) is not the image centre "
                             f"({cam.width / 2}, {cam.height / 2}), which LLFF's [h, w, f] assumes")
    base = [Path(rel).name for rel in names]
    if len(set(base)) != len(base):
        raise InputError(f"{src}: two images share a file name in different folders; rename them first")
    from PIL import Image

    for cam, rel in zip(cameras, names):
        with Image.open(src / rel) as im:
            if im.size != (cam.width, cam.height):  # resized on load: the file is not what was read
                raise InputError(f"--downscale {downscale}: {rel} is {im.size[0]}x{im.size[1]}, the view read is "
                                 f"{cam.width}x{cam.height} (the converter copies files, it does not resize: "
                                 f"choose a downscale with its own images_N/ folder)")
    if len({c.width for c in cameras}) > 1 or len({c.height for c in cameras}) > 1:
        raise InputError(f"{src}: images of several sizes")
    out = [f"{ds.layout} -> {to}: {len(cameras)} views of {cameras[0].width}x{cameras[0].height}"]
    (dst / "images").mkdir(parents=True, exist_ok=True)
    for rel, name in zip(names, base):
        shutil.copyfile(src / rel, dst / "images" / name)
    if to == "llff":
        bounds = _bounds(ds, near, far)
        rows = np.stack([row_from_camera(c, *b) for c, b in zip(cameras, bounds)])
        order = np.argsort(base)  # LLFF's rows follow the sorted image names
        np.save(dst / POSES_FILE, rows[order].astype(np.float64), allow_pickle=False)
        out.append(f"wrote {POSES_FILE} ({len(rows)} rows) and images/; near/far "
                   f"{bounds[:, 0].min():.4g}..{bounds[:, 1].max():.4g}")
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
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("src", type=Path)
    parser.add_argument("dst", type=Path)
    parser.add_argument("--to", choices=("llff", "colmap", "blender"), required=True)
    parser.add_argument("--downscale", type=int, default=1, help="read SRC at this data.downscale")
    parser.add_argument("--near", type=float)
    parser.add_argument("--far", type=float)
    args = parser.parse_args(argv)
    try:
        for line in convert(args.src, args.dst, args.to, args.downscale, args.near, args.far):
            print(line)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
