"""Captures as they come: lens distortion undistorted on load (pycolmap), downscaling, the
every-8th split, teacher scenes and grids over any scene (splatbench.data, experiments.teacher,
experiments.train_kind)."""

from __future__ import annotations

import dataclasses

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from splatbench.data import load_dataset
from splatbench.errors import InputError

FOX = Path(__file__).resolve().parents[2] / "shared" / "data" / "fox"
W, H = 64, 48
OPENCV = {"fl_x": 60.0, "fl_y": 61.0, "cx": 31.0, "cy": 24.5, "k1": 0.12, "k2": -0.05, "p1": 0.002, "p2": -0.001}


def _colour(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smooth colour of the ray direction (x/z, y/z) [.., 3] in [0.1, 0.9]."""
    return np.stack([0.5 + 0.4 * np.sin(3 * x) * np.cos(2 * y), 0.5 + 0.4 * np.cos(2.5 * x + y),
                     0.5 + 0.4 * np.sin(2 * y - x)], axis=-1)


def _lens():
    import pycolmap

    p = OPENCV
    return pycolmap.Camera(model="OPENCV", width=W, height=H,
                           params=[p["fl_x"], p["fl_y"], p["cx"], p["cy"], p["k1"], p["k2"], p["p1"], p["p2"]])


def _distorted_capture(root: Path, n: int = 3, extra: dict | None = None) -> Path:
    """A transforms.json capture whose photos are the smooth colour of each pixel's ray
    through the OPENCV lens (exact, no resampling)."""
    lens = _lens()
    j, i = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    rays = lens.cam_from_img(np.stack([j.ravel(), i.ravel()], axis=1))
    image = (_colour(rays[:, 0], rays[:, 1]).reshape(H, W, 3) * 255).round().astype(np.uint8)
    (root / "images").mkdir(parents=True)
    frames = []
    for k in range(n):
        Image.fromarray(image).save(root / "images" / f"{k:04d}.png")
        c2w = np.eye(4)
        c2w[:3, 3] = [k * 0.1, 0.0, 2.0]
        frames.append({"file_path": f"images/{k:04d}.png", "transform_matrix": c2w.tolist(), "sharpness": 1.0})
    meta = {**OPENCV, "w": W, "h": H, "aabb_scale": 4, "frames": frames, **(extra or {})}
    (root / "transforms.json").write_text(json.dumps(meta))
    return root


def test_transforms_with_distortion_is_undistorted_by_pycolmap(tmp_path, monkeypatch):
    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    lines: list[str] = []
    ds = load_dataset(_distorted_capture(tmp_path / "cap"), test_every=0, say=lines.append)
    assert any("OPENCV lens distortion undistorted by pycolmap" in n for n in ds.notes)
    assert any("ignored keys aabb_scale, sharpness" in n for n in ds.notes)
    cam = ds.train.cameras[0]
    # the note gives the focal the views train with (after the crop), as the camera carries it
    assert any(f"focal {cam.fx:.6g} x {cam.fy:.6g} px)" in n for n in ds.notes), ds.notes
    import pycolmap

    expected = pycolmap.undistort_camera(pycolmap.UndistortCameraOptions(), _lens())
    assert (cam.width, cam.height) == (expected.width, expected.height)
    # Each undistorted pixel must show the colour of its pinhole ray. Error budget: 8-bit
    # rounding of the source and of the output (2 x 0.5/255) plus bilinear interpolation
    # of a function with |f''| <= 0.4 * 3^2 over 1/60-wide pixels ((1/60)^2 / 8 * 3.6 * 2
    # < 3e-4): 0.005 bounds it; a wrong principal point or a skipped remap is off by > 0.02.
    j, i = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    want = _colour((j - cam.cx) / cam.fx, (i - cam.cy) / cam.fy)
    err = np.abs(ds.train.images[0] - want)[2:-2, 2:-2]  # the outermost pixels interpolate with the border
    assert err.max() < 0.005, err.max()
    # cached by content: a second load reuses the folder and does not run pycolmap again
    lines.clear()
    again = load_dataset(tmp_path / "cap", test_every=0, say=lines.append)
    assert not any(line.startswith("undistorting") for line in lines)
    assert np.array_equal(again.train.images, ds.train.images)


@pytest.mark.parametrize("extra, message", [
    ({"k4": 0.1}, "k4: an OPENCV camera has no k4 term"),
    ({"camera_model": "PINHOLE"}, "camera_model PINHOLE with distortion"),
    ({"camera_model": "EQUIRECTANGULAR"}, "camera_model: expected PINHOLE"),
    ({"camera_model": "OPENCV_FISHEYE"}, "p1, p2: an OPENCV_FISHEYE camera has no tangential terms"),
])
def test_what_cannot_be_undistorted_is_refused_in_one_line(tmp_path, monkeypatch, extra, message):
    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    with pytest.raises(InputError, match=message) as exc:
        load_dataset(_distorted_capture(tmp_path / "cap", extra=extra))
    assert "\n" not in str(exc.value)


def _pinhole_capture(root: Path, n: int, size=(32, 24)) -> Path:
    (root / "images").mkdir(parents=True)
    rng = np.random.default_rng(0)
    frames = []
    for k in range(n):
        Image.fromarray(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)).save(
            root / "images" / f"{k:04d}.png")
        c2w = np.eye(4)
        c2w[:3, 3] = [k * 0.1, 0.0, 2.0]
        frames.append({"file_path": f"images/{k:04d}.png", "transform_matrix": c2w.tolist()})
    meta = {"fl_x": 30.0, "fl_y": 30.0, "cx": 16.0, "cy": 12.0, "w": size[0], "h": size[1], "frames": frames[::-1]}
    (root / "transforms.json").write_text(json.dumps(meta))
    return root


@pytest.mark.parametrize("edit, message", [
    (lambda m: m.update(fl_x="30.0"), "transforms.json: fl_x: expected a number, got '30.0'"),
    (lambda m: m.update(w=True), "transforms.json: w: expected a number, got True"),  # True is an int in Python
    (lambda m: m.update(camera_angle_y="0.7"), "transforms.json: camera_angle_y: expected a number, got '0.7'"),
    (lambda m: m.update(k1=None), "transforms.json: k1: expected a number, got null"),
    (lambda m: m["frames"][0].update(cy="12"), "transforms.json: frames[0]: cy: expected a number, got '12'"),
    (lambda m: m["frames"][1]["transform_matrix"][0].__setitem__(3, "0.1"),
     "transforms.json: frames[1]: transform_matrix[0][3]: expected a number, got '0.1'"),
    (lambda m: m["frames"][0]["transform_matrix"][2].__setitem__(2, False),
     "transforms.json: frames[0]: transform_matrix[2][2]: expected a number, got False"),
    (lambda m: m["frames"][0].update(transform_matrix=None),
     "transforms.json: frames[0]: transform_matrix: expected shape [4, 4], got null"),
])
def test_a_string_flag_or_null_where_transforms_json_wants_a_number_is_one_line(tmp_path, edit, message):
    """Nothing a user gives is reinterpreted: "30.0" is not read as 30.0, nor true as 1."""
    root = _pinhole_capture(tmp_path / "cap", 3)
    meta = json.loads((root / "transforms.json").read_text())
    edit(meta)
    (root / "transforms.json").write_text(json.dumps(meta))
    with pytest.raises(InputError) as exc:
        load_dataset(root, test_every=0)
    assert str(exc.value) == message


def test_downscale_scales_cameras_and_prefers_images_n(tmp_path):
    root = _pinhole_capture(tmp_path / "cap", 17)
    ds = load_dataset(root, downscale=2)
    cam = ds.train.cameras[0]
    assert (cam.width, cam.height, cam.fx, cam.cx) == (16, 12, 15.0, 8.0)
    assert ds.train.images.shape[1:] == (12, 16, 3)
    # every 8th image by sorted name (frames are listed in reverse): 0000, 0008, 0016
    assert ds.test.names == ["images/0000.png", "images/0008.png", "images/0016.png"]
    assert any("every 8th image by sorted name" in n for n in ds.notes)
    # an images_2/ folder is read instead of resizing (graphdeco's copies), cameras fitted to it
    (root / "images_2").mkdir()
    for k in range(17):
        Image.fromarray(np.full((12, 16, 3), k, np.uint8)).save(root / "images_2" / f"{k:04d}.png")
    ds2 = load_dataset(root, downscale=2)
    assert ds2.test.images[1].max() == pytest.approx(8 / 255)  # images_2/0008.png, not a resized original
    assert ds2.train.cameras[0].fx == 15.0
    assert any("reading images_2/" in n for n in ds2.notes)
    with pytest.raises(InputError, match="downscale: expected an int >= 1"):
        load_dataset(root, downscale=0)


def test_long_side_over_1600_px_is_noted(tmp_path):
    root = _pinhole_capture(tmp_path / "cap", 2, size=(1700, 8))
    assert any("exceeds 1600 px" in n for n in load_dataset(root).notes)
    assert not any("exceeds 1600 px" in n for n in load_dataset(root, downscale=2).notes)


def test_colmap_opencv_capture_undistorts_to_the_pinhole_colours(tmp_path, monkeypatch):
    """A COLMAP model with an OPENCV camera (the photos made through the lens, exactly) loads
    as PINHOLE views whose pixels show their pinhole rays' colours (same budget as above)."""
    import pycolmap

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    cap = _distorted_capture(tmp_path / "cap", n=2)
    rec = pycolmap.Reconstruction()
    cam = _lens()
    cam.camera_id = 1
    rec.add_camera_with_trivial_rig(cam)
    for k in range(2):
        image = pycolmap.Image(name=f"{k:04d}.png", camera_id=1, image_id=k + 1)
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(), [k * 0.1, 0.0, 2.0]))
    (cap / "sparse" / "0").mkdir(parents=True)
    rec.write(str(cap / "sparse" / "0"))
    ds = load_dataset(cap, layout="colmap", test_every=0)
    c = ds.train.cameras[0]
    j, i = np.meshgrid(np.arange(c.width) + 0.5, np.arange(c.height) + 0.5)
    err = np.abs(ds.train.images[1] - _colour((j - c.cx) / c.fx, (i - c.cy) / c.fy))[2:-2, 2:-2]
    assert err.max() < 0.005, err.max()
    assert np.allclose(ds.train.cameras[1].translation, [0.1, 0.0, 2.0])


