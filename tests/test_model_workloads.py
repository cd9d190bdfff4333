"""Workloads compare cannot be fooled by: synthetic scenes from a random camera pose, and real
trained models (the bundled PlayCanvas guitar and biker, MIT) framed from a few directions."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import reference
from splatbench.workloads import parse_model
from splatbench.errors import InputError
from splatbench.framing import DEFAULT_UP
from splatbench.ply import ViewHints, read_ply, write_ply
from splatbench.workloads import BUNDLED_MODELS, model_workload, synthetic


def _render(w, degree=None):
    g, c = w.gaussians, w.camera
    return reference.render(g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, c.K, c.world_to_camera,
                            c.width, c.height, sh_degree=degree)


def test_posed_synthetic_is_the_same_image_from_a_random_seeded_pose():
    plain, posed = synthetic(30, 24, 16, seed=5), synthetic(30, 24, 16, seed=5, random_pose=True)
    w2c = posed.camera.world_to_camera
    assert not np.allclose(w2c, np.eye(4)) and np.linalg.norm(reference.camera_centre(w2c)) > 0.1
    np.testing.assert_allclose(w2c[:3, :3] @ w2c[:3, :3].T, np.eye(3), atol=1e-12)   # a rigid pose
    assert np.array_equal(w2c, synthetic(30, 24, 16, seed=5, random_pose=True).camera.world_to_camera)  # seeded
    assert not np.allclose(w2c, synthetic(30, 24, 16, seed=6, random_pose=True).camera.world_to_camera)
    # the camera-space scene is the identity pose's: the same image without view-dependent colour,
    # up to `Gaussians` storing float32: world means |x| <~ 10 rounded to 2^-24 |x| ~ 6e-7 move a
    # Gaussian by ~6e-7 * f / z ~ 1e-5 px (f = 24, z >= 2), changing a pixel by at most that
    # times its largest slope (~1 per pixel here): 1e-5
    np.testing.assert_allclose(_render(posed, 0).rgb, _render(plain, 0).rgb, atol=1e-5)
    # ... while the SH bands see other world directions, as they should
    assert np.abs(_render(posed).rgb - _render(plain).rgb).max() > 1e-3


@pytest.fixture(scope="module")
def thin_guitar(tmp_path_factory):
    """Every 50th Gaussian of the bundled guitar, as a PLY (reading the full one takes seconds)."""
    arrays = read_ply(BUNDLED_MODELS["guitar"])
    path = tmp_path_factory.mktemp("models") / "thin_guitar.ply"
    write_ply(arrays._replace(**{k: v[::50] for k, v in arrays._asdict().items()}), path)
    return path


@pytest.mark.parametrize("name, count", [("guitar", 90_854), ("biker", 152_746)])
def test_bundled_models_are_intact(name, count):
    """The header's vertex count and 17 float32 properties (no SH bands above 0) fill the file exactly."""
    data = BUNDLED_MODELS[name].read_bytes()
    header, _, body = data.partition(b"end_header\n")
    lines = header.decode().splitlines()
    assert f"element vertex {count}" in lines and sum(line.startswith("property float ") for line in lines) == 17
    assert len(body) == count * 17 * 4


def test_model_views_frame_the_model(thin_guitar, tmp_path):
    views = [model_workload(thin_guitar, k, 3, 32, 32) for k in range(3)]
    assert [w.name for w in views] == ["thin_guitar-view0", "thin_guitar-view1", "thin_guitar-view2"]
    centres = [reference.camera_centre(w.camera.world_to_camera) for w in views]
    assert min(np.linalg.norm(a - b) for a, b in zip(centres, centres[1:] + centres[:1])) > 1.0  # three directions
    # 20 degrees above the horizontal, "above" along the default up (-y: the camera's y is smaller)
    lo, hi = np.percentile(views[0].gaussians.means, [1, 99], axis=0)
    offset = centres[0] - (lo + hi) / 2
    assert np.degrees(np.arcsin(offset @ np.array(DEFAULT_UP) / np.linalg.norm(offset))) == pytest.approx(20)
    # the framed model is in view (the thinned guitar still covers some pixels)
    assert all(_render(w).alpha.max() > 0.5 for w in views)
    # an up recorded in the PLY is used; an explicit up wins over it
    write_ply(read_ply(thin_guitar), tmp_path / "z_up.ply", ViewHints(up=(0.0, 0.0, 1.0)))
    recorded = model_workload(tmp_path / "z_up.ply", 0, 3, 32, 32)
    given = model_workload(tmp_path / "z_up.ply", 0, 3, 32, 32, up=DEFAULT_UP)
    up_of = lambda w: -w.camera.world_to_camera[1, :3]  # noqa: E731 - OpenCV: image y points down
    assert up_of(recorded) @ [0, 0, 1] > 0.9 and up_of(given) @ np.array(DEFAULT_UP) > 0.9


def test_parse_model_one_spec_per_view_and_bad_input(thin_guitar):
    assert [s.path for s in parse_model("biker")] == [str(BUNDLED_MODELS["biker"].resolve())] * 3  # by name
    specs = parse_model(str(thin_guitar), "+y", 2, "40x30")
    assert [(s.kind, s.view, s.views, s.width, s.height, s.up) for s in specs] == \
        [("model", 0, 2, 40, 30, (0.0, 1.0, 0.0)), ("model", 1, 2, 40, 30, (0.0, 1.0, 0.0))]
    assert specs[1].build().camera.width == 40
    with pytest.raises(InputError, match="--model: no such file 'nope.ply'"):
        parse_model("nope.ply")
    with pytest.raises(InputError, match="--up:"):
        parse_model("guitar", "sideways")
    with pytest.raises(InputError, match="--model-views: expected a count >= 1"):
        parse_model("guitar", None, 0)


def test_cli_up_without_model_is_one_line(tmp_path):
    from splatbench.cli import main

    out = CliRunner().invoke(main, ["compare", "--backend", "drjit", "--up", "+y", "--out", str(tmp_path)])
    assert out.exit_code == 2 and out.output.strip() == "splatbench: error: --up: applies to --model only"
