"""Scene catalog, rigs, Mitsuba rendering into datasets, the cache, and the CLI.

Renders are tiny (32x32, 8 views, 4 spp) on a copy of the built-in ``diffuse`` scene
placed in a user scenes folder, so the suite also covers ``--scenes-dir``.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

import splatbench  # noqa: F401 - sets DRJIT_LIBLLVM_PATH before mitsuba/drjit load
from splatbench.cameras import Camera
from splatbench.data import load_dataset
from splatbench.mitsuba_loader import mitsuba
from splatbench.scenes import (RigSpec, builtin_scenes_dir, find_scenes, get_scene, linear_to_srgb,
                               load_mitsuba_scene, plan_render, read_manifest, render_dataset, render_depth,
                               render_rgb, sample_surface, srgb_to_linear)
from splatbench.scenes import render as render_module
from tests.assertions import one_line_error

BUILTIN = ("diffuse", "glossy", "textured", "thin", "occlusion", "far")
# Layout agreement: both layouts store float64 (COLMAP: quaternion + translation;
# Blender: JSON repr of the matrix), so poses agree to ~1e-15; 1e-6 is the bar.
POSE_TOL = 1e-6
TINY_RIG = {"resolution": [32, 32], "train_views": 6, "test_views": 2, "spp": 4, "points": 400}



def write_rig(path, **fields) -> None:
    def fmt(v):
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(fmt(x) for x in v) + "]"
        return repr(v)

    path.write_text("".join(f"{k} = {fmt(v)}\n" for k, v in fields.items()))


def rig_fields(name: str) -> dict:
    import tomllib

    return tomllib.loads((builtin_scenes_dir() / name / "rig.toml").read_text())


@pytest.fixture()
def user_scenes(tmp_path):
    """A user scenes folder with ``mini``: the built-in diffuse scene with a tiny rig."""
    root = tmp_path / "my_scenes"
    shutil.copytree(builtin_scenes_dir() / "diffuse", root / "mini")
    write_rig(root / "mini" / "rig.toml", **{**rig_fields("diffuse"), **TINY_RIG})
    return root


# ----------------------------------------------------------------------- catalog
def test_catalog_has_the_six_scenes_with_valid_rigs():
    scenes = find_scenes()
    assert set(BUILTIN) <= set(scenes)
    for name in BUILTIN:
        spec = scenes[name]
        rig = spec.rig
        assert spec.scene_file.is_file() and spec.rig_file.is_file() and rig.description
        cams = rig.cameras()
        assert len(cams) == rig.train_views + rig.test_views
        # the shipped rigs hold out every 8th view, so COLMAP's default split agrees
        assert rig.test_indices() == list(range(0, len(cams), 8))
        for cam in cams:  # every camera looks at the target
            uv, z = cam.project(np.array([rig.target]))
            np.testing.assert_allclose(uv[0], [cam.cx, cam.cy], atol=1e-9)
            assert (cam.width, cam.height) == rig.resolution


def test_builtin_scenes_load_in_mitsuba():
    for name in BUILTIN:
        scene = load_mitsuba_scene(name)
        assert len(scene.shapes()) >= 3, name
        assert len(scene.emitters()) >= 1, name


def test_scene_purposes_show_in_their_materials():
    """diffuse holds only Lambertian BSDFs; glossy has rough conductors and plastics;
    thin has wires of radius <= 1 cm; far has geometry >= 100 units from the origin."""
    import xml.etree.ElementTree as ET

    def bsdf_types(name):
        root = ET.parse(builtin_scenes_dir() / name / "scene.xml").getroot()
        return {b.get("type") for b in root.iter("bsdf")}

    assert bsdf_types("diffuse") == {"diffuse", "twosided"}
    assert {"roughconductor", "roughplastic"} <= bsdf_types("glossy")
    thin = ET.parse(builtin_scenes_dir() / "thin" / "scene.xml").getroot()
    radii = [float(f.get("value")) for s in thin.iter("shape") if s.get("type") == "cylinder"
             for f in s.iter("float") if f.get("name") == "radius"]
    assert sum(r <= 0.01 for r in radii) >= 8
    far = load_mitsuba_scene("far")
    extent = max(float(np.max(np.abs(np.array([s.bbox().min, s.bbox().max])))) for s in far.shapes())
    assert extent >= 100


def test_rig_kinds_place_cameras_as_documented():
    base = dict(radius=3.0, target=(1.0, 0.5, -2.0), train_views=28, test_views=4)
    for kind in ("orbit", "hemisphere"):
        rig = RigSpec(kind=kind, elevation_deg=(10.0, 50.0), **base)
        eyes = rig.eyes()
        d = eyes - np.array(rig.target)
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), 3.0, rtol=1e-12)
        elevation = np.degrees(np.arcsin(d[:, 1] / 3.0))
        assert elevation.min() >= 10 - 1e-9 and elevation.max() <= 50 + 1e-9
        np.testing.assert_array_equal(eyes, rig.eyes())  # deterministic
    forward = RigSpec(kind="forward", elevation_deg=(0.0, 0.0), azimuth_deg=(90.0, 90.0), spread=0.5, **base)
    eyes = forward.eyes()
    centre = np.array(base["target"]) + [0.0, 0.0, 3.0]  # azimuth 90 deg = +z for up = +y
    assert np.abs(eyes[:, 2] - centre[2]).max() < 1e-12  # the disc faces the target
    assert np.linalg.norm(eyes - centre, axis=1).max() <= 0.5 + 1e-12
    # --views V: every 8th view is a test view
    assert RigSpec(kind="orbit", radius=1.0).test_indices(20) == [0, 8, 16]
    assert RigSpec(kind="orbit", radius=1.0, train_views=100, test_views=200).test_indices()[:3] == [0, 1, 3]


@pytest.mark.parametrize("up", [(0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0), (1.0, 2.0, -0.5)])
def test_rig_up_is_recovered_exactly_from_the_cameras(up):
    """Every rig kind, any up: the direction perpendicular to every camera's x axis is the
    rig's up (float64 round-off: 1e-12); the built-in rigs give exactly +y."""
    from splatbench.scenes.orientation import rig_up

    base = dict(radius=3.0, target=(1.0, 0.5, -2.0), train_views=7, test_views=1, up=up)
    for rig in (RigSpec(kind="orbit", **base), RigSpec(kind="hemisphere", **base),
                RigSpec(kind="forward", spread=0.5, **base)):
        np.testing.assert_allclose(rig_up(rig.cameras()), np.array(up) / np.linalg.norm(up), atol=1e-12)
    for name in BUILTIN:
        assert rig_up(get_scene(name).rig.cameras()).tolist() == [0.0, 1.0, 0.0], name