@pytest.mark.slow  # reads and undistorts 67 photos of 1080x1920 (~15 s)
@pytest.mark.skipif(not FOX.is_dir(), reason="needs ../shared/data/fox (NVIDIA non-commercial licence, not bundled)")
def test_fox_capture_loads_undistorted_and_downscaled(tmp_path, monkeypatch):
    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    ds = load_dataset(FOX, downscale=8)
    # COLMAP's undistorter crops the 1080x1920 photos to the 1067x1897 pixels that saw the
    # scene (keeping 1080x1920 would add 36k blank pixels); / 8 -> 133x237
    assert {(c.width, c.height) for c in ds.train.cameras + ds.test.cameras} == {(133, 237)}
    assert (len(ds.train), len(ds.test)) == (58, 9)
    assert ds.test.names[:2] == ["images/0001.jpg", "images/0009.jpg"]
    assert ds.train.alphas is None  # a real capture is opaque


def _small_ply(path: Path, up=None) -> Path:
    from splatbench.gaussians import Gaussians
    from splatbench.ply import ViewHints

    rng = np.random.default_rng(1)
    n = 60
    sh = np.zeros((n, 1, 3))
    sh[:, 0] = rng.uniform(-1, 1, (n, 3))
    Gaussians(means=rng.normal(0, 0.5, (n, 3)), log_scales=np.full((n, 3), np.log(0.15)),
              quats=np.tile([1.0, 0, 0, 0], (n, 1)), opacity_logits=np.full(n, 3.0), sh=sh).to_ply(
        path, ViewHints(up=up) if up else None)
    return path


