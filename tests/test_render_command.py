"""`splatbench render` of a PLY: which way is up, and the background.

The model is asymmetric along y: a dim Gaussian at the origin and a bright one at
y = +1 (so the framing camera, centred between them, sees the bright one half the
extent away from the centre, far from the middle row). Up = +y must put it in the
upper half of the image, up = -y (COLMAP's y-down world, the default for a PLY that
records no up) in the lower half.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from splatbench.cli import main
from splatbench.framing import framing_camera
from splatbench.gaussians import SH_C0, Gaussians
from splatbench.ply import ViewHints

W, H = 48, 40


def bright_above(axis: int = 1) -> Gaussians:
    """A dim grey Gaussian at the origin and a bright white one at +1 along ``axis``."""
    means = np.zeros((2, 3))
    means[1, axis] = 1.0
    rgb = np.array([[[0.15, 0.15, 0.15]], [[1.0, 1.0, 1.0]]])
    return Gaussians(means=means, log_scales=np.full((2, 3), np.log(0.12)), quats=np.tile([1.0, 0, 0, 0], (2, 1)),
                     opacity_logits=np.full(2, 4.0), sh=(rgb - 0.5) / SH_C0)


def run(*args) -> tuple[int, str, np.ndarray | None]:
    res = CliRunner().invoke(main, ["render", *map(str, args)])
    image = None
    if res.exit_code == 0:
        path = res.stdout.strip().splitlines()[-1].split(": ", 1)[1]
        image = np.asarray(Image.open(path).convert("RGB")).astype(int)
    return res.exit_code, res.output, image


def bright_row(image: np.ndarray) -> float:
    """Mean row of the brightest pixels (the white Gaussian's centre)."""
    lum = image.sum(axis=2)
    rows, _ = np.nonzero(lum >= lum.max() - 3)
    return float(rows.mean())


@pytest.mark.parametrize("axis, up, upper", [(1, "+y", True), (1, "-y", False), (2, "+z", True), (2, "-z", False)])
def test_up_option_puts_the_bright_gaussian_above_or_below(tmp_path, axis, up, upper):
    bright_above(axis).to_ply(tmp_path / "m.ply")
    code, out, image = run(tmp_path / "m.ply", "--size", f"{W}x{H}", "--up", up, "--out", tmp_path / "m.png")
    assert code == 0, out
    row = bright_row(image)
    # the bright Gaussian's centre is a quarter of the framed width from the middle row:
    # well clear of it (more than 5 rows of 40) whichever half it is in
    assert (row < H / 2 - 5) if upper else (row > H / 2 + 5), (up, row)
    assert "note:" not in out  # --up given: nothing assumed


def test_recorded_up_and_background_are_used_and_options_override_them(tmp_path):
    grey = (0.5, 0.5, 0.5)
    bright_above(1).to_ply(tmp_path / "m.ply", ViewHints(up=(0.0, 1.0, 0.0), background=grey))
    code, out, image = run(tmp_path / "m.ply", "--size", f"{W}x{H}", "--out", tmp_path / "a.png")
    assert code == 0, out
    assert "note: up +y (recorded in the PLY)" in out
    assert "note: background [0.5, 0.5, 0.5] (recorded in the PLY)" in out
    assert bright_row(image) < H / 2 - 5
    # the corner is background only: linear 0.5 written as 8-bit round(0.5 * 255) (save_png
    # stores values as given; +-1 for the rounding of the far tails of the Gaussians)
    assert np.abs(image[0, 0] - 128).max() <= 1
    code, out, image = run(tmp_path / "m.ply", "--size", f"{W}x{H}", "--up", "-y", "--background", "0,0,1",
                           "--out", tmp_path / "b.png")
    assert code == 0, out
    assert bright_row(image) > H / 2 + 5 and image[0, 0].tolist() == [0, 0, 255]


def test_a_ply_without_hints_renders_as_before(tmp_path):
    """No comments, no options: the framing camera is the one the command always used
    (from -z, up = -y, level), the background black, and the image that of
    --up -y --elevation 0."""
    g = bright_above(1)
    g.to_ply(tmp_path / "m.ply")
    code, out, image = run(tmp_path / "m.ply", "--size", f"{W}x{H}", "--out", tmp_path / "a.png")
    assert code == 0 and "note: up -y (COLMAP's y-down world" in out
    assert bright_row(image) > H / 2 + 5 and image[0, 0].tolist() == [0, 0, 0]
    _, _, explicit = run(tmp_path / "m.ply", "--size", f"{W}x{H}", "--up", "-y", "--elevation", "0",
                         "--out", tmp_path / "b.png")
    assert np.array_equal(image, explicit)
    cam = framing_camera(g, W, H)  # the camera with no up recorded, written out
    from splatbench import Camera

    lo, hi = np.percentile(g.means, [1, 99], axis=0)
    centre = (lo + hi) / 2
    # the framed sphere fits the narrower field of view (since issue 21's trial: tall models were cropped)
    distance = max(float(np.linalg.norm(hi - lo)) / 2, 3 * 0.12) / (np.tan(np.radians(25)) * min(1, H / W)) * 1.2
    before = Camera.look_at(centre - [0.0, 0.0, distance], centre, [0.0, -1.0, 0.0], W, H, 50.0,
                            near=min(0.01, distance / 100))
    np.testing.assert_array_equal(cam.world_to_camera, before.world_to_camera)


@pytest.mark.parametrize("up", [(0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)])
def test_framing_camera_looks_down_by_the_elevation_with_up_up(up):
    """The view direction dips ``elevation`` below the horizontal plane of ``up``, and
    ``up`` points up in the image (against the camera's y axis, which points down)."""
    cam = framing_camera(bright_above(), W, H, up=up, elevation_deg=20.0)
    forward, down = cam.rotation[2], cam.rotation[1]
    assert forward @ np.array(up) == pytest.approx(-np.sin(np.radians(20.0)), abs=1e-12)
    assert down @ np.array(up) == pytest.approx(-np.cos(np.radians(20.0)), abs=1e-12)


@pytest.mark.parametrize("args, message", [
    (["--up", "up"], "--up: expected one of +x, -x, +y, -y, +z, -z or X,Y,Z"),
    (["--up", "0,0,0"], "--up: expected one of"),
    (["--background", "0.5,0.5"], "--background: expected R,G,B, 3 numbers in [0, 1], got '0.5,0.5'"),
    (["--background", "0,2,0"], "--background: expected R,G,B"),
    (["--elevation", "90"], "Invalid value for '--elevation': 90.0 is not in the range -89<=x<=89"),
    (["--size", "0x0"], "--size: expected WxH with W, H >= 1, got '0x0'"),   # not the camera's 'width: ...'
    (["--size", "64x-1"], "--size: expected WxH with W, H >= 1, got '64x-1'"),
    (["--size", "64"], "--size: expected WxH, got '64'"),
])
def test_bad_up_or_background_is_one_line(tmp_path, args, message):
    bright_above().to_ply(tmp_path / "m.ply")
    code, out, _ = run(tmp_path / "m.ply", *args)
    assert code == 2 and len(out.strip().splitlines()) == 1 and out.startswith(f"splatbench: error: {message}"), out


def test_camera_option_renders_from_a_datasets_test_view(tmp_path):
    """--camera DATASET:VIEW uses that test camera at its size: a Gaussian placed on its
    optical axis lands on the principal point (the image centre)."""
    from splatbench.data import load_dataset
    from splatbench.scenes.render import render_dataset

    folder = render_dataset("diffuse", tmp_path / "d", resolution=16, views=16, spp=1, progress=False).path
    cam = load_dataset(folder).test.cameras[1]  # views 0 and 8 are the test views
    point = cam.center + 2.0 * cam.rotation[2]  # 2 units along the optical axis
    g = bright_above()
    g = Gaussians(means=np.stack([point, point + 100.0]), log_scales=g.log_scales, quats=g.quats,
                  opacity_logits=g.opacity_logits, sh=g.sh[::-1].copy())  # the bright one on the axis
    g.to_ply(tmp_path / "m.ply")
    code, out, image = run(tmp_path / "m.ply", "--camera", f"{folder}:1", "--out", tmp_path / "c.png")
    assert code == 0, out
    assert image.shape == (16, 16, 3) and "note: up" not in out
    lum = image.sum(axis=2)
    assert lum[7:9, 7:9].min() == lum.max() > 600  # the 2x2 pixels around the centre (cx = cy = 8)
    # --downscale sizes the dataset's camera as training at that downscale saw it: half the size,
    # the axis still on the centre (cx = cy = 4)
    code, out, image = run(tmp_path / "m.ply", "--camera", f"{folder}:1", "--downscale", 2, "--out", tmp_path / "h.png")
    assert code == 0 and image.shape == (8, 8, 3) and "at downscale 2 (8x8)" in out, out
    lum = image.sum(axis=2)
    assert lum[3:5, 3:5].min() == lum.max()
    code, out, _ = run(tmp_path / "m.ply", "--camera", f"{folder}:1", "--size", "100x100")  # the dataset sizes it
    assert code == 2 and out.startswith("splatbench: error: --size: does not apply with --camera"), out
    code, out, _ = run(tmp_path / "m.ply", "--downscale", 2)
    assert code == 2 and out.startswith("splatbench: error: --downscale: only with --camera"), out
    for view in ("2", "x", "-1", ""):   # out of range, not a number, negative, empty: VIEW named, not DATASET
        code, out, _ = run(tmp_path / "m.ply", "--camera", f"{folder}:{view}")
        assert code == 2 and out.strip() == (f"splatbench: error: --camera: view {view!r} is not a view index "
                                             f"(0..1) of {folder}; give DATASET:VIEW"), out
    code, out, _ = run(tmp_path / "m.ply", "--camera", f"{tmp_path / 'none'}:1")   # a missing folder is the dataset's
    assert code == 2 and out.startswith(f"splatbench: error: dataset: {str(tmp_path / 'none')!r} is not a dataset")
    code, out, _ = run(tmp_path / "m.ply", "--camera", str(folder), "--up", "+y")
    assert code == 2 and "--up: does not apply with --camera" in out


def test_framing_rig_circles_the_up_axis_at_one_elevation():
    """Each rig camera looks at the same centre from the same distance and elevation; their
    horizontal directions are evenly spaced (azimuth 360/n apart) about the up axis."""
    from splatbench.framing import framing_rig
    g = bright_above()
    up = np.array([0.0, 0.0, 1.0])
    rig = framing_rig(g, 4, W, H, up=up, elevation_deg=30.0)
    eyes = np.array([np.linalg.inv(c.world_to_camera)[:3, 3] for c in rig])
    axes = np.array([c.world_to_camera[2, :3] for c in rig])  # camera +z (viewing direction) in world
    dist = np.linalg.norm(eyes - eyes.mean(0), axis=1)
    assert np.allclose(dist, dist[0], rtol=1e-9)
    elev = np.degrees(np.arcsin(-(axes @ up)))  # looking down by the elevation
    assert np.allclose(elev, 30.0, atol=1e-6)
    horiz = axes - (axes @ up)[:, None] * up
    horiz /= np.linalg.norm(horiz, axis=1)[:, None]
    cos = np.sum(horiz * np.roll(horiz, -1, axis=0), axis=1)
    assert np.allclose(cos, 0.0, atol=1e-9)  # 90 degrees apart for 4 views


def test_a_bundled_models_name_renders_it(tmp_path):
    """`splatbench render guitar` renders the bundled model, as `compare --model guitar` takes it."""
    code, out, image = run("guitar", "--size", "48x32", "--out", tmp_path / "g.png")
    assert code == 0, out
    assert image.shape == (32, 48, 3) and image.max() > 50  # something drawn, on the recorded/default background
