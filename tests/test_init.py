"""Initialisers: from_points, from_random, from_surface, from_sfm, and the SfM alignment maths."""

from __future__ import annotations

import json
import math
import shutil
import tomllib

import numpy as np
import pytest
from click.testing import CliRunner

import splatbench  # noqa: F401 - configures libLLVM before drjit loads
from splatbench import InputError
from splatbench.gaussians import SH_C0, quat_to_rotmat
from splatbench.gaussians_from_points import from_points, from_random, from_sfm, from_surface, knn_mean_sq_dist
from splatbench.scenes import builtin_scenes_dir, linear_to_srgb, render_dataset
from splatbench.sfm import Similarity, rig_radius, umeyama

#: A small calibrated capture of the `textured` scene that SfM can still solve: 12
#: training views 5 degrees apart (SIFT needs overlap), 160x160, 8 spp.
TINY_RIG = {"resolution": [160, 160], "spp": 8, "train_views": 12, "test_views": 1, "points": 2000,
            "azimuth_deg": [0.0, 60.0], "elevation_deg": [30.0, 40.0]}


def _dc_colour(g) -> np.ndarray:
    return SH_C0 * g.sh[:, 0, :].astype(np.float64) + 0.5


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """(dataset folder, scenes folder) of the tiny `textured` capture, rendered once per module."""
    root = tmp_path_factory.mktemp("init")
    scenes = root / "scenes"
    shutil.copytree(builtin_scenes_dir() / "textured", scenes / "tiny")
    rig = {**tomllib.loads((scenes / "tiny" / "rig.toml").read_text()), **TINY_RIG}
    (scenes / "tiny" / "rig.toml").write_text("".join(f"{k} = {json.dumps(v)}\n" for k, v in rig.items()))
    result = render_dataset("tiny", root / "tiny-160", extra_dirs=[scenes], progress=False)
    return result.path, scenes


# ----------------------------------------------------------------------- from_random
def test_from_random_is_uniform_in_the_box_and_seeded():
    lo, hi = np.array([-1.3, -0.5, 2.0]), np.array([1.3, 0.5, 4.0])
    g = from_random(lo, hi, 4000, seed=7, sh_degree=2)
    assert len(g) == 4000 and g.sh.shape == (4000, 9, 3) and not g.sh[:, 1:].any()
    assert np.all(g.means >= lo.astype(np.float32)) and np.all(g.means <= hi.astype(np.float32))
    # uniform: each axis's mean within 5 standard errors of the box centre
    se = (hi - lo) / math.sqrt(12 * 4000)
    assert np.all(np.abs(g.means.mean(0) - (lo + hi) / 2) < 5 * se)
    colours = _dc_colour(g)
    assert colours.min() >= -1e-6 and colours.max() <= 1 + 1e-6 and colours.std() > 0.2
    np.testing.assert_allclose(g.opacities, 0.1, rtol=1e-6)
    np.testing.assert_allclose(np.exp(2 * g.log_scales[:, 0]), np.maximum(knn_mean_sq_dist(g.means), 1e-7),
                               rtol=1e-4)
    same = from_random(lo, hi, 4000, seed=7, sh_degree=2)
    np.testing.assert_array_equal(same.means, g.means)
    np.testing.assert_array_equal(same.sh, g.sh)
    assert not np.array_equal(from_random(lo, hi, 4000, seed=8).means, g.means)


@pytest.mark.parametrize("args, match", [
    (([0, 0, 0], [1, 1, 0], 10), "bounds_min < bounds_max"),
    (([0, 0], [1, 1, 1], 10), "bounds_min"),
    (([0, 0, 0], [1, 1, 1], 1), "n: expected an int >= 2"),
    (([0, 0, 0], [1, np.nan, 1], 10), "bounds_max: non-finite"),
])
def test_from_random_errors(args, match):
    with pytest.raises(InputError, match=match):
        from_random(*args, seed=0)