def test_rig_up_of_views_along_one_azimuth_still_points_up():
    """Parallel x axes leave the up direction undetermined within a plane: the cameras'
    mean image-up is used, which is never upside down (positive along the true up)."""
    from splatbench.scenes.orientation import rig_up

    rig = RigSpec(kind="orbit", radius=3.0, azimuth_deg=(30.0, 30.0), elevation_deg=(10.0, 60.0))
    assert rig_up(rig.cameras()) @ np.array([0.0, 1.0, 0.0]) > 0.5
    assert rig_up(rig.cameras()[:1]) @ np.array([0.0, 1.0, 0.0]) > 0.5


@pytest.mark.parametrize("fields, part", [
    ({"kind": "spiral"}, "kind: expected one of orbit, hemisphere, forward"),
    ({"radius": -1.0}, "radius: expected a number > 0"),
    ({"elevation_deg": [40.0, 10.0]}, "elevation_deg:"),
    ({"elevation_deg": [10.0, 95.0]}, "elevation_deg:"),
    ({"train_views": 0}, "train_views: expected an int >= 1"),
    ({"resolution": [32]}, "resolution: expected [width, height]"),
    ({"near": 5.0, "far": 1.0}, "near, far:"),
    ({"fov_deg": 180.0}, "fov_deg:"),
    ({"up": [0.0, 0.0, 0.0]}, "up: expected a non-zero vector"),
    ({"kind": "forward"}, "spread: a forward rig needs spread > 0"),
    ({"frobnicate": 1}, "frobnicate: unknown key (known: "),
])
def test_rig_errors_are_one_line_naming_the_field(tmp_path, fields, part):
    path = tmp_path / "rig.toml"
    write_rig(path, **{"kind": "orbit", "radius": 2.0, **fields})
    one_line_error(lambda: RigSpec.from_toml(path), str(path), part)


