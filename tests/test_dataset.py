"""`load_dataset`: COLMAP and Blender layouts written by hand the way other tools write
them (pycolmap models old and new, NeRF-synthetic transforms, nerfstudio transforms.json),
the split rules, and one-line errors for missing files, sizes and camera models."""

from __future__ import annotations

import json
import math

import numpy as np
from PIL import Image

import splatbench  # noqa: F401 - sets DRJIT_LIBLLVM_PATH before pycolmap/drjit load
from splatbench.cameras import Camera
from splatbench.data import Dataset, PointCloud, load_dataset
from tests.assertions import one_line_error

W, H = 24, 16
TOL = 1e-9  # float64 all the way (COLMAP binary, JSON repr): agreement to ~1e-15



def orbit_cameras(n: int, width: int = W, height: int = H) -> list[Camera]:
    return [Camera.look_at([3 * math.cos(a), 1.0, 3 * math.sin(a)], [0, 0, 0], [0, 1, 0], width, height, 50.0)
            for a in np.linspace(0, 2 * math.pi, n, endpoint=False)]


def write_image(path, rng, width=W, height=H, channels=3) -> np.ndarray:
    pixels = rng.integers(0, 256, (height, width, channels), dtype=np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(pixels).save(path)
    return pixels


def write_colmap(root, cams, names, *, model="PINHOLE", sparse="sparse/0", rng=None, points=5):
    """A COLMAP model as pycolmap writes it (one camera per image) plus the images."""
    import pycolmap

    rng = rng or np.random.default_rng(0)
    rec = pycolmap.Reconstruction()
    for i, (cam, name) in enumerate(zip(cams, names)):
        if model == "PINHOLE":
            pc, pose = cam.to_colmap()
        else:
            pose = cam.to_colmap()[1]
            params = {"SIMPLE_PINHOLE": [cam.fx, cam.cx, cam.cy],
                      "OPENCV": [cam.fx, cam.fy, cam.cx, cam.cy, 0.1, 0, 0, 0],
                      "FOV": [cam.fx, cam.fy, cam.cx, cam.cy, 0.5]}[model]
            pc = pycolmap.Camera(model=model, width=cam.width, height=cam.height, params=params)
        pc.camera_id = i + 1
        rec.add_camera_with_trivial_rig(pc)
        rec.add_image_with_trivial_frame(pycolmap.Image(name=name, camera_id=i + 1, image_id=i + 1), pose)
        write_image(root / "images" / name, rng, cam.width, cam.height)
    xyz = rng.normal(size=(points, 3))
    rgb = rng.integers(0, 256, (points, 3), dtype=np.uint8)
    for p, c in zip(xyz, rgb):
        rec.add_point3D(p, pycolmap.Track(), c)
    (root / sparse).mkdir(parents=True, exist_ok=True)
    rec.write(str(root / sparse))
    return xyz, rgb


def assert_same_cameras(got: list[Camera], want: list[Camera]) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want):
        assert (a.width, a.height) == (b.width, b.height)
        assert np.abs(a.world_to_camera - b.world_to_camera).max() <= TOL
        assert np.abs(a.K - b.K).max() <= TOL


# ------------------------------------------------------------------------- COLMAP
def test_colmap_layout_every_8th_view_is_held_out(tmp_path):
    cams = orbit_cameras(10)
    names = [f"img_{i:02d}.png" for i in range(10)]
    xyz, rgb = write_colmap(tmp_path, cams, names)
    ds = load_dataset(tmp_path)
    assert isinstance(ds, Dataset) and ds.layout == "colmap" and ds.name == tmp_path.name
    assert ds.test.names == ["images/img_00.png", "images/img_08.png"]
    assert ds.train.names == [f"images/{n}" for i, n in enumerate(names) if i % 8]
    assert_same_cameras(ds.test.cameras, [cams[0], cams[8]])
    assert_same_cameras(ds.train.cameras, [c for i, c in enumerate(cams) if i % 8])
    first = np.asarray(Image.open(tmp_path / "images" / names[0]), dtype=np.float32) / 255
    np.testing.assert_array_equal(ds.test.images[0], first)
    assert ds.train.images.shape == (8, H, W, 3) and ds.train.images.dtype == np.float32
    assert ds.train.depths is None and ds.train.alphas is None
    assert isinstance(ds.points, PointCloud)
    np.testing.assert_array_equal(ds.points.xyz, xyz)
    np.testing.assert_array_equal(ds.points.rgb, rgb)
    assert len(load_dataset(tmp_path, test_every=0).train) == 10
    assert load_dataset(tmp_path, test_every=3).test.names == [f"images/{names[i]}" for i in (0, 3, 6, 9)]