def test_teacher_scene_renders_exact_views_and_points(tmp_path):
    from splatbench.experiments.teacher import render_teacher

    ply = _small_ply(tmp_path / "toy.ply", up=(0.0, 0.0, 1.0))
    t = render_teacher(ply, tmp_path / "teacher", views=16, resolution=24)
    assert t.up == (0.0, 0.0, 1.0) and t.up_source == "the PLY's hint" and not t.cached
    ds = load_dataset(t.path)
    assert (len(ds.train), len(ds.test)) == (14, 2) and ds.train.images.shape[1:] == (24, 24, 3)
    assert ds.points is not None and len(ds.points) > 10
    # the points are unprojected render depth, not the teacher's 60 Gaussian centres
    assert len(ds.points) != 60
    assert render_teacher(ply, tmp_path / "teacher", views=16, resolution=24).cached


_MIXED = """
name = "mixed"
kind = "train"
scenes = ["diffuse", { name = "cap", path = "cap", downscale = 2 }, { name = "toy", model = "toy.ply", views = 9 }]
[base]
iterations = 20
init.method = "random"
init.random_points = 200
data.resolution = 40     # LPIPS (AlexNet) needs images of about 32 px or more
data.views = 9
data.spp = 2
"""


def _mixed_grid(tmp_path):
    from splatbench.experiments.grid import load_experiment

    _pinhole_capture(tmp_path / "exp" / "cap", 9, size=(80, 64))
    _small_ply(tmp_path / "exp" / "toy.ply")
    (tmp_path / "exp" / "grid.toml").write_text(_MIXED)
    return load_experiment(tmp_path / "exp" / "grid.toml")


