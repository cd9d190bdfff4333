"""init = "sfm" (issue 12 §2): pycolmap SfM on the training views only, aligned to the
dataset's frame, cached by content in ``<dataset>/sfm``, and one line when SfM cannot
register the dataset. The tiny `textured` capture (12 training views, 160 px) is the
one of tests/test_init.py: SfM solves it in a few seconds on one core."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import splatbench  # noqa: F401 - configures libLLVM before drjit loads
from splatbench.data import load_dataset
from splatbench.errors import InputError
from splatbench.fsutil import read_manifest
from splatbench.sfm import cached_sfm, sfm_cache_dir, sfm_inputs
from splatbench.train import TrainConfig, train
from splatbench.train.config import InitConfig, SHConfig, StrategyConfig
from splatbench.train.initializers import InitSettings, initialize
from tests.test_init import tiny  # noqa: F401 - the module-scoped tiny capture fixture

#: The folder older versions wrote the model into, inside the dataset folder (never again).
OLD_SFM_DIR = "sfm"
SETTINGS = InitSettings(sh_degree=0, opacity=0.1, random_points=10, seed=0)


@pytest.fixture
def capture(tiny, tmp_path, monkeypatch):  # noqa: F811
    """A private copy of the tiny capture, with a private cache root (where SfM runs are kept)."""
    path, _ = tiny
    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    return shutil.copytree(path, tmp_path / "tiny", ignore=shutil.ignore_patterns(OLD_SFM_DIR))


def cache_of(capture, poses: str = "known") -> Path:
    """The cache folder of the capture's SfM run (init="sfm"'s known poses by default), as it is now."""
    return sfm_cache_dir(sfm_inputs(load_dataset(capture), poses=poses))


def untouched(capture) -> bool:
    """Nothing written into the user's dataset folder (no sfm/, no hidden temporary folder)."""
    return not (capture / OLD_SFM_DIR).exists() and not list(capture.glob(".*"))


def test_sfm_init_sees_training_views_only_and_starts_from_the_aligned_points(capture):
    ds = load_dataset(capture)
    assert len(ds.test) >= 1
    init = initialize("sfm", ds, SETTINGS)
    s = init.summary
    assert s["method"] == "sfm" and s["cached"] is False
    assert s["total"] == len(ds.train) == 12 and s["registered"] >= 0.9 * s["total"]
    # the alignment is good to 1 % of the rig radius (the bound of test_from_sfm_registers...)
    assert s["center_rmse_rel"] <= 0.01
    assert untouched(capture)
    manifest = read_manifest(cache_of(capture))
    assert sorted(manifest["inputs"]["views"]) == sorted(ds.train.names)        # the inputs: training views
    assert not set(manifest["registered_names"]) & set(ds.test.names)          # no test view was seen
    with np.load(cache_of(capture) / "points.npz") as pts:
        assert s["points"] == len(init.gaussians) == len(pts["xyz"]) >= 2
        np.testing.assert_array_equal(init.gaussians.means, pts["xyz"].astype(np.float32))
        # SH DC from the SfM colours: C0 sh0 + 0.5 = rgb / 255 (float32 rounding of the DC)
        rgb = 0.28209479177387814 * init.gaussians.sh[:, 0].astype(np.float64) + 0.5
        np.testing.assert_allclose(rgb, pts["rgb"] / 255.0, atol=1e-6)
    assert s["poses"] == "known" and s["center_rmse_rel"] < 1e-6  # the dataset's poses, held fixed
    assert init.note.startswith(f"SfM: {s['points']} points triangulated with the dataset's poses, seen by "
                                f"{s['registered']}/12 training views")


def test_sfm_is_reused_while_the_training_views_are_unchanged_and_rerun_when_one_changes(capture, monkeypatch):
    ds = load_dataset(capture)
    first, cached = cached_sfm(ds)
    assert not cached
    before = sfm_inputs(ds)["hash"]
    calls = []
    import splatbench.sfm as sfm_module

    real = sfm_module._sfm_into  # where pycolmap runs (run_sfm and cached_sfm alike)
    monkeypatch.setattr(sfm_module, "_sfm_into", lambda *a, **k: calls.append(1) or real(*a, **k))
    again, cached = cached_sfm(ds)
    assert cached and calls == []
    assert again.xyz.tobytes() == first.xyz.tobytes() and again.registered == first.registered
    # a test view is not an input: editing it keeps the cache
    test_image = capture / ds.test.names[0]
    Image.new("RGB", Image.open(test_image).size, (7, 7, 7)).save(test_image)
    assert cached_sfm(load_dataset(capture))[1] and calls == []
    # a training view is: editing one reruns SfM (deterministic: the same model when restored)
    train_image = capture / ds.train.names[0]
    original = train_image.read_bytes()
    img = np.array(Image.open(train_image))
    img[0, 0, 0] ^= 1
    Image.fromarray(img).save(train_image)
    assert sfm_inputs(load_dataset(capture))["hash"] != before
    _, cached = cached_sfm(load_dataset(capture))
    assert not cached and calls == [1]
    train_image.write_bytes(original)
    restored, cached = cached_sfm(load_dataset(capture))  # each version of the inputs keeps its own folder
    assert cached and restored.xyz.tobytes() == first.xyz.tobytes() and calls == [1]
    shutil.rmtree(cache_of(capture, "estimated"))  # rerun from scratch: SfM is deterministic, the same model
    rerun, cached = cached_sfm(load_dataset(capture))
    assert not cached and rerun.xyz.tobytes() == first.xyz.tobytes()