def test_user_scene_folders_and_errors(tmp_path, user_scenes, monkeypatch):
    assert "mini" in find_scenes([user_scenes])
    monkeypatch.setenv("SPLATBENCH_SCENES", str(user_scenes))
    assert find_scenes()["mini"].folder == (user_scenes / "mini").resolve()
    # a user folder shadows a built-in scene of the same name
    shutil.copytree(user_scenes / "mini", user_scenes / "diffuse")
    assert find_scenes()["diffuse"].rig.resolution == (32, 32)
    assert get_scene(str(user_scenes / "mini")).name == "mini"  # a path works too
    one_line_error(lambda: get_scene("nope"), "scene: unknown name 'nope'", "diffuse")
    one_line_error(lambda: find_scenes([tmp_path / "missing"]), "--scenes-dir:")
    (user_scenes / "broken").mkdir()
    (user_scenes / "broken" / "scene.xml").write_text('<scene version="3.0.0"></scene>')
    one_line_error(lambda: find_scenes(), "broken/rig.toml: missing")
    (user_scenes / "broken" / "scene.xml").write_text('<scene version="0.6.0"></scene>')
    shutil.copy(user_scenes / "mini" / "rig.toml", user_scenes / "broken" / "rig.toml")
    one_line_error(lambda: find_scenes(), "Mitsuba 3", "0.6.0")
    (user_scenes / "broken" / "scene.xml").write_text('<scene version="3.0.0"><shape type="teapot"/></scene>')
    one_line_error(lambda: load_mitsuba_scene("broken", [user_scenes]), "scene.xml: Mitsuba cannot load it", "teapot")


# ----------------------------------------------------------------------- renderer
def test_srgb_transfer_function():
    x = np.array([0.0, 0.0031308, 0.18, 0.5, 1.0, 2.0, -1.0, np.nan])
    y = linear_to_srgb(x)
    np.testing.assert_allclose(y[[0, 4, 5, 6, 7]], [0.0, 1.0, 1.0, 0.0, 0.0])
    np.testing.assert_allclose(y[1], 12.92 * 0.0031308, rtol=1e-12)
    np.testing.assert_allclose(y[3], 1.055 * 0.5 ** (1 / 2.4) - 0.055, rtol=1e-12)  # 0.7354
    grid = np.linspace(0, 1, 101)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(grid)), grid, atol=1e-12)


def test_depth_is_camera_z_of_a_tilted_plane():
    """Mitsuba's depth AOV is a distance from the near plane along the ray; `render_depth`
    must return camera z at each pixel centre. A tilted plane n·X = n·p0 (camera frame)
    has z = (n·p0) / (n·((u-cx)/fx, (v-cy)/fy, 1)) exactly."""
    mi = mitsuba()
    w, h = 40, 30
    w2c = np.eye(4)
    w2c[:3, :3] = Camera.look_at([0, 0, 0], [0.3, -0.2, 1.0], [0, -1, 0], 4, 4, 60).rotation  # a non-trivial pose
    w2c[:3, 3] = [0.5, -1.0, 2.0]
    cam = Camera(w, h, 35.0, 35.0, w / 2, h / 2, w2c, near=0.05, far=100.0)
    n_cam = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])
    p0_cam = np.array([0.1, 0.05, 3.0])
    c2w = cam.camera_to_world
    n, p0 = c2w[:3, :3] @ n_cam, c2w[:3, :3] @ p0_cam + c2w[:3, 3]
    x = np.cross([0.0, 1.0, 0.0], n)
    x /= np.linalg.norm(x)
    to_world = np.eye(4)
    to_world[:3, 0], to_world[:3, 1], to_world[:3, 2], to_world[:3, 3] = 20 * x, 20 * np.cross(n, x), n, p0
    scene = mi.load_dict({"type": "scene", "plane": {"type": "rectangle", "to_world": mi.ScalarTransform4f(to_world)}})
    depth = render_depth(scene, cam)
    j, i = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    ray = np.stack([(j - cam.cx) / cam.fx, (i - cam.cy) / cam.fy, np.ones_like(j)], -1)
    expected = (n_cam @ p0_cam) / (ray @ n_cam)
    # float32 ray distances of ~3 units: a few ulps
    np.testing.assert_allclose(depth, expected, rtol=1e-5)
    assert expected.max() - expected.min() > 1.0  # the plane really is tilted
    # a miss is 0
    empty = mi.load_dict({"type": "scene", "s": {"type": "sphere", "center": [0, 0, -50], "radius": 0.1}})
    assert not render_depth(empty, cam).any()