# ---------------------------------------------------------------------- from_surface
def test_from_surface_albedo_on_a_known_scene():
    """Two diffuse quads of known reflectance: points on them, area-weighted, sRGB albedo colours."""
    from splatbench.mitsuba_loader import mitsuba

    mi = mitsuba()
    scene = mi.load_dict({
        "type": "scene",
        "big": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([2.0, 1.0, 1.0]),
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.25, 0.5, 0.75]}}},
        "small": {"type": "rectangle",
                  "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, 1.0]).scale([0.5, 1.0, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.9, 0.1, 0.1]}}},
    })
    g = from_surface(scene, 3000, seed=1, sh_degree=0)
    on_big = np.abs(g.means[:, 2]) < 1e-6
    on_small = np.abs(g.means[:, 2] - 1.0) < 1e-6
    assert np.all(on_big | on_small)
    assert np.all(np.abs(g.means[on_big, 0]) <= 2 + 1e-5) and np.all(np.abs(g.means[on_small, 0]) <= 0.5 + 1e-5)
    p_big = 4 / 5  # areas 8 and 2
    assert abs(on_big.mean() - p_big) < 5 * math.sqrt(p_big * (1 - p_big) / 3000)
    colours = _dc_colour(g)
    np.testing.assert_allclose(colours[on_big], np.broadcast_to(linear_to_srgb([0.25, 0.5, 0.75]), (on_big.sum(), 3)),
                               atol=1e-5)
    np.testing.assert_allclose(colours[on_small], np.broadcast_to(linear_to_srgb([0.9, 0.1, 0.1]),
                                                                  (on_small.sum(), 3)), atol=1e-5)
    np.testing.assert_array_equal(from_surface(scene, 3000, seed=1, sh_degree=0).means, g.means)


def test_from_surface_points_are_the_scene_samplers_points():
    """One surface sampler: `from_surface` and `splatbench.scenes.sample_surface` give the
    same points for a seed, also from separate loads (Mitsuba's shape order varies)."""
    from splatbench.scenes import get_scene, load_mitsuba_scene, sample_surface

    g = from_surface("textured", 1500, seed=4, sh_degree=0)
    pts = sample_surface(load_mitsuba_scene(get_scene("textured")), 1500, seed=4, albedo=True)
    np.testing.assert_array_equal(g.means, pts.xyz)
    # the colours are the same samples' albedo, sRGB-encoded (float32 SH round trip: 1e-5)
    np.testing.assert_allclose(_dc_colour(g), linear_to_srgb(pts.albedo), atol=1e-5)


def test_from_surface_of_a_dataset_takes_colours_from_the_views(tiny):
    from splatbench.data import load_dataset
    from splatbench.scenes import load_mitsuba_scene

    path, scenes = tiny
    g = from_surface(path, 3000, seed=2, extra_dirs=[scenes])
    # the same seed gives the same points whatever order Mitsuba's parallel loader lists the shapes in
    for _ in range(3):
        scene = load_mitsuba_scene(scenes / "tiny")
        np.testing.assert_array_equal(from_surface(scene, 3000, seed=2).means, g.means)
    albedo = from_surface(path, 3000, seed=2, colors="albedo", extra_dirs=[scenes])
    np.testing.assert_array_equal(albedo.means, g.means)
    # without extra_dirs the manifest's scene folder is found
    np.testing.assert_array_equal(from_surface(path, 3000, seed=2).means, g.means)
    # colours of points seen by the first training view are that view's pixels there
    ds = load_dataset(path)
    cam, depth = ds.train.cameras[0], ds.train.depths[0]
    uv, z = cam.project(g.means.astype(np.float64))
    inside = np.isfinite(uv).all(1) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
    col = np.floor(np.where(inside, uv[:, 0], 0)).astype(int)
    row = np.floor(np.where(inside, uv[:, 1], 0)).astype(int)
    d = depth[row, col].astype(np.float64)
    seen = inside & (np.abs(d - z) < 0.02 * z)
    assert seen.sum() > 300
    # on the true surfaces: none floats in front of what view 0 sees (but for the few that fall
    # within a pixel of a silhouette and pick up the farther surface's depth there)
    in_front = inside & (d > 0) & (z < 0.98 * d)
    assert in_front.sum() < 0.05 * (inside & (d > 0)).sum(), (in_front.sum(), (inside & (d > 0)).sum())
    colours = _dc_colour(g)
    # every image colour is some view's pixel: exactly a multiple of 1/255
    assert np.allclose(colours[seen] * 255, np.round(colours[seen] * 255), atol=1e-3)
    # lit appearance, not albedo: they differ (shading), but are correlated (texture)
    diff = np.abs(colours[seen] - _dc_colour(albedo)[seen]).mean()
    corr = np.corrcoef(colours[seen].ravel(), _dc_colour(albedo)[seen].ravel())[0, 1]
    assert diff > 0.02 and corr > 0.5, (diff, corr)