def test_grid_scenes_resolve_per_scene_type(tmp_path):
    """Expansion only (no run): each scene type keeps the data keys that apply to it."""
    from splatbench.experiments.grid import expand

    runs = {r.scene: r.config for r in expand(_mixed_grid(tmp_path))}
    reading = {"layout": "auto", "test_every": 8, "masks": True}  # DataConfig's, in every run
    assert runs["diffuse"]["data"] == {"resolution": 40, "views": 9, "spp": 2, **reading}
    assert runs["cap"]["data"] == {"path": str((tmp_path / "exp" / "cap").resolve()), "downscale": 2, **reading}
    assert runs["toy"]["data"] == {"model": str((tmp_path / "exp" / "toy.ply").resolve()), "views": 9,
                                   "resolution": 40, **reading}
    assert runs["cap"]["iterations"] == runs["toy"]["iterations"] == 20


def test_run_ids_of_user_data_follow_content_not_path(tmp_path):
    """A committed report's run ids must hold in another clone: the same folder and model at
    another path give the same ids; one changed byte of a model, or one more image, gives new
    ones; splatbench's own SfM cache inside the folder does not change them."""
    import shutil

    from splatbench.experiments.grid import expand, load_experiment

    first = {r.scene: r.run_id for r in expand(_mixed_grid(tmp_path / "a"))}
    shutil.copytree(tmp_path / "a" / "exp", tmp_path / "b" / "moved")
    moved = load_experiment(tmp_path / "b" / "moved" / "grid.toml")
    assert {r.scene: r.run_id for r in expand(moved)} == first

    (tmp_path / "b" / "moved" / "cap" / "sfm").mkdir()
    (tmp_path / "b" / "moved" / "cap" / "sfm" / "model.bin").write_bytes(b"derived")
    assert {r.scene: r.run_id for r in expand(load_experiment(moved.source))} == first

    ply = tmp_path / "b" / "moved" / "toy.ply"
    data = bytearray(ply.read_bytes())
    data[-1] ^= 1
    ply.write_bytes(bytes(data))
    image = next((tmp_path / "b" / "moved" / "cap" / "images").iterdir())
    shutil.copy(image, image.with_name("zz_extra" + image.suffix))
    changed = {r.scene: r.run_id for r in expand(load_experiment(moved.source))}
    assert changed["diffuse"] == first["diffuse"]
    assert changed["toy"] != first["toy"] and changed["cap"] != first["cap"]