def test_sample_surface_is_on_the_shapes_and_area_weighted():
    mi = mitsuba()
    scene = mi.load_dict({"type": "scene",
                          "ball": {"type": "sphere", "center": [1.0, 2.0, 3.0], "radius": 0.5},
                          "panel": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([2.0, 1.0, 1.0])}})
    pts = sample_surface(scene, 4000, seed=3)
    assert pts.xyz.shape == (4000, 3) and sorted(pts.shape_ids) == ["ball", "panel"]
    ball = pts.shape_index == pts.shape_ids.index("ball")
    np.testing.assert_allclose(np.linalg.norm(pts.xyz[ball] - [1, 2, 3], axis=1), 0.5, rtol=1e-5)
    assert np.abs(pts.xyz[~ball, 2]).max() < 1e-6 and np.abs(pts.xyz[~ball, 0]).max() <= 2 + 1e-6
    expected = math.pi / (math.pi + 8.0)  # sphere area pi, rectangle 4 x 2
    assert abs(ball.mean() - expected) < 4 * math.sqrt(expected * (1 - expected) / 4000)
    np.testing.assert_array_equal(sample_surface(scene, 4000, seed=3).xyz, pts.xyz)


# ------------------------------------------------------------------------ datasets
@pytest.fixture()
def rendered(tmp_path, user_scenes):
    out = tmp_path / "mini-32"
    result = render_dataset("mini", out, views=8, extra_dirs=[user_scenes], progress=False)
    return result, user_scenes


def test_render_writes_both_layouts_that_load_to_the_same_cameras(rendered):
    result, scenes_dir = rendered
    root = result.path
    assert not result.cached and (result.train, result.test) == (7, 1)
    for rel in ("images/0000.png", "images/0007.png", "depth/0007.npy", "transforms_train.json",
                "transforms_test.json", "sparse/0/cameras.bin", "sparse/0/images.bin", "sparse/0/points3D.bin",
                "points3D.ply", "split.json", "manifest.json"):
        assert (root / rel).is_file(), rel
    assert not [p for p in root.parent.iterdir() if p.name.startswith(".")]  # no temporary folders left
    colmap, blender = load_dataset(root, layout="colmap"), load_dataset(root, layout="blender")
    assert load_dataset(root).layout == "colmap"
    plan = plan_render("mini", views=8, extra_dirs=[scenes_dir])
    for split in ("train", "test"):
        a, b = getattr(colmap, split), getattr(blender, split)
        assert a.names == b.names
        assert len(a) == (7 if split == "train" else 1)
        np.testing.assert_array_equal(a.images, b.images)
        np.testing.assert_array_equal(a.depths, b.depths)
        assert a.images.shape[1:] == (32, 32, 3) and a.images.dtype == np.float32
        for ca, cb in zip(a.cameras, b.cameras):
            assert np.abs(ca.world_to_camera - cb.world_to_camera).max() <= POSE_TOL
            assert np.abs(ca.K - cb.K).max() <= POSE_TOL and (ca.width, ca.height) == (cb.width, cb.height)
    assert colmap.test.names == ["images/0000.png"]  # every 8th view
    for cam, truth in zip(colmap.test.cameras + colmap.train.cameras, [plan.cameras[0]] + plan.cameras[1:]):
        assert np.abs(cam.world_to_camera - truth.world_to_camera).max() <= POSE_TOL
    np.testing.assert_array_equal(colmap.points.xyz, blender.points.xyz)
    np.testing.assert_array_equal(colmap.points.rgb, blender.points.rgb)
    assert 0 < len(colmap.points) <= 400
    # images are well exposed (not black, not blown out)
    assert 0.2 < colmap.train.images.mean() < 0.8