def test_from_surface_refuses_a_dataset_whose_scene_changed(tiny, tmp_path):
    path, scenes = tiny
    changed = tmp_path / "scenes"
    shutil.copytree(scenes / "tiny", changed / "tiny")
    (changed / "tiny" / "scene.xml").write_text((changed / "tiny" / "scene.xml").read_text() + "\n<!-- edit -->\n")
    with pytest.raises(InputError, match="changed since the dataset was rendered"):
        from_surface(path, 100, seed=0, extra_dirs=[changed])
    with pytest.raises(InputError, match="colors: expected one of"):
        from_surface(path, 100, seed=0, colors="paint", extra_dirs=[scenes])
    with pytest.raises(InputError, match="scene_or_dataset"):
        from_surface(42, 100, seed=0)


# --------------------------------------------------------------------------- SfM maths
def _random_similarity(rng) -> Similarity:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return Similarity(float(np.exp(rng.uniform(-2, 2))), quat_to_rotmat(q), rng.uniform(-10, 10, 3))


@pytest.mark.parametrize("seed", range(5))
def test_umeyama_recovers_a_similarity(seed):
    rng = np.random.default_rng(seed)
    truth = _random_similarity(rng)
    src = rng.normal(size=(20, 3)) * rng.uniform(0.1, 5)
    est = umeyama(src, truth.apply(src))
    assert abs(est.scale - truth.scale) <= 1e-9 * truth.scale
    np.testing.assert_allclose(est.rotation, truth.rotation, atol=1e-9)
    np.testing.assert_allclose(est.apply(src), truth.apply(src), atol=1e-9 * (1 + np.abs(truth.apply(src)).max()))
    assert np.linalg.det(est.rotation) > 0


def test_umeyama_with_noisy_cameras_on_an_orbit():
    """SfM-like input: orbit cameras in an arbitrary frame with noisy centres; RMSE ~ the noise."""
    from splatbench import Camera

    rng = np.random.default_rng(4)
    cams = []
    target = np.array([0.0, 0.3, 0.0])
    for k in range(24):
        az, el = 2 * math.pi * k / 24, math.radians(20 + 30 * (k % 3) / 2)
        eye = target + 4 * np.array([math.cos(el) * math.cos(az), math.sin(el), math.cos(el) * math.sin(az)])
        cams.append(Camera.look_at(eye, target, [0, 1, 0], 64, 64, 50))
    assert abs(rig_radius(cams) - 4.0) < 1e-9
    gt = np.stack([c.center for c in cams])
    to_model = _random_similarity(rng)  # the SfM model's arbitrary frame
    noise = 0.004
    est = to_model.apply(gt) + rng.normal(0, noise * to_model.scale, gt.shape)
    sim = umeyama(est, gt)
    rmse = math.sqrt(np.mean(np.sum((sim.apply(est) - gt) ** 2, axis=1)))
    assert 0.5 * noise * math.sqrt(3) < rmse < 1.5 * noise * math.sqrt(3)
    assert abs(sim.scale * to_model.scale - 1) < 0.01