@pytest.mark.slow
def test_grid_over_catalog_folder_and_teacher_scenes_runs_and_reports(tmp_path, monkeypatch):
    from splatbench.experiments.runner import run_experiment

    monkeypatch.setenv("SPLATBENCH_DATASETS", str(tmp_path / "datasets"))
    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    spec = _mixed_grid(tmp_path)
    summary = run_experiment(spec, results_dir=tmp_path / "results", workers=1, progress=False)
    from splatbench.experiments.store import read_records

    rows = {r.scene: r for r in read_records(tmp_path / "results" / "mixed").values()}
    assert set(rows) == {"diffuse", "cap", "toy"}
    assert all(r.status == "done" for r in rows.values()), [r.error for r in rows.values()]
    # the folder's keys as the file gave them (the path made absolute), the rest of DataConfig at its defaults
    from splatbench.train.config import DataConfig

    defaults = {k: v for k, v in dataclasses.asdict(DataConfig()).items() if k not in ("path", "downscale")}
    assert rows["cap"].config["data"] == {"path": str((tmp_path / "exp" / "cap").resolve()), "downscale": 2,
                                          **defaults}
    assert rows["toy"].config["data"]["resolution"] == 40 and rows["toy"].config["data"]["views"] == 9
    assert "spp" not in rows["toy"].config["data"]
    assert all(r.metrics["test_psnr"] is not None for r in rows.values())
    assert (summary.done, summary.failed) == (3, 0)
    from splatbench.reports.report import build_report, write_report

    text = write_report(build_report(spec, tmp_path / "results"), tmp_path / "report").read_text()
    assert "scenes diffuse, cap, toy" in text and "content): `cap` path `cap`" in text  # as the file writes it, not absolute