def test_points_lie_on_the_surfaces_seen_by_training_views(rendered):
    """Each point3D projects to the pixel centre of its observation, at the depth stored there."""
    import pycolmap

    root = rendered[0].path
    rec = pycolmap.Reconstruction(str(root / "sparse" / "0"))
    ds = load_dataset(root)
    by_name = dict(zip(ds.train.names, range(len(ds.train))))
    checked = 0
    for point in rec.points3D.values():
        (element,) = point.track.elements
        image = rec.images[element.image_id]
        k = by_name[f"images/{image.name}"]  # a training view: test views never contribute
        uv, z = ds.train.cameras[k].project(point.xyz[None])
        np.testing.assert_allclose(uv[0], image.points2D[element.point2D_idx].xy, atol=1e-6)
        col, row = (uv[0] - 0.5).round().astype(int)
        assert abs(z[0] - ds.train.depths[k, row, col]) <= 1e-6 * z[0]
        np.testing.assert_array_equal(point.color, np.round(ds.train.images[k, row, col] * 255))
        checked += 1
    assert checked == len(ds.points)


def test_cache_skips_the_same_render_and_redoes_a_changed_one(rendered):
    result, scenes_dir = rendered
    again = render_dataset("mini", result.path, views=8, extra_dirs=[scenes_dir], progress=False)
    assert again.cached and again.hash == result.hash
    spp = render_dataset("mini", result.path, views=8, spp=2, extra_dirs=[scenes_dir], progress=False)
    assert not spp.cached and spp.hash != result.hash
    assert read_manifest(result.path)["settings"]["spp"] == 2
    rig = scenes_dir / "mini" / "rig.toml"
    rig.write_text(rig.read_text().replace("seed = 0", "seed = 1"))
    changed = render_dataset("mini", result.path, views=8, spp=2, extra_dirs=[scenes_dir], progress=False)
    assert not changed.cached and changed.hash != spp.hash
    assert changed.replaced == f"replaced {result.path}, which held a different render: seed 0 -> 1"
    (scenes_dir / "mini" / "notes.txt").write_text("a file of the scene folder")  # settings unchanged
    assert render_dataset("mini", result.path, views=8, spp=2, extra_dirs=[scenes_dir], progress=False).replaced == \
        f"replaced {result.path}, which held a different render: scene files changed: notes.txt"
    assert render_dataset("mini", result.path, views=8, spp=2, extra_dirs=[scenes_dir], progress=False).cached


def test_test_spp_renders_cleaner_test_views_and_leaves_training_views_alone(rendered, tmp_path):
    """``test_spp`` renders the held-out view (view 0) with more samples: its image
    changes and lies closer to a converged render, while every training view stays
    byte-identical to the plain ``spp`` dataset (same seeds, same spp)."""
    plain, scenes_dir = rendered  # the mini rig: 4 spp everywhere
    clean = render_dataset("mini", tmp_path / "clean", views=8, test_spp=64, extra_dirs=[scenes_dir], progress=False)
    assert not clean.cached and clean.hash != plain.hash
    assert read_manifest(clean.path)["settings"]["test_spp"] == 64
    a, b = load_dataset(plain.path), load_dataset(clean.path)
    np.testing.assert_array_equal(a.train.images, b.train.images)
    np.testing.assert_array_equal(a.points.xyz, b.points.xyz)  # points come from training views only
    assert not np.array_equal(a.test.images, b.test.images)
    # Against a 1024-spp render of the test view, quantised like the dataset: the per-pixel
    # Monte Carlo variance falls as 1/spp, so the expected MSE ratio is about 4/64 = 1/16
    # (plus the same small floor on both sides: the reference's own noise, 1/1024, and
    # 8-bit rounding, 1/(12*255^2)). Requiring only 1/4 leaves room for the estimate's
    # spread over 32x32x3 values and for clipping, which tames the noise of bright pixels.
    mi_scene = load_mitsuba_scene(get_scene("mini", [scenes_dir]))
    camera = plan_render("mini", views=8, extra_dirs=[scenes_dir]).cameras[0]
    ref = np.round(linear_to_srgb(render_rgb(mi_scene, camera, spp=1024, seed=99)) * 255) / 255
    mse_plain = float(((a.test.images[0] - ref) ** 2).mean())
    mse_clean = float(((b.test.images[0] - ref) ** 2).mean())
    assert mse_plain > 0 and mse_clean < mse_plain / 4, (mse_clean, mse_plain)