def test_train_with_sfm_init_logs_points_and_registered_views(capture, tmp_path):
    cfg = TrainConfig(dataset=str(capture), out=str(tmp_path / "run"), iterations=2, schedule="absolute", init=InitConfig(method="sfm"), strategy=StrategyConfig(name="none"), sh=SHConfig(degree=0))
    result = train(cfg)
    assert result.init["method"] == "sfm" and result.init["points"] == result.num_gaussians
    note = next(n for n in result.notes if n.startswith("SfM: "))
    assert f"{result.init['points']} points triangulated with the dataset's poses, seen by " \
        f"{result.init['registered']}/12 training views" in note
    saved = json.loads((tmp_path / "run" / "result.json").read_text())
    assert saved["init"]["registered"] == result.init["registered"] and note in saved["notes"]


def test_a_dataset_sfm_cannot_register_is_one_line(capture, tmp_path, capfd):
    """Flat grey training views give SIFT no features: no model, one line naming the way out."""
    ds = load_dataset(capture)
    for name in ds.train.names:
        Image.new("RGB", Image.open(capture / name).size, (128, 128, 128)).save(capture / name)
    cfg = TrainConfig(dataset=str(capture), out=str(tmp_path / "run"), iterations=2, schedule="absolute", init=InitConfig(method="sfm"), strategy=StrategyConfig(name="none"))
    with pytest.raises(InputError) as err:
        train(cfg)
    text = str(err.value)
    assert "\n" not in text and text.startswith("init: 'sfm' failed on") and "init=surface or init=random" in text
    cache = tmp_path / "cache" / "sfm"
    assert untouched(capture) and not (cache.exists() and any(cache.iterdir()))  # nothing (half-)written
    # and COLMAP's own error log (glog lines such as "E20261123 ... sfm.cc:310] ...") stays quiet
    assert not re.search(r"^[EWF]\d{8} ", capfd.readouterr().err, re.M)


def test_train_says_sfm_as_it_starts_and_ends_before_the_progress_bar(capture, tmp_path, monkeypatch):
    """SfM takes minutes on a real capture: one line before it starts (running, or reusing the
    cache) and its result note as soon as it ends, on stderr ahead of the bar, not only at the end."""
    from click.testing import CliRunner

    import splatbench.sfm as sfm_module
    from splatbench.cli import main

    events: list[str] = []
    real = sfm_module._sfm_into  # where pycolmap runs
    monkeypatch.setattr(sfm_module, "_sfm_into", lambda *a, **k: events.append("pycolmap") or real(*a, **k))
    cached_sfm(load_dataset(capture), poses="known", say=events.append)
    assert events == [f"SfM: running pycolmap (triangulating with the known poses) on 12 training views (cached "
                      f"in {cache_of(capture)})", "pycolmap"]

    res = CliRunner().invoke(main, ["train", str(capture), "--out", str(tmp_path / "run"), "--set", "iterations=2",
                                    "--set", "init='sfm'", "--set", "strategy='none'", "--set", "sh.degree=0",
                                    "--set", "schedule='absolute'"])
    assert res.exit_code == 0, res.output
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert lines[0] == f"SfM: reusing {cache_of(capture)}" and events[-1] == "pycolmap"  # not rerun
    assert untouched(capture)
    assert lines[1].startswith("SfM: ") and "training views" in lines[1] and "cached in" in lines[1]
    assert any("train" in line and "it" in line for line in lines[2:])  # the progress bar comes after
    assert lines[1] not in res.stdout  # said once, as it happened, not again among the final notes


def test_known_poses_keep_the_cameras_and_triangulate_points_onto_their_features(capture):
    """init="sfm" with the dataset's poses (COLMAP's point triangulator): the model's cameras
    are the dataset's to rounding, and every point, seen by the TRUE cameras, lands on the
    keypoints it was triangulated from. COLMAP keeps a point only when its reprojection error
    is under 4 px in every view (IncrementalTriangulatorOptions' default filter), and SIFT
    keypoints on a clean render are good to a fraction of a pixel, so the median is under 1 px;
    a wrong pose or intrinsics (e.g. the raw images with the undistorted camera) misses by more."""
    import pycolmap

    ds = load_dataset(capture)
    run, cached = cached_sfm(ds, poses="known")
    assert not cached and run.poses == "known" and run.models == 1 and len(run.xyz) >= 100
    assert run.total == 12 and run.registered == 12 and run.center_rmse < 1e-6 * run.rig_radius
    assert untouched(capture)
    rec = pycolmap.Reconstruction(str(run.model_path))
    truth = dict(zip(ds.train.names, ds.train.cameras))
    assert sorted(im.name for im in rec.images.values()) == sorted(ds.train.names)  # the dataset's names
    errors = []
    for _, point in sorted(rec.points3D.items()):
        for el in point.track.elements:
            image = rec.image(el.image_id)
            uv, z = truth[image.name].project(np.asarray(point.xyz)[None])
            assert z[0] > 0
            errors.append(np.linalg.norm(uv[0] - image.points2D[el.point2D_idx].xy))
    assert np.median(errors) < 1.0 and np.max(errors) < 4.0 + 1e-6, (np.median(errors), np.max(errors))