def test_colmap_split_json_depth_and_simple_pinhole(tmp_path):
    cams = orbit_cameras(4)
    names = [f"{i:04d}.png" for i in range(4)]
    write_colmap(tmp_path, cams, names, model="SIMPLE_PINHOLE")
    (tmp_path / "split.json").write_text(json.dumps({"train": names[:3], "test": names[3:]}))
    (tmp_path / "depth").mkdir()
    for i, n in enumerate(names):
        np.save(tmp_path / "depth" / n.replace(".png", ".npy"), np.full((H, W), i + 1.0, np.float32))
    ds = load_dataset(tmp_path)
    assert ds.test.names == ["images/0003.png"]
    assert_same_cameras(ds.train.cameras, cams[:3])
    np.testing.assert_array_equal(ds.test.depths, np.full((1, H, W), 4.0, np.float32))
    (tmp_path / "split.json").write_text(json.dumps({"train": ["nope.png"], "test": []}))
    one_line_error(lambda: load_dataset(tmp_path), "split.json: train: image 'nope.png'")


def test_colmap_models_old_text_and_undistorter_layouts(tmp_path):
    """COLMAP < 3.12 (no rigs/frames files), the text format, and image_undistorter's sparse/."""
    import pycolmap

    cams = orbit_cameras(3)
    names = ["a.png", "b.png", "c.png"]
    write_colmap(tmp_path / "old", cams, names)
    for f in ("rigs.bin", "frames.bin"):
        (tmp_path / "old" / "sparse" / "0" / f).unlink()
    assert_same_cameras(load_dataset(tmp_path / "old", test_every=0).train.cameras, cams)

    write_colmap(tmp_path / "undistorted", cams, names, sparse="sparse")
    rec = pycolmap.Reconstruction(str(tmp_path / "undistorted" / "sparse"))
    for f in (tmp_path / "undistorted" / "sparse").glob("*.bin"):
        f.unlink()
    rec.write_text(str(tmp_path / "undistorted" / "sparse"))
    assert_same_cameras(load_dataset(tmp_path / "undistorted", test_every=0).train.cameras, cams)


def test_colmap_images_dir_scales_cameras_to_the_images(tmp_path):
    cams = orbit_cameras(2, 48, 32)
    write_colmap(tmp_path, cams, ["a.png", "b.png"])
    rng = np.random.default_rng(1)
    for n in ("a.png", "b.png"):
        write_image(tmp_path / "images_2" / n, rng, 24, 16)
    ds = load_dataset(tmp_path, images_dir="images_2", test_every=0)
    assert_same_cameras(ds.train.cameras, [c.scaled(0.5) for c in cams])
    assert ds.train.names == ["images_2/a.png", "images_2/b.png"]