def test_test_spp_keeps_old_cache_keys_and_rejects_bad_values(rendered, tmp_path):
    """Datasets rendered before ``test_spp`` existed keep their key: the settings hashed
    are the old ones unless the test views really get another spp."""
    plain, scenes_dir = rendered
    old = plan_render("mini", views=8, extra_dirs=[scenes_dir])
    assert set(old.settings()) == {"resolution", "views", "test", "spp", "seed", "points"}
    assert old.hash() == plain.hash == read_manifest(plain.path)["hash"]
    same = plan_render("mini", views=8, test_spp=4, extra_dirs=[scenes_dir])  # the rig's spp: the same plan
    assert same.hash() == old.hash() and same.settings() == old.settings()
    assert render_dataset("mini", plain.path, views=8, test_spp=4, extra_dirs=[scenes_dir], progress=False).cached
    assert plan_render("mini", views=8, test_spp=5, extra_dirs=[scenes_dir]).hash() != old.hash()
    for bad in (0, -3, 2.5, True):
        one_line_error(lambda: render_dataset("mini", tmp_path / "bad", test_spp=bad, extra_dirs=[scenes_dir]),
                       "--test-spp: expected a positive int", repr(bad))
    assert not (tmp_path / "bad").exists()


def test_interrupted_render_leaves_no_dataset(tmp_path, user_scenes, monkeypatch):
    def boom(plan, folder, progress):
        (folder / "images").mkdir()
        (folder / "images" / "0000.png").write_bytes(b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(render_module, "_render_into", boom)
    out = tmp_path / "data" / "mini"
    with pytest.raises(KeyboardInterrupt):
        render_dataset("mini", out, extra_dirs=[user_scenes], progress=False)
    assert not out.exists() and list(out.parent.iterdir()) == []
    # a folder that is not a splatbench dataset is never replaced
    out.mkdir()
    (out / "precious.txt").write_text("keep")
    one_line_error(lambda: render_dataset("mini", out, extra_dirs=[user_scenes]), "--out:", "not a splatbench dataset")


def test_cli_list_and_render(tmp_path, user_scenes):
    from click.testing import CliRunner

    from splatbench.cli import main

    runner = CliRunner()
    listed = runner.invoke(main, ["scenes", "list", "--scenes-dir", str(user_scenes)])
    assert listed.exit_code == 0, listed.output
    assert all(name in listed.output for name in ("mini", *BUILTIN))
    out = tmp_path / "cli-out"
    args = ["scenes", "render", "mini", "--resolution", "16", "--views", "2", "--spp", "1", "--out", str(out),
            "--scenes-dir", str(user_scenes)]
    first = runner.invoke(main, args)
    assert first.exit_code == 0, first.output
    assert first.stdout.strip().splitlines()[-1].startswith(f"dataset: {out}")
    assert load_dataset(out).train.images.shape == (1, 16, 16, 3)
    second = runner.invoke(main, args)
    assert second.stdout.strip() == f"cached: {out}"
    bad = runner.invoke(main, ["scenes", "render", "mini", "--views", "0", "--scenes-dir", str(user_scenes)])
    assert bad.exit_code == 2 and bad.output.strip() == "splatbench: error: --views: expected a positive int, got 0"
    bad = runner.invoke(main, ["scenes", "render", "mini", "--test-spp", "0", "--scenes-dir", str(user_scenes)])
    assert bad.exit_code == 2 and bad.output.strip() == "splatbench: error: --test-spp: expected a positive int, got 0"
    clean = runner.invoke(main, ["scenes", "render", "mini", "--resolution", "16", "--views", "2", "--spp", "1",
                                 "--test-spp", "8", "--out", str(tmp_path / "cli-clean"), "--scenes-dir",
                                 str(user_scenes)])
    assert clean.exit_code == 0, clean.output
    assert read_manifest(tmp_path / "cli-clean")["settings"]["test_spp"] == 8


def test_sample_surface_is_deterministic_across_loads_with_a_normal_per_point():
    """Mitsuba loads shapes in parallel (their order varies between loads), and planar
    shapes report one constant normal: neither may leak into the samples."""
    first = sample_surface(load_mitsuba_scene(get_scene("textured")), 2000, seed=3)
    second = sample_surface(load_mitsuba_scene(get_scene("textured")), 2000, seed=3)
    np.testing.assert_array_equal(first.xyz, second.xyz)
    assert first.normals.shape == first.xyz.shape == (2000, 3)
    np.testing.assert_allclose(np.linalg.norm(first.normals, axis=1), 1.0, atol=1e-5)


# ----------------------------------------------------------------- dataset folders
def test_default_folder_names_the_settings_that_differ_from_the_rig():
    """The rig's own views and spp keep ``<name>-<W>``; any other views, spp or test_spp
    get the experiment runner's name (one function), so they never share a folder."""
    from splatbench.experiments.train_kind import dataset_folder
    from splatbench.scenes import dataset_name, default_out

    def out(**kw):
        return default_out(plan_render("glossy", **kw)).as_posix()

    assert out() == "data/scenes/glossy-256" and out(resolution=64) == "data/scenes/glossy-64"
    assert out(resolution=64, views=64, spp=128, test_spp=128) == "data/scenes/glossy-64"  # the rig's values
    names = {out(resolution=64, test_spp=256), out(resolution=64, test_spp=64), out(resolution=64, spp=32),
             out(resolution=64, views=16), out(resolution=64)}
    assert len(names) == 5
    assert out(resolution=64, test_spp=256) == "data/scenes/glossy-64-v64-s128-t256"
    data = {"resolution": 128, "views": 64, "spp": 64, "test_spp": 2048}
    assert out(**data) == "data/scenes/" + dataset_folder("glossy", data).name == \
        "data/scenes/" + dataset_name("glossy", 128, 64, 64, 2048)


def test_cli_renders_with_other_settings_into_other_folders_and_says_what_it_replaces(tmp_path, user_scenes,
                                                                                       monkeypatch):
    from click.testing import CliRunner

    from splatbench.cli import main

    monkeypatch.chdir(tmp_path)
    runner = CliRunner()

    def render(*args):
        res = runner.invoke(main, ["scenes", "render", "mini", "--scenes-dir", str(user_scenes), *args])
        assert res.exit_code == 0, res.output
        return res.stdout.strip().splitlines()

    # no --out: the rig's settings, then two test_spp values -- three folders, none replaced
    for args, folder in (((), "mini-32"), (("--test-spp", "8"), "mini-32-v8-s4-t8"),
                         (("--test-spp", "16"), "mini-32-v8-s4-t16")):
        lines = render(*args)
        assert len(lines) == 1 and lines[0].startswith(f"dataset: {Path('data/scenes') / folder} ("), lines
    assert read_manifest(tmp_path / "data/scenes/mini-32")["settings"].get("test_spp") is None
    assert read_manifest(tmp_path / "data/scenes/mini-32-v8-s4-t8")["settings"]["test_spp"] == 8
    assert read_manifest(tmp_path / "data/scenes/mini-32-v8-s4-t16")["settings"]["test_spp"] == 16
    # an explicit --out over another dataset replaces it and says what it held
    out = tmp_path / "mine"
    render("--test-spp", "8", "--out", str(out))
    lines = render("--test-spp", "16", "--out", str(out))
    assert lines[0] == f"replaced {out}, which held a different render: test_spp 8 -> 16"
    assert lines[1].startswith(f"dataset: {out} (")
    lines = render("--test-spp", "16", "--out", str(out), "--force")
    assert lines[0] == f"replaced {out}, which held the same render (--force)"
    lines = render("--spp", "2", "--out", str(out))
    assert lines[0] == f"replaced {out}, which held a different render: spp 4 -> 2; test_spp 16 -> 2"