def test_umeyama_and_rig_radius_errors():
    with pytest.raises(InputError, match="at least 3"):
        umeyama(np.zeros((2, 3)), np.zeros((2, 3)))
    line = np.outer(np.arange(5.0), [1, 2, 3])
    with pytest.raises(InputError, match="collinear"):
        umeyama(line, line)
    with pytest.raises(InputError, match="equal shape"):
        umeyama(np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(InputError, match="at least 2 cameras"):
        rig_radius([])


# ----------------------------------------------------------------------------- from_sfm
def test_from_sfm_registers_and_aligns_the_tiny_capture(tiny, tmp_path, monkeypatch):
    """>= 90 % registered, camera centres within 1 % of the rig radius, the model in the content
    cache (never in the dataset folder, which is the user's), deterministic."""
    import pycolmap

    from splatbench.cli import main
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    path, _ = tiny
    before = sorted(p.relative_to(path) for p in path.rglob("*"))
    result = from_sfm(path, seed=0)
    assert result.total == 12 and result.registered >= 0.9 * result.total
    assert result.center_rmse_rel <= 0.01, result
    assert result.model_path.is_relative_to(tmp_path / "cache" / "sfm"), result.model_path
    assert sorted(p.relative_to(path) for p in path.rglob("*")) == before  # nothing written into the capture
    rec = pycolmap.Reconstruction(str(result.model_path))
    assert rec.num_reg_images() == result.registered and rec.num_points3D() == len(result.gaussians)
    np.testing.assert_allclose(result.gaussians.means,
                               np.array([p.xyz for _, p in sorted(rec.points3D.items())]), atol=1e-5)
    # the model is in the true frame: its points, seen by the TRUE cameras, land near the keypoints
    # they were triangulated from. An alignment good to 1 % of the rig radius R moves a point at
    # depth z by about 0.01 R fx / z pixels; add 1 px of keypoint noise. A wrong scale or pose
    # misses by tens of pixels.
    ds = load_dataset(path)
    truth = dict(zip(ds.train.names, ds.train.cameras))
    errors, depths = [], []
    for _, point in sorted(rec.points3D.items()):
        for el in point.track.elements:
            image = rec.image(el.image_id)
            uv, z = truth[image.name].project(np.asarray(point.xyz)[None])
            errors.append(np.linalg.norm(uv[0] - image.points2D[el.point2D_idx].xy))
            depths.append(z[0])
    fx = ds.train.cameras[0].fx
    tolerance = 0.01 * result.rig_radius * fx / np.percentile(depths, 5) + 1.0
    assert np.median(errors) < tolerance, (np.median(errors), tolerance)
    np.testing.assert_allclose(result.gaussians.opacities, 0.1, rtol=1e-6)
    # the command reuses the cached run and prints the same numbers; run again into --out,
    # single-threaded with the same seed, it gives the same model
    out = CliRunner().invoke(main, ["sfm", str(path), "--seed", "0"])
    assert out.exit_code == 0, out.output
    assert f"registered: {result.registered}/12" in out.output and "of the rig radius" in out.output
    assert "SfM: reusing" in out.output and str(result.model_path) in out.output
    fresh = tmp_path / "fresh"
    out = CliRunner().invoke(main, ["sfm", str(path), "--seed", "0", "--out", str(fresh)])
    assert out.exit_code == 0, out.output
    assert f"registered: {result.registered}/12" in out.output
    refused = CliRunner().invoke(main, ["sfm", str(path), "--threads", "all"])
    assert refused.exit_code == 2 and "--threads all: give --out DIR" in refused.output, refused.output
    again = pycolmap.Reconstruction(str(fresh / "0"))
    np.testing.assert_array_equal(np.array([p.xyz for _, p in sorted(again.points3D.items())]),
                                  np.array([p.xyz for _, p in sorted(rec.points3D.items())]))


def test_from_points_is_unchanged():
    """The shared seeding rule (3-NN scales, opacity 0.1, DC colour) that every initialiser ends in."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]], dtype=np.float64)
    g = from_points(pts, np.full((4, 3), 255, np.uint8), sh_degree=0)
    np.testing.assert_allclose(_dc_colour(g), 1.0, atol=1e-6)
    np.testing.assert_allclose(np.exp(2 * g.log_scales[:, 0]), knn_mean_sq_dist(pts), rtol=1e-5)