# ------------------------------------------------------------------------ Blender
def test_classic_nerf_synthetic_layout(tmp_path):
    """transforms_{train,val,test}.json with "./train/r_0" paths (no extension), RGBA
    images, camera_angle_x only, as the NeRF synthetic scenes ship."""
    rng = np.random.default_rng(2)
    cams = orbit_cameras(5, 20, 20)
    splits = {"train": [0, 1, 2], "val": [3], "test": [4]}
    pixels = {}
    for split, ids in splits.items():
        frames = []
        for k, i in enumerate(ids):
            frame, angle = cams[i].to_blender()
            frames.append({"file_path": f"./{split}/r_{k}", "rotation": 0.012566, "transform_matrix":
                           frame["transform_matrix"]})
            pixels[i] = write_image(tmp_path / split / f"r_{k}.png", rng, 20, 20, channels=4)
        (tmp_path / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": angle, "frames": frames}))
    ds = load_dataset(tmp_path, background=(1.0, 1.0, 1.0))
    assert ds.layout == "blender" and ds.points is None
    assert ds.train.names == ["train/r_0.png", "train/r_1.png", "train/r_2.png"]
    assert ds.test.names == ["test/r_0.png"]
    assert_same_cameras(ds.train.cameras, cams[:3])
    assert_same_cameras(ds.test.cameras, cams[4:])
    rgba = pixels[4].astype(np.float32) / 255
    np.testing.assert_allclose(ds.test.alphas[0], rgba[..., 3])
    np.testing.assert_allclose(ds.test.images[0], rgba[..., :3] * rgba[..., 3:] + (1 - rgba[..., 3:]), atol=1e-6)


def test_nerfstudio_transforms_json_with_shared_intrinsics_and_points(tmp_path):
    rng = np.random.default_rng(3)
    base = orbit_cameras(9)
    cams = [Camera(W, H, 30.0, 31.0, 11.0, 9.5, c.world_to_camera) for c in base]  # fy != fx, off-centre
    frames = []
    for i in (4, 0, 8, 1, 2, 3, 5, 6, 7):  # file order need not be sorted
        frames.append({"file_path": f"images/frame_{i + 1:05d}.png",
                       "transform_matrix": cams[i].to_blender()[0]["transform_matrix"]})
        write_image(tmp_path / "images" / f"frame_{i + 1:05d}.png", rng)
    from plyfile import PlyData, PlyElement

    vertex = np.array([(1.0, 2.0, 3.0, 10, 20, 30), (4.0, 5.0, 6.0, 40, 50, 60)],
                      dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    PlyData([PlyElement.describe(vertex, "vertex")]).write(str(tmp_path / "sparse_pc.ply"))
    meta = {"camera_model": "OPENCV", "fl_x": 30.0, "fl_y": 31.0, "cx": 11.0, "cy": 9.5, "w": W, "h": H,
            "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "ply_file_path": "sparse_pc.ply", "frames": frames}
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    ds = load_dataset(tmp_path)
    assert ds.test.names == ["images/frame_00001.png", "images/frame_00009.png"]  # sorted, every 8th
    assert_same_cameras(ds.test.cameras, [cams[0], cams[8]])
    assert_same_cameras(ds.train.cameras, cams[1:8])
    np.testing.assert_array_equal(ds.points.xyz, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(ds.points.rgb, [[10, 20, 30], [40, 50, 60]])
    meta["k4"] = 0.05  # distortion is undistorted on load (test_capture.py); a k4 under OPENCV is refused
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    one_line_error(lambda: load_dataset(tmp_path), "transforms.json: frames[0]: k4:", "OPENCV camera has no k4")


# ------------------------------------------------------------------------- errors
def test_missing_files_are_one_line_errors(tmp_path):
    one_line_error(lambda: load_dataset(tmp_path / "nowhere"), "dataset:", "nowhere")
    one_line_error(lambda: load_dataset(tmp_path), "dataset:", "neither a COLMAP model")
    cams = orbit_cameras(4)
    names = [f"{i:04d}.png" for i in range(4)]
    write_colmap(tmp_path / "c", cams, names)
    (tmp_path / "c" / "images" / "0002.png").unlink()
    one_line_error(lambda: load_dataset(tmp_path / "c"), "images/0002.png: missing", "sparse/0/images.bin")
    write_colmap(tmp_path / "d", cams, names)
    (tmp_path / "d" / "sparse" / "0" / "images.bin").unlink()
    one_line_error(lambda: load_dataset(tmp_path / "d"), "sparse/0/images.bin: missing")
    write_colmap(tmp_path / "e", cams, names)
    (tmp_path / "e" / "depth").mkdir()
    np.save(tmp_path / "e" / "depth" / "0000.npy", np.ones((H, W), np.float32))
    one_line_error(lambda: load_dataset(tmp_path / "e"), "depth/0001.npy: missing")
    np.save(tmp_path / "e" / "depth" / "0000.npy", np.ones((H + 1, W), np.float32))
    one_line_error(lambda: load_dataset(tmp_path / "e", test_every=0), "depth/0000.npy: depth shape [17, 24]")
    frame, angle = cams[0].to_blender()
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "transforms_train.json").write_text(json.dumps(
        {"camera_angle_x": angle, "frames": [{"file_path": "./train/r_0", **frame}]}))
    one_line_error(lambda: load_dataset(tmp_path / "b"), "transforms_train.json: frames[0]: file_path './train/r_0'",
                   "no such image")


def test_image_size_that_disagrees_with_its_camera(tmp_path):
    cams = orbit_cameras(3)
    names = ["a.png", "b.png", "c.png"]
    write_colmap(tmp_path / "c", cams, names)
    write_image(tmp_path / "c" / "images" / "b.png", np.random.default_rng(0), W - 4, H)
    one_line_error(lambda: load_dataset(tmp_path / "c"), "images/b.png: image size 20x16 disagrees with its camera 24x16")
    frame, angle = cams[0].to_blender()
    write_image(tmp_path / "b" / "r_0.png", np.random.default_rng(0))
    (tmp_path / "b" / "transforms.json").write_text(json.dumps(
        {"camera_angle_x": angle, "w": W + 1, "h": H, "frames": [{"file_path": "r_0.png", **frame}]}))
    one_line_error(lambda: load_dataset(tmp_path / "b"), "r_0.png: image size 24x16 disagrees with its camera 25x16")


def test_unknown_camera_models_are_rejected_by_name(tmp_path):
    # distorted models pycolmap undistorts load (test_capture.py); others are refused by name
    write_colmap(tmp_path / "c", orbit_cameras(2), ["a.png", "b.png"], model="FOV")
    one_line_error(lambda: load_dataset(tmp_path / "c"), "sparse/0/cameras.bin: camera 1:", "'FOV'",
                   "undistort")
    frame, angle = orbit_cameras(1)[0].to_blender()
    write_image(tmp_path / "b" / "r_0.png", np.random.default_rng(0))
    (tmp_path / "b" / "transforms.json").write_text(json.dumps(
        {"camera_model": "EQUIRECTANGULAR", "camera_angle_x": angle, "frames": [{"file_path": "r_0.png", **frame}]}))
    one_line_error(lambda: load_dataset(tmp_path / "b"), "camera_model:", "'EQUIRECTANGULAR'")


def test_argument_errors(tmp_path):
    write_colmap(tmp_path, orbit_cameras(2), ["a.png", "b.png"])
    one_line_error(lambda: load_dataset(tmp_path, layout="nerfies"), "layout:", "'nerfies'")
    one_line_error(lambda: load_dataset(tmp_path, layout="llff"), "poses_bounds.npy", "no such file")
    one_line_error(lambda: load_dataset(tmp_path, test_every=-1), "test_every:")
    one_line_error(lambda: load_dataset(tmp_path, background=(2, 0, 0)), "background:")
    one_line_error(lambda: load_dataset(tmp_path, layout="blender"), "transforms_train.json: missing")


def _loaded_as_before(arr: np.ndarray, bg: np.ndarray, downscale: int) -> tuple[np.ndarray, np.ndarray | None]:
    """What the loader returned before images were held as 8-bit (splatbench 9af4c7d,
    `_read_image` and `_resize`, written out here): float32 / 255, RGBA composited on
    ``bg`` at load; downscaled by quantising the composited float to 8 bits, PIL bicubic, / 255."""
    data = arr.astype(np.float32) / 255.0
    rgb, alpha = (data, None) if arr.shape[2] == 3 else \
        (data[..., :3] * data[..., 3][..., None] + bg * (1 - data[..., 3][..., None]), data[..., 3])
    if downscale == 1:
        return rgb, alpha

    def resize(image):
        u8 = np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)
        size = (image.shape[1] // downscale, image.shape[0] // downscale)
        return np.asarray(Image.fromarray(u8).resize(size, Image.Resampling.BICUBIC)).astype(np.float32) / 255.0

    return resize(rgb), None if alpha is None else resize(alpha)


def test_8bit_pixels_convert_to_the_same_floats_as_loading_them_as_float(tmp_path):
    """The loader holds 8-bit pixels and converts a view when it is read (Split.image):
    bit-identical to converting (and compositing, and downscaling) at load time as before,
    for RGBA (alpha 0, 255 and between), RGB PNG and JPEG, a split that mixes RGBA and RGB
    views, at downscale 1 and 2, on a background that is neither black nor white. The
    pixels are held as uint8 (a quarter of float32's memory)."""
    rng = np.random.default_rng(7)
    cams = orbit_cameras(6, 20, 20)
    kinds = {"train": [("png", 4), ("png", 4), ("png", 3)], "test": [("jpg", 3), ("png", 4), ("png", 4)]}
    arrays = {}
    for split, files in kinds.items():
        frames = []
        for k, (ext, channels) in enumerate(files):
            i = len(arrays)
            frame, angle = cams[i].to_blender()
            frames.append({"file_path": f"./{split}/r_{k}.{ext}", "transform_matrix": frame["transform_matrix"]})
            pixels = rng.integers(0, 256, (20, 20, channels), dtype=np.uint8)
            if channels == 4:
                pixels[:5, :, 3], pixels[5:10, :, 3] = 0, 255  # empty and opaque rows beside partial alpha
            path = tmp_path / split / f"r_{k}.{ext}"
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(pixels).save(path, **({"quality": 90} if ext == "jpg" else {}))
            arrays[(split, k)] = np.asarray(Image.open(path))  # what the file decodes to (JPEG is lossy)
        (tmp_path / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": angle, "frames": frames}))
    bg = np.array([0.3, 0.6, 0.9], np.float32)
    for downscale in (1, 2):
        ds = load_dataset(tmp_path, background=tuple(float(c) for c in bg), downscale=downscale)
        for name, split in (("train", ds.train), ("test", ds.test)):
            assert split.pixels.dtype == np.uint8 and split.alpha_pixels.dtype == np.uint8
            for k in range(3):
                want_rgb, want_alpha = _loaded_as_before(arrays[(name, k)], bg, downscale)
                assert split.image(k).dtype == np.float32
                assert split.image(k).tobytes() == want_rgb.tobytes(), (downscale, name, k)
                want_alpha = np.ones(want_rgb.shape[:2], np.float32) if want_alpha is None else want_alpha
                assert split.alpha(k).tobytes() == want_alpha.tobytes(), (downscale, name, k)
            assert split.images.tobytes() == np.stack([split.image(k) for k in range(3)]).tobytes()
    # an RGB-only dataset holds no alphas and composites nothing
    rgb_only = tmp_path / "rgb"
    (rgb_only / "train").mkdir(parents=True)
    frame, angle = cams[0].to_blender()
    pixels = write_image(rgb_only / "train" / "r_0.png", rng, 20, 20)
    (rgb_only / "transforms_train.json").write_text(json.dumps(
        {"camera_angle_x": angle, "frames": [{"file_path": "./train/r_0", "transform_matrix": frame["transform_matrix"]}]}))
    split = load_dataset(rgb_only).train
    assert split.alpha_pixels is None and split.composite is None and split.alpha(0) is None
    assert split.image(0).tobytes() == (pixels.astype(np.float32) / 255.0).tobytes()