@pytest.mark.slow
def test_opencv_capture_trains_like_the_same_scene_rendered_pinhole(tmp_path, monkeypatch):
    """A teacher scene rendered pinhole, and the same views seen through a known OPENCV lens
    (a COLMAP capture made by sampling 2x-resolution, wider pinhole renders at each distorted
    pixel's ray; the pinhole dataset's points as its points3D), train to the same test PSNR
    once the loader has undistorted the second.

    Bound, derived: the undistorted targets differ from exact pinhole renders of their cameras
    by resampling error of PSNR ``P_r`` (measured below: bilinear twice). A model fitting the
    scene to ``P_pin`` then scores, with independent errors adding in MSE,
    ``P_pred = -10 log10(10^(-P_pin/10) + 10^(-P_r/10))`` against them. The run must reach
    ``P_pred - 1 dB``; the 1 dB is an allowance (not derived) for what the prediction leaves
    out: the undistorted views are a crop of the pinhole ones (less border), and the two runs
    see different pixels, so their optimisations differ. A loader that ignored the lens (the
    old behaviour) or put the principal point off would leave target and camera inconsistent
    by several pixels at the borders."""
    import pycolmap
    from scipy.ndimage import map_coordinates

    from splatbench.cameras import Camera
    from splatbench.gaussians import Gaussians
    from splatbench.raster.api import render
    from splatbench.experiments.teacher import render_teacher
    from splatbench.train import TrainConfig, train

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    ply = _small_ply(tmp_path / "toy.ply")
    teacher = Gaussians.from_ply(ply)
    pin = render_teacher(ply, tmp_path / "pin", views=24, resolution=48).path
    every = load_dataset(pin)
    cams = every.train.cameras + every.test.cameras
    names = every.train.names + every.test.names
    c0 = cams[0]
    k = (0.1, -0.03, 0.001, -0.001)  # k1 k2 p1 p2
    lens = pycolmap.Camera(model="OPENCV", width=c0.width, height=c0.height,
                           params=[c0.fx, c0.fy, c0.cx, c0.cy, *k])
    cap = tmp_path / "opencv"
    (cap / "images").mkdir(parents=True)
    j, i = np.meshgrid(np.arange(c0.width) + 0.5, np.arange(c0.height) + 0.5)
    rays = lens.cam_from_img(np.stack([j.ravel(), i.ravel()], axis=1))
    rec = pycolmap.Reconstruction()
    lens.camera_id = 1
    rec.add_camera_with_trivial_rig(lens)
    for n, (cam, name) in enumerate(zip(cams, names)):
        big = Camera(3 * cam.width, 3 * cam.height, 2 * cam.fx, 2 * cam.fy, 2 * cam.cx + cam.width / 2,
                     2 * cam.cy + cam.height / 2, cam.world_to_camera, cam.near, cam.far)
        hi = render(teacher, big).rgb
        u = 2 * cam.fx * rays[:, 0] + big.cx - 0.5
        v = 2 * cam.fy * rays[:, 1] + big.cy - 0.5
        img = np.stack([map_coordinates(hi[..., ch], [v, u], order=1) for ch in range(3)], axis=-1)
        img = (np.clip(img, 0, 1) * 255).round().astype(np.uint8).reshape(cam.height, cam.width, 3)
        Image.fromarray(img).save(cap / "images" / Path(name).name)
        image = pycolmap.Image(name=Path(name).name, camera_id=1, image_id=n + 1)
        rec.add_image_with_trivial_frame(image, cam.to_colmap()[1])
    points = every.points
    for xyz, rgb in zip(points.xyz, points.rgb):
        rec.add_point3D(xyz, pycolmap.Track(), rgb)
    (cap / "sparse" / "0").mkdir(parents=True)
    rec.write(str(cap / "sparse" / "0"))
    (cap / "split.json").write_text((pin / "split.json").read_text())

    undist = load_dataset(cap)
    floor = []
    for cam, gt in zip(undist.test.cameras, undist.test.images):
        exact = render(teacher, cam).rgb
        floor.append(np.mean((exact[2:-2, 2:-2] - gt[2:-2, 2:-2]) ** 2))
    p_r = -10 * np.log10(np.mean(floor))
    settings = dict(iterations=300)  # init "auto": the same points3D (jittered alike, seed 0) for both
    p_pin = train(TrainConfig(dataset=str(pin), out=str(tmp_path / "run-pin"), **settings)).test_psnr
    p_dist = train(TrainConfig(dataset=str(cap), out=str(tmp_path / "run-dist"), **settings)).test_psnr
    p_pred = -10 * np.log10(10 ** (-p_pin / 10) + 10 ** (-p_r / 10))
    print(f"pinhole {p_pin:.2f} dB, OPENCV undistorted {p_dist:.2f} dB, resampling floor {p_r:.2f} dB, "
          f"predicted {p_pred:.2f} dB")
    assert p_dist >= p_pred - 1.0, (p_pin, p_dist, p_r, p_pred)


def test_train_config_data_downscale():
    from splatbench.train.config import DataConfig, TrainConfig, apply_overrides

    cfg = apply_overrides(TrainConfig(), ["data.downscale=8"])
    assert cfg.data == DataConfig(downscale=8) and TrainConfig().data.downscale == 1
    assert TrainConfig.from_toml(cfg.to_toml()) == cfg
    with pytest.raises(InputError, match="data.size: unknown key"):
        apply_overrides(TrainConfig(), ["data.size=8"])
    with pytest.raises(InputError, match="data.downscale: expected an int >= 1"):
        apply_overrides(TrainConfig(), ["data.downscale=0"])


