"""LLFF's layout (poses_bounds.npy beside images/ and images_N/) and object masks (issue 40).

A forward-facing scene rendered by splatbench is written in LLFF's layout and read back
with its own cameras; tools/llff_convert.py writes it as COLMAP and transforms.json, and
every layout loads to the same cameras and pixels; it trains. data.downscale follows the
field (N of the originals: images_N/, else the nearest finer folder reduced by area). Masks
become alphas, a masked capture trains and is evaluated on white. Broken poses_bounds.npy
files are one line, through load_dataset and through the CLI. The real captures in
../shared/data (maryrose, ethiopian_head) are read when present.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import math
import pickle
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import splatbench
from splatbench.cameras import Camera
from splatbench.data import load_dataset
from splatbench.data.llff import POSES_FILE, camera_from_row, row_from_camera
from splatbench.gaussians import Gaussians
from splatbench.train.config import DataConfig, EvalConfig, InitConfig, OptimConfig, StrategyConfig
from tests.assertions import one_line_error

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
W, H, FOV = 40, 30, 50.0
EPS32 = float(np.finfo(np.float32).eps)


def _tool():
    spec = importlib.util.spec_from_file_location("llff_convert", Path(__file__).parents[1] / "tools" /
                                                  "llff_convert.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def forward_cameras() -> list[Camera]:
    """9 cameras on a 3 x 3 grid in the z = 0 plane, all looking down +z (a forward-facing rig)."""
    return [Camera.look_at([x, y, 0.0], [0.3 * x, 0.3 * y, 5.5], [0, 1, 0], W, H, FOV)
            for y in (-0.3, 0.0, 0.3) for x in (-0.3, 0.0, 0.3)]


def forward_scene(root: Path, *, rows_dtype=np.float32) -> list[Camera]:
    """Random Gaussians 4..7 units in front of `forward_cameras`, rendered by splatbench and
    written in LLFF's layout: images/ (W x H), images_2/ (each 2 x 2 block's mean), and
    poses_bounds.npy rows in ``rows_dtype`` with near 3, far 8."""
    rng = np.random.default_rng(4)
    n = 300
    means = np.stack([rng.uniform(-2, 2, n), rng.uniform(-1.5, 1.5, n), rng.uniform(4, 7, n)], 1)
    sh = rng.normal(size=(n, 1, 3)) * 0.8
    truth = Gaussians(means, np.full((n, 3), np.log(0.15)), np.tile([1.0, 0, 0, 0], (n, 1)), np.full(n, 2.0), sh)
    cams = forward_cameras()
    for i, cam in enumerate(cams):
        rgb = (np.clip(splatbench.render(truth, cam).rgb, 0, 1) * 255).round().astype(np.uint8)
        for folder, image in (("images", rgb), ("images_2", _box2(rgb))):
            (root / folder).mkdir(parents=True, exist_ok=True)
            Image.fromarray(image).save(root / folder / f"view_{i:02d}.png")
    rows = np.stack([row_from_camera(c, 3.0, 8.0) for c in cams]).astype(rows_dtype)
    np.save(root / POSES_FILE, rows)
    return cams


def _box2(image: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    blocks = image[: h // 2 * 2, : w // 2 * 2].reshape(h // 2, 2, w // 2, 2, *image.shape[2:]).astype(np.float64)
    return blocks.mean(axis=(1, 3)).round().astype(np.uint8)


def _assert_cameras(got: list[Camera], want: list[Camera], rot_tol: float, pos_tol: float, k_tol: float) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want):
        assert (a.width, a.height) == (b.width, b.height)
        assert np.abs(a.rotation - b.rotation).max() <= rot_tol
        assert np.abs(a.center - b.center).max() <= pos_tol
        assert np.abs(a.K - b.K).max() <= k_tol


def test_llff_rows_follow_imgs2poses(tmp_path):
    """The row of a camera is what LLFF's imgs2poses.py computes from its COLMAP pose:
    c2w = inv(w2c); [c2w[:3, 1], c2w[:3, 0], -c2w[:3, 2], centre, (h, w, f)]; and back."""
    cam = Camera.look_at([0.4, -0.2, 1.0], [0.1, 0.3, 6.0], [0, 1, 0], W, H, FOV)
    c2w = np.linalg.inv(cam.world_to_camera)
    hwf = np.array([[H], [W], [cam.fx]])
    pose = np.concatenate([c2w[:3, 1:2], c2w[:3, 0:1], -c2w[:3, 2:3], c2w[:3, 3:4], hwf], 1)  # imgs2poses.py
    want = np.concatenate([pose.ravel(), [2.0, 9.0]])
    np.testing.assert_allclose(row_from_camera(cam, 2.0, 9.0), want, rtol=0, atol=1e-12)
    back, near, far = camera_from_row(want, "row")
    _assert_cameras([back], [cam], 1e-12, 1e-12, 1e-12)
    assert (near, far) == (2.0, 9.0)
    one_line_error(lambda: row_from_camera(Camera(W, H, 30.0, 31.0, W / 2, H / 2, np.eye(4)), 1, 2), "fx, fy")
    one_line_error(lambda: row_from_camera(Camera(W, H, 30.0, 30.0, 19.0, H / 2, np.eye(4)), 1, 2), "cx, cy")


def test_forward_facing_scene_loads_to_the_same_cameras_in_llff_colmap_and_transforms_json(tmp_path):
    cams = forward_scene(tmp_path / "llff")
    ds = load_dataset(tmp_path / "llff", test_every=0)
    assert ds.layout == "llff" and ds.masks == "" and ds.points is None
    assert ds.train.names == [f"images/view_{i:02d}.png" for i in range(9)]
    # poses_bounds.npy in float32: each stored entry is within half an ulp of the camera's: rotation entries
    # <= 1 (error <= eps/2 each; the nearest rotation to the rounded matrix moves them by about as much again),
    # focals ~43 px (<= 43 eps/2); a centre (|c| <= 0.3 sqrt 2) is stored to eps/2 |c|
    rot_tol, pos_tol = 2 * EPS32, EPS32 / 2 * 0.3 * math.sqrt(2)
    _assert_cameras(ds.train.cameras, cams, rot_tol, pos_tol, cams[0].fx * EPS32 / 2)
    assert ds.bounds.shape == (9, 2) and np.all(ds.bounds == [3.0, 8.0])
    written = np.stack([np.asarray(Image.open(tmp_path / "llff" / n)) for n in ds.train.names])
    assert np.array_equal(ds.train.pixels, written)
    tool = _tool()
    for layout in ("colmap", "blender"):
        tool.convert(tmp_path / "llff", tmp_path / layout, layout)
        other = load_dataset(tmp_path / layout, test_every=0)
        assert other.layout == layout
        # the float64 values read written and read back (COLMAP binary with its rotation as a quaternion,
        # JSON repr): float64 rounding only
        _assert_cameras(other.train.cameras, ds.train.cameras, 1e-14, 1e-14, 1e-12)
        assert [Path(n).name for n in other.train.names] == [Path(n).name for n in ds.train.names]
        assert np.array_equal(other.train.pixels, ds.train.pixels)
    tool.convert(tmp_path / "colmap", tmp_path / "back", "llff", near=3.0, far=8.0)
    again = load_dataset(tmp_path / "back", test_every=0)  # float64 rows of the COLMAP model's cameras
    _assert_cameras(again.train.cameras, load_dataset(tmp_path / "colmap", test_every=0).train.cameras, 1e-14,
                    1e-14, 1e-12)
    assert np.array_equal(again.train.pixels, ds.train.pixels)
    # and it trains: from random points in its frusta between the bounds, the test views' PSNR rises
    from splatbench.train import TrainConfig
    from splatbench.train.loop import Trainer

    trainer = Trainer(TrainConfig(dataset=str(tmp_path / "llff"), out=str(tmp_path / "run"), iterations=80,
                                  schedule="absolute", strategy=StrategyConfig(name="none"), init=InitConfig(method="random", random_points=3000), data=DataConfig(test_every=4), eval=EvalConfig(lpips_net="none"), optim=OptimConfig(lr_opacity_logits=0.1, lr_sh_dc=0.01)))
    assert "depth_bounds" in trainer.init_note
    before = trainer.evaluate().psnr
    for _ in range(80):
        trainer.step()
    after = trainer.evaluate().psnr
    assert after > before + 3, (before, after)
    # what LLFF cannot hold is refused in one line
    (tmp_path / "dist").mkdir()
    meta = json.loads((tmp_path / "blender" / "transforms.json").read_text())
    meta["k1"] = 0.01
    (tmp_path / "dist" / "transforms.json").write_text(json.dumps(meta))
    one_line_error(lambda: tool.convert(tmp_path / "dist", tmp_path / "d2", "llff"), "distortion", "k1")
    assert tool.main([str(tmp_path / "dist"), str(tmp_path / "d3"), "--to", "llff"]) == 2


def test_downscale_reads_images_n_or_area_reduces_the_nearest_finer_folder(tmp_path):
    cams = forward_scene(tmp_path, rows_dtype=np.float64)
    f = cams[0].fx
    lines: list[str] = []
    full = load_dataset(tmp_path, test_every=0, downscale=1)
    half = load_dataset(tmp_path, test_every=0, downscale=2, say=lines.append)
    assert full.train.names[0].startswith("images/") and half.train.names[0].startswith("images_2/")
    assert half.train.cameras[0].fx == pytest.approx(f / 2, rel=1e-15) and half.train.image_size == (15, 20)
    quarter = load_dataset(tmp_path, test_every=0, downscale=4, say=lines.append)
    assert quarter.train.image_size == (8, 10)  # round(30 / 4), round(40 / 4)
    cam = quarter.train.cameras[0]
    assert (cam.fx, cam.fy) == pytest.approx((f * 10 / 40, f * 8 / 30), rel=1e-15)  # per axis, corners to corners
    assert any("images_2/ read and reduced by 2 to 10x8 by area averaging" in line for line in lines)
    # the area average of images_2's pixels (15 rows to 8: each output row averages 1.875 input rows,
    # weighted by overlap), rounded to 8 bits: within half a step of the exact means
    src = half.train.pixels[0].astype(np.float64)
    exact = np.zeros((8, 10, 3))
    for i in range(8):
        for j in range(10):
            y0, y1, x0, x1 = i * 15 / 8, (i + 1) * 15 / 8, j * 2, j * 2 + 2
            rows = [(r, min(r + 1, y1) - max(r, y0)) for r in range(int(y0), math.ceil(y1))]
            exact[i, j] = sum(w * src[r, x0:x1].mean(0) for r, w in rows) / (y1 - y0)
    assert np.abs(quarter.train.pixels[0] - exact).max() <= 0.5 + 1e-4  # the resize sums in float32 (~3e-5 here)
    odd = load_dataset(tmp_path, test_every=0, downscale=3)  # from images_2 by 1.5
    assert odd.train.image_size == (10, 13)
    for name in (tmp_path / "images").iterdir():
        name.unlink()
    (tmp_path / "images").rmdir()
    one_line_error(lambda: load_dataset(tmp_path, downscale=1), "data.downscale=1", "40x30", "available factors 2")
    # the every-8th split by sorted name
    split = load_dataset(tmp_path, downscale=2)
    assert [Path(n).name for n in split.test.names] == ["view_00.png", "view_08.png"] and len(split.train) == 7


def _write_masks(root: Path, folder: str, size: tuple[int, int], suffix: str = "_mask") -> list[np.ndarray]:
    out = []
    for i in range(9):
        rng = np.random.default_rng(100 + i)
        mask = np.where(rng.random(size[::-1]) < 0.6, 255, 0).astype(np.uint8)
        (root / folder).mkdir(exist_ok=True)
        Image.fromarray(mask).save(root / folder / f"view_{i:02d}{suffix}.png")
        out.append(mask)
    return out


def test_masks_become_alphas_and_a_masked_capture_trains_and_evaluates_on_white(tmp_path):
    from splatbench.train import TrainConfig
    from splatbench.train.loop import Trainer

    forward_scene(tmp_path, rows_dtype=np.float64)
    masks = _write_masks(tmp_path, "masks_2", (20, 15))
    ds = load_dataset(tmp_path, test_every=0, downscale=2)
    assert ds.masks == "masks_2"
    np.testing.assert_array_equal(ds.train.alpha_pixels, np.stack(masks))
    a = ds.train.alpha(3)[..., None]  # composited on the loader's background (black) view by view
    np.testing.assert_array_equal(ds.train.image(3), ds.train.pixels[3].astype(np.float32) / 255 * a)
    assert load_dataset(tmp_path, downscale=2, masks=False).train.alpha_pixels is None
    # a mask folder serves the downscales it can be reduced to, masks/ of the originals all of them
    assert load_dataset(tmp_path, test_every=0, downscale=4).train.alpha_pixels.shape == (9, 8, 10)
    one_line_error(lambda: load_dataset(tmp_path, downscale=1), "no mask folder serves", "data.masks=false")
    cfg = TrainConfig(dataset=str(tmp_path), out=str(tmp_path / "run"), iterations=30, schedule="absolute", strategy=StrategyConfig(name="none"), init=InitConfig(method="random", random_points=2000), data=DataConfig(downscale=2, test_every=3), eval=EvalConfig(lpips_net="none"))
    trainer = Trainer(cfg)
    assert trainer._background_rgb == [1.0, 1.0, 1.0] and "white" in trainer.background_note
    assert trainer.background_source == "masks"  # what TrainResult.background_source records
    assert "depth_bounds" in trainer.init_note  # a forward-facing rig with bounds: its frusta
    for _ in range(30):
        trainer.step()
    ev = trainer.evaluate()
    # evaluation composites the test views over the same white: a render against photo x a + (1 - a)
    want = []
    for i, cam in enumerate(trainer.dataset.test.cameras):
        rgb = trainer._render(cam, trainer.sh.degree, [1.0, 1.0, 1.0])[0].detach().cpu().numpy().astype(np.float64)
        alpha = trainer.dataset.test.alpha(i)[..., None]
        gt = trainer.dataset.test.pixels[i].astype(np.float32) / 255 * alpha + (1 - alpha)
        want.append(-10 * math.log10(float(np.mean((rgb - gt) ** 2))))
    np.testing.assert_allclose(ev.per_view_psnr, want, rtol=1e-5)  # float32 sums of the metric vs float64 here
    assert math.isfinite(ev.psnr)
    # data.masks=false: the photos as they are, on the auto background of an RGB capture
    plain = Trainer(dataclasses.replace(cfg, data=DataConfig(downscale=2, masks=False)))
    assert plain.dataset.train.alpha_pixels is None and "black" in plain.background_note
    assert plain.background_source == "none" and plain._background_rgb == [0.0, 0.0, 0.0]


def test_broken_masks_are_one_line(tmp_path):
    forward_scene(tmp_path, rows_dtype=np.float64)
    _write_masks(tmp_path, "masks_2", (20, 15), suffix="")
    assert load_dataset(tmp_path, downscale=2).masks == "masks_2"  # by stem, without a suffix too
    (tmp_path / "masks_2" / "view_04.png").unlink()
    one_line_error(lambda: load_dataset(tmp_path, downscale=2), "masks_2/", "no mask for images_2/view_04.png",
                   "data.masks=false")
    Image.fromarray(np.zeros((15, 21), np.uint8)).save(tmp_path / "masks_2" / "view_04.png")
    one_line_error(lambda: load_dataset(tmp_path, downscale=2), "masks_2/view_04.png", "21x15", "20x15")
    Image.fromarray(np.zeros((15, 20), np.uint8)).save(tmp_path / "masks_2" / "view_04_mask.png")
    Image.fromarray(np.zeros((15, 20), np.uint8)).save(tmp_path / "masks_2" / "view_04.jpg")
    one_line_error(lambda: load_dataset(tmp_path, downscale=2), "could each be the mask")
    (tmp_path / "masks_2" / "view_04.jpg").write_bytes(b"not an image")
    (tmp_path / "masks_2" / "view_04.png").unlink()
    one_line_error(lambda: load_dataset(tmp_path, downscale=2), "masks_2/view_04.jpg")


def _broken(path: Path, kind: str, rows: np.ndarray) -> None:
    if kind == "wrong shape":
        np.save(path, rows[:, :15])
    elif kind == "nan":
        bad = rows.copy()
        bad[3, 7] = np.nan
        np.save(path, bad)
    elif kind == "inf":
        bad = rows.copy()
        bad[0, 16] = np.inf
        np.save(path, bad)
    elif kind == "too few rows":
        np.save(path, rows[:-1])
    elif kind == "too many rows":
        np.save(path, np.concatenate([rows, rows[:1]]))
    elif kind == "truncated":
        np.save(path, rows)
        path.write_bytes(path.read_bytes()[:-40])
    elif kind == "pickled object array":
        np.save(path, np.array([rows, "x"], dtype=object), allow_pickle=True)
    elif kind == "a pickle":
        path.write_bytes(pickle.dumps(rows))
    elif kind == "bool":
        np.save(path, rows > 0)
    elif kind == "not a rotation":
        bad = rows.copy()
        bad[2, 0] *= 2
        np.save(path, bad)
    elif kind == "near after far":
        bad = rows.copy()
        bad[1, 15], bad[1, 16] = 9.0, 2.0
        np.save(path, bad)
    elif kind == "zero focal":
        bad = rows.copy()
        bad[5, 14] = 0.0
        np.save(path, bad)
    elif kind == "fractional size":
        bad = rows.copy()
        bad[0, 4] = 30.5
        np.save(path, bad)


BROKEN = {"wrong shape": "shape [9, 15]", "nan": "row 3 column 7", "inf": "row 0 column 16",
          "too few rows": "8 rows for 9 images", "too many rows": "10 rows for 9 images", "truncated": "truncated",
          "pickled object array": "Python objects", "a pickle": "not a valid .npy", "bool": "dtype bool",
          "not a rotation": "row 2", "near after far": "row 1: near, far", "zero focal": "row 5: focal",
          "fractional size": "row 0: height, width"}


def test_broken_poses_bounds_are_one_line_through_load_dataset_and_the_cli(tmp_path):
    from click.testing import CliRunner

    from splatbench.cli import main

    forward_scene(tmp_path / "ok", rows_dtype=np.float64)
    rows = np.load(tmp_path / "ok" / POSES_FILE)
    runner = CliRunner()
    for kind, part in BROKEN.items():
        folder = tmp_path / kind.replace(" ", "_")
        folder.mkdir()
        (folder / "images").symlink_to(tmp_path / "ok" / "images")
        _broken(folder / POSES_FILE, kind, rows)
        msg = one_line_error(lambda: load_dataset(folder), part)
        assert POSES_FILE in msg, (kind, msg)
    for kind in ("wrong shape", "nan", "too few rows", "truncated", "pickled object array"):
        res = runner.invoke(main, ["train", str(tmp_path / kind.replace(" ", "_")), "--set", "iterations=2",
                                   "--quiet", "--out", str(tmp_path / "out" / kind.replace(" ", "_"))])
        assert res.exit_code != 0 and "Traceback" not in res.output, (kind, res.output)
        assert res.exception is None or isinstance(res.exception, SystemExit), (kind, res.exception)
        assert len(res.stderr.strip().splitlines()) == 1 and POSES_FILE in res.stderr, (kind, res.stderr)


def test_colmap_wins_over_poses_bounds_with_a_note_and_layout_llff_reads_it(tmp_path):
    cams = forward_scene(tmp_path, rows_dtype=np.float64)
    _tool().convert(tmp_path, tmp_path / "c", "colmap")
    for item in ("sparse",):
        (tmp_path / item).symlink_to(tmp_path / "c" / item)
    auto = load_dataset(tmp_path, test_every=0)
    assert auto.layout == "colmap" and any(POSES_FILE in n and "data.layout=llff" in n for n in auto.notes)
    llff = load_dataset(tmp_path, test_every=0, layout="llff")
    assert llff.layout == "llff"
    _assert_cameras(llff.train.cameras, cams, 1e-14, 1e-14, 1e-12)


@pytest.mark.skipif(not (SHARED / "maryrose").is_dir(), reason="needs ../shared/data/maryrose and ethiopian_head")
@pytest.mark.parametrize("name, views, size, original", [("maryrose", 69, 216, 3456),
                                                          ("ethiopian_head", 66, 250, 4000)])
def test_real_llff_captures_with_masks_load(name, views, size, original):
    ds = load_dataset(SHARED / name, downscale=16)
    assert ds.layout == "llff" and ds.masks == "masks_8"
    assert len(ds.train) + len(ds.test) == views and len(ds.test) == math.ceil(views / 8)
    assert ds.train.image_size == (size, size) and ds.train.alpha_pixels is not None
    rows = np.load(SHARED / name / POSES_FILE)
    assert ds.train.cameras[0].fx == pytest.approx(rows[1, 14] * size / original, rel=1e-12)  # views[1]: train
    assert ds.train.cameras[0].cx == size / 2
    # the alpha marks the object: a minority of each view, never empty
    cover = ds.train.alphas.mean(axis=(1, 2))
    assert 0.02 < cover.min() and cover.max() < 0.9
    one_line_error(lambda: load_dataset(SHARED / name, downscale=4), "data.downscale=4", "available factors 8")


def test_masks_are_read_in_every_layout_and_the_converter_copies_them(tmp_path, capsys):
    """trial 40 item 2: a COLMAP or transforms.json capture reads masks/ as LLFF does; the
    converter copies them (and says so), so a converted capture has the same alphas."""
    forward_scene(tmp_path / "llff", rows_dtype=np.float64)
    masks = _write_masks(tmp_path / "llff", "masks", (40, 30))
    want = load_dataset(tmp_path / "llff", test_every=0)
    assert want.masks == "masks" and np.array_equal(want.train.alpha_pixels, np.stack(masks))
    tool = _tool()
    for layout in ("colmap", "blender"):
        assert tool.main([str(tmp_path / "llff"), str(tmp_path / layout), "--to", layout]) == 0
        assert "copied 9 masks from masks/ to masks/" in capsys.readouterr().out
        lines: list[str] = []
        got = load_dataset(tmp_path / layout, test_every=0, say=lines.append)
        assert got.masks == "masks" and any(line.startswith("masks: masks/ (9 object masks)") for line in lines)
        np.testing.assert_array_equal(got.train.alpha_pixels, want.train.alpha_pixels)
        np.testing.assert_array_equal(got.train.image(2), want.train.image(2))  # composited alike
        # data.masks=false: no alphas, and a note (never silent)
        off = load_dataset(tmp_path / layout, test_every=0, masks=False)
        assert off.train.alpha_pixels is None and off.masks == ""
        assert any("masks ignored (data.masks=false)" in n for n in off.notes)
    # COLMAP's own naming (the whole image name + .png) at downscale 2: images_2/ takes masks_2/
    root = tmp_path / "colmap"
    for p in sorted((root / "masks").iterdir()):
        p.rename(root / "masks" / (p.stem + ".png.png"))
    (root / "images_2").symlink_to(tmp_path / "llff" / "images_2")
    half = _write_masks(root, "masks_2", (20, 15), suffix=".png")
    ds = load_dataset(root, test_every=0, downscale=2)
    assert ds.masks == "masks_2" and ds.train.names[0].startswith("images_2/")
    np.testing.assert_array_equal(ds.train.alpha_pixels, np.stack(half))
    # no masks_4/: the full-size masks/ serve images/ at downscale 4 (resized with their photos)
    assert load_dataset(root, test_every=0, downscale=4).masks == "masks"
    # the LLFF capture without masks converts with none, and says so
    assert tool.main([str(tmp_path / "llff"), str(tmp_path / "bare"), "--to", "colmap", "--no-masks"]) == 0
    assert not (tmp_path / "bare" / "masks").exists()
    assert load_dataset(tmp_path / "bare", test_every=0).train.alpha_pixels is None


def test_masks_with_a_distorted_camera_are_refused(tmp_path):
    forward_scene(tmp_path / "llff", rows_dtype=np.float64)
    _write_masks(tmp_path / "llff", "masks", (40, 30))
    _tool().convert(tmp_path / "llff", tmp_path / "b", "blender")
    meta = json.loads((tmp_path / "b" / "transforms.json").read_text())
    meta["k1"] = 0.01
    (tmp_path / "b" / "transforms.json").write_text(json.dumps(meta))
    one_line_error(lambda: load_dataset(tmp_path / "b", test_every=0), "lens distortion", "masks/",
                   "image_undistorter", "data.masks=false")


def test_ambiguous_and_stray_masks(tmp_path):
    """trial 40 item 8: X.png and X_mask.png for image X is one line naming both; a mask no
    image takes is a note."""
    forward_scene(tmp_path, rows_dtype=np.float64)
    _write_masks(tmp_path, "masks_2", (20, 15))
    Image.fromarray(np.zeros((15, 20), np.uint8)).save(tmp_path / "masks_2" / "view_03.png")
    one_line_error(lambda: load_dataset(tmp_path, downscale=2), "masks_2/view_03.png", "masks_2/view_03_mask.png",
                   "images_2/view_03.png", "keep one")
    (tmp_path / "masks_2" / "view_03.png").rename(tmp_path / "masks_2" / "view_99_mask.png")
    ds = load_dataset(tmp_path, downscale=2)
    assert ds.masks == "masks_2"
    assert any("1 masks match no image" in n and "view_99_mask.png" in n for n in ds.notes), ds.notes


def test_mask_errors_name_the_file_and_a_fix(tmp_path):
    forward_scene(tmp_path, rows_dtype=np.float64)
    _write_masks(tmp_path, "masks_2", (20, 15))
    Image.fromarray(np.zeros((15, 21), np.uint8)).save(tmp_path / "masks_2" / "view_04_mask.png")
    one_line_error(lambda: load_dataset(tmp_path, downscale=2), "masks_2/view_04_mask.png", "21x15", "20x15",
                   "resize or re-export it", "data.masks=false")
    (tmp_path / "masks_2" / "view_04_mask.png").write_bytes(b"not an image")
    msg = one_line_error(lambda: load_dataset(tmp_path, downscale=2), "masks_2/view_04_mask.png")
    assert "BytesIO" not in msg and " at 0x" not in msg, msg


def test_poses_bounds_messages_name_the_file_and_print_plain_numbers(tmp_path):
    """trial 40 item 7: the full path, no numpy reprs, and what a valid file is."""
    forward_scene(tmp_path / "ok", rows_dtype=np.float64)
    rows = np.load(tmp_path / "ok" / POSES_FILE)
    for kind, bad, part in (("nan", (3, 7, np.inf), "row 3 column 7 is inf"),
                            ("size", (0, 4, 30.5), "height, width 30.5, 40"),
                            ("focal", (5, 14, -2.0), "focal -2"), ("near", (1, 15, 9.0), "near, far 9, 8")):
        folder = tmp_path / kind
        folder.mkdir()
        (folder / "images").symlink_to(tmp_path / "ok" / "images")
        broken = rows.copy()
        broken[bad[0], bad[1]] = bad[2]
        np.save(folder / POSES_FILE, broken)
        msg = one_line_error(lambda: load_dataset(folder), str(folder / POSES_FILE), part)
        assert "np." not in msg, msg
    for kind, data in (("empty", b""), ("text", b"0 1 2 3\n")):
        (tmp_path / kind).mkdir()
        (tmp_path / kind / "images").symlink_to(tmp_path / "ok" / "images")
        (tmp_path / kind / POSES_FILE).write_bytes(data)
        one_line_error(lambda: load_dataset(tmp_path / kind), str(tmp_path / kind / POSES_FILE),
                       "a valid one is LLFF's N x 17 float array")
    one_line_error(lambda: load_dataset(tmp_path / "none"), "COLMAP", "transforms", "LLFF")


def test_the_converter_writes_whole_or_nothing_and_its_help_and_messages_name_its_flags(tmp_path, capsys):
    """trial 40 items 4 and 6."""
    forward_scene(tmp_path / "llff", rows_dtype=np.float64)
    tool = _tool()
    tool.convert(tmp_path / "llff", tmp_path / "colmap", "colmap")  # no points: --to llff needs --near/--far
    assert tool.main([str(tmp_path / "colmap"), str(tmp_path / "back"), "--to", "llff"]) == 2
    assert "--near and --far" in capsys.readouterr().err
    assert not (tmp_path / "back").exists() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    (tmp_path / "back").mkdir()  # an empty DST is fine; a non-empty one is refused in one line
    assert tool.main([str(tmp_path / "colmap"), str(tmp_path / "back"), "--to", "llff", "--near", "3",
                      "--far", "8"]) == 0
    assert (tmp_path / "back" / POSES_FILE).is_file()
    capsys.readouterr()
    assert tool.main([str(tmp_path / "colmap"), str(tmp_path / "back"), "--to", "llff"]) == 2
    err = capsys.readouterr().err
    assert "not empty" in err and len(err.strip().splitlines()) == 1
    # a downscale no folder serves names the converter's flag, not the config key
    assert tool.main([str(tmp_path / "llff"), str(tmp_path / "x"), "--to", "colmap", "--downscale", "3"]) == 2
    err = capsys.readouterr().err
    assert "--downscale" in err and "data.downscale" not in err, err
    with pytest.raises(SystemExit):
        tool.main(["--help"])
    text = capsys.readouterr().out
    assert "issue 40" not in text and "masks" in text
    flat = " ".join(text.split())
    for help_text in ("SRC the capture folder to read", "DST the folder to write", "the layout to write",
                      "read SRC's images reduced by N", "near depth bound", "FAR with --near",
                      "--no-masks do not read or copy"):  # every argument has its own help
        assert help_text in flat, help_text