def test_scene_tables_are_checked_in_one_line(tmp_path):
    from splatbench.experiments.spec import parse_experiment

    def parse(scene):
        return parse_experiment({"kind": "train", "scenes": [scene]}, source="x.toml", default_name="x",
                                base_dir=tmp_path)

    with pytest.raises(InputError, match="x.toml: scenes.a: expected exactly one of 'path'"):
        parse({"name": "a"})
    with pytest.raises(InputError, match="scenes.a.path: .* does not exist \\(paths are relative to the experiment file"):
        parse({"name": "a", "path": "nowhere"})
    with pytest.raises(InputError, match="scenes.a.views: unknown key"):
        (tmp_path / "d").mkdir()
        parse({"name": "a", "path": "d", "views": 3})
    # a wrong model file and a zero up are named when the file is read, not when a run starts
    (tmp_path / "t.json").write_text("{}")
    with pytest.raises(InputError, match="x.toml: scenes.a.model: .* is not a PLY with a vertex element"):
        parse({"name": "a", "model": "t.json"})
    _small_ply(tmp_path / "m.ply")
    with pytest.raises(InputError, match="x.toml: scenes.a.up: expected a non-zero direction"):
        parse({"name": "a", "model": "m.ply", "up": [0, 0, 0]})
    assert parse({"name": "a", "model": "m.ply", "up": [0, -1, 0]}).scene_sources["a"]["up"] == [0.0, -1.0, 0.0]
    spec = parse({"name": "a", "path": "d", "downscale": 4})
    assert spec.name == "x" and spec.scenes == ("a",)
    # a bare path where a table is needed: the table to write is named
    from splatbench.experiments.grid import expand
    with pytest.raises(InputError, match=r'unknown scene .*\{ name = "NAME", path = "\.\./d" \}'):
        expand(parse("../d"))
    with pytest.raises(InputError, match="scenes.diffuse: the name of a catalog scene"):
        expand(parse({"name": "diffuse", "path": "d"}))
    assert spec.scene_sources["a"] == {"path": str((tmp_path / "d").resolve()), "downscale": 4}


def test_a_model_trained_on_a_capture_records_the_up_its_cameras_share(tmp_path):
    """A capture declares no up; the trained PLY records the one its cameras share (NeRF c2w
    identity: image-up is world +y) with a note, so `splatbench render` draws it upright."""
    from splatbench.ply import read_view_hints
    from splatbench.train import TrainConfig, train
    from splatbench.train.config import EvalConfig, InitConfig

    cap = _pinhole_capture(tmp_path / "cap", 9)
    result = train(TrainConfig(dataset=str(cap), out=str(tmp_path / "run"), iterations=3, init=InitConfig(method="random", random_points=50), eval=EvalConfig(lpips_net="none")))
    assert np.allclose(read_view_hints(result.ply_path).up, [0.0, 1.0, 0.0], atol=1e-9)
    assert any(n.startswith("world up [0.0, 1.0, 0.0] estimated from the training cameras") for n in result.notes)


@pytest.mark.slow
@pytest.mark.skipif(not FOX.is_dir(), reason="needs ../shared/data/fox (NVIDIA non-commercial licence, not bundled)")
def test_fox_transforms_mutated_loads_or_is_one_line(tmp_path, monkeypatch):
    """The structure-aware fuzz cases (tests/structured_fuzzing.py) on a real capture: the
    fox's transforms.json (its own keys and values, cut to its first 4 frames, with their
    photos; copied to tmp_path, never written in place), 4 cases per mutation class, at
    downscale 8. Each case loads and passes the dataset check or is one InputError line."""
    from tests import structured_fuzzing as sf
    from tests.fuzzing import run_case
    from tests.test_fuzz import _valid_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    seed = tmp_path / "seed"
    sf.capture_seed(FOX, 4)(seed)
    _valid_dataset(load_dataset(seed, test_every=2, downscale=8))
    outcomes: dict[str, int] = {}
    for klass in sf.JSON_CLASSES:
        for number in range(4):
            what = sf.mutate("fox", klass, number, seed, tmp_path / "case")
            try:
                outcome = run_case(f"fox: {klass}", lambda: load_dataset(tmp_path / "case" / "capture", test_every=2,
                                                                         downscale=8), _valid_dataset, 2**24)
            except BaseException as exc:
                raise AssertionError(f"{sf.describe('fox', klass, number)}: {what}: {type(exc).__name__}: "
                                     f"{str(exc)[:300]}") from exc
            outcomes[outcome] = outcomes.get(outcome, 0) + 1
    assert sum(outcomes.values()) == 4 * len(sf.JSON_CLASSES) and outcomes.get("ok", 0) > 0, outcomes
