"""Camera: validation, projection, and the Mitsuba / COLMAP / Blender conventions.

Each converter is checked against the other tool's own ray or projection code where
it has one (Mitsuba's ``sample_ray``, pycolmap's ``img_from_cam``) and against
independent maths where it has not (NeRF's ``get_rays`` for Blender frames).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import splatbench  # noqa: F401 - sets DRJIT_LIBLLVM_PATH before mitsuba/drjit load
from splatbench.cameras import Camera
from tests.assertions import one_line_error

EPS32 = float(np.finfo(np.float32).eps)

# Round trips in float64: each conversion is a handful of float64 operations on
# values of order 1e3 px, so the reprojection error is ~1e-12 px; 1e-6 px is far
# below any convention slip (half a pixel, a flipped axis, a mirrored offset).
ROUND_TRIP_TOL_PX = 1e-6


def random_rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def random_camera(rng, square: bool = False, width: int = 97, height: int = 61) -> Camera:
    w2c = np.eye(4)
    w2c[:3, :3] = random_rotation(rng)
    w2c[:3, 3] = rng.normal(size=3) * 3
    fx = rng.uniform(40, 200)
    fy = fx if square else fx * rng.uniform(0.8, 1.25)
    cx, cy = width / 2 + rng.uniform(-10, 10), height / 2 + rng.uniform(-8, 8)  # off-centre
    return Camera(width, height, fx, fy, cx, cy, w2c, near=0.05, far=500.0)


def points_in_view(cam: Camera, rng, m: int = 200, margin: float = 0.0) -> np.ndarray:
    """World points that project inside the image (plus ``margin`` px), at depths 0.5..20."""
    u = rng.uniform(-margin, cam.width + margin, m)
    v = rng.uniform(-margin, cam.height + margin, m)
    z = rng.uniform(0.5, 20, m)
    cam_pts = np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], -1)
    return (cam_pts - cam.translation) @ cam.rotation  # Rᵀ(p - t), row-wise


def assert_same_pixels(a: Camera, b: Camera, pts: np.ndarray, tol: float) -> None:
    uv_a, z_a = a.project(pts)
    uv_b, z_b = b.project(pts)
    err = np.abs(uv_a - uv_b).max()
    assert err <= tol, f"max reprojection difference {err:.3g} px > {tol:.3g} px"
    np.testing.assert_allclose(z_a, z_b, rtol=0, atol=tol * 1e-2)



# ------------------------------------------------------------------- validation
GOOD = dict(width=64, height=48, fx=50.0, fy=50.0, cx=32.0, cy=24.0, world_to_camera=np.eye(4))


def _bad_w2c(kind: str) -> np.ndarray:
    m = np.eye(4)
    if kind == "scale":
        m[:3, :3] *= 1.001  # RᵀR - I = 2e-3 > 1e-5
    elif kind == "reflection":
        m[0, 0] = -1.0
    elif kind == "last_row":
        m[3, 0] = 0.5
    elif kind == "nan":
        m[1, 3] = np.nan
    return m


@pytest.mark.parametrize("field, value, parts", [
    ("width", 0, ["width:", "0"]),
    ("width", 64.0, ["width:", "64.0"]),
    ("height", True, ["height:", "True"]),
    ("height", -3, ["height:", "-3"]),
    ("fx", 0.0, ["fx:", "0.0"]),
    ("fy", -1.0, ["fy:", "-1.0"]),
    ("fx", math.nan, ["fx:", "nan"]),
    ("cx", math.inf, ["cx:", "inf"]),
    ("cy", "a", ["cy:", "'a'"]),
    ("world_to_camera", np.eye(3), ["world_to_camera:", "[4, 4]", "[3, 3]"]),
    ("world_to_camera", _bad_w2c("scale"), ["world_to_camera:", "orthonormal"]),
    ("world_to_camera", _bad_w2c("reflection"), ["world_to_camera:", "reflection"]),
    ("world_to_camera", _bad_w2c("last_row"), ["world_to_camera:", "last row"]),
    ("world_to_camera", _bad_w2c("nan"), ["world_to_camera:", "non-finite", "[1, 3]"]),
    ("near", 0.0, ["near:"]),
    ("far", 0.001, ["near, far:", "near=0.01", "far=0.001"]),
])
def test_validation_errors(field, value, parts):
    one_line_error(lambda: Camera(**{**GOOD, field: value}), *parts)


def test_orthonormality_tolerance():
    m = np.eye(4)
    m[:3, :3] *= 1 + 4e-6  # RᵀR - I = 8e-6 <= 1e-5: float32-rounded rotations must pass
    assert Camera(**{**GOOD, "world_to_camera": m}).width == 64
    m[:3, :3] *= 1 + 2e-6  # now 1.2e-5
    one_line_error(lambda: Camera(**{**GOOD, "world_to_camera": m}), "orthonormal")


def test_accepts_numpy_scalars_and_stores_plain_types():
    cam = Camera(**{**GOOD, "width": np.int64(64), "height": np.array(48), "fx": np.float32(50)})
    assert type(cam.width) is int and type(cam.height) is int and type(cam.fx) is float
    assert cam.world_to_camera.dtype == np.float64


# ------------------------------------------------------------------ properties
def test_properties_and_projection():
    rng = np.random.default_rng(0)
    cam = random_camera(rng)
    np.testing.assert_array_equal(cam.K, [[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])
    np.testing.assert_allclose(cam.camera_to_world @ cam.world_to_camera, np.eye(4), atol=1e-14)
    np.testing.assert_allclose(cam.world_to_camera @ np.append(cam.center, 1), [0, 0, 0, 1], atol=1e-14)
    np.testing.assert_array_equal(cam.rotation, cam.world_to_camera[:3, :3])
    np.testing.assert_array_equal(cam.translation, cam.world_to_camera[:3, 3])
    # a camera-space point (x, y, z) lands at (fx x/z + cx, fy y/z + cy)
    cam_pt = np.array([0.3, -0.2, 2.5])
    world = cam.rotation.T @ (cam_pt - cam.translation)
    uv, z = cam.project(world[None])
    np.testing.assert_allclose(uv[0], [cam.fx * 0.12 + cam.cx, cam.fy * -0.08 + cam.cy], rtol=1e-14)
    np.testing.assert_allclose(z, [2.5], rtol=1e-14)
    behind = cam.rotation.T @ (np.array([0.3, 0.2, -1.0]) - cam.translation)
    uv, z = cam.project(np.stack([behind, cam.center]))
    assert np.isnan(uv).all() and z[0] < 0 and abs(z[1]) < 1e-12
    one_line_error(lambda: cam.project(np.zeros((3, 2))), "points:", "[?, 3]")


def test_look_at_geometry():
    # OpenGL-style scene: camera on +z looking at the origin, world +y up.
    cam = Camera.look_at(eye=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0], width=80, height=60, fov_x_deg=90)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == pytest.approx((40, 40, 40, 30), rel=1e-15)
    np.testing.assert_allclose(cam.center, [0, 0, 5], atol=1e-15)
    uv, z = cam.project(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 0]]))
    np.testing.assert_allclose(uv[0], [40, 30], atol=1e-12)  # target at the principal point
    assert uv[1, 0] > 40 and uv[2, 1] < 30  # world +x to the right, world up is image up
    np.testing.assert_allclose(uv[3], [80, 30], atol=1e-12)  # fov_x 90° at distance 5: edge at x = 5
    np.testing.assert_allclose(z, 5, atol=1e-15)
    one_line_error(lambda: Camera.look_at([1, 2, 3], [1, 2, 3], [0, 1, 0], 8, 8, 60), "target:")
    one_line_error(lambda: Camera.look_at([0, 0, 0], [0, 2, 0], [0, 1, 0], 8, 8, 60), "up:", "parallel")
    one_line_error(lambda: Camera.look_at([0, 0, 0], [0, 0, 1], [0, 1, 0], 8, 8, 180), "fov_x_deg:")


def test_scaled_maps_pixel_corners_to_pixel_corners():
    rng = np.random.default_rng(1)
    cam = random_camera(rng, width=97, height=61)
    pts = points_in_view(cam, rng)
    for factor in (0.25, 0.5, 2.0, 0.3):
        small = cam.scaled(factor)
        assert (small.width, small.height) == (round(97 * factor), round(61 * factor))
        sx, sy = small.width / cam.width, small.height / cam.height
        uv, _ = cam.project(pts)
        uv_small, _ = small.project(pts)
        np.testing.assert_allclose(uv_small, uv * [sx, sy], rtol=1e-12, atol=1e-10)
    one_line_error(lambda: cam.scaled(0.001), "factor:")
    one_line_error(lambda: cam.scaled(-1), "factor:")


# ------------------------------------------------------------------ round trips
def test_round_trip_look_at_mitsuba_colmap_blender():
    rng = np.random.default_rng(2)
    start = Camera.look_at(eye=[1.5, -2.0, 0.7], target=[0.1, 0.3, -0.2], up=[0, 0, 1],
                           width=97, height=61, fov_x_deg=63.0, near=0.05, far=500.0)
    start = Camera(start.width, start.height, start.fx, start.fy, 40.3, 33.9,  # off-centre principal point
                   start.world_to_camera, start.near, start.far)
    pts = points_in_view(start, rng, margin=20)
    via_mitsuba = Camera.from_mitsuba(start.to_mitsuba())
    via_colmap = Camera.from_colmap(*via_mitsuba.to_colmap(), near=0.05, far=500.0)
    frame, angle = via_colmap.to_blender()
    via_blender = Camera.from_blender(frame, angle, via_colmap.width, via_colmap.height, near=0.05, far=500.0)
    for cam in (via_mitsuba, via_colmap, via_blender):
        assert_same_pixels(start, cam, pts, ROUND_TRIP_TOL_PX)
        assert (cam.width, cam.height) == (97, 61)
    assert (via_mitsuba.near, via_mitsuba.far) == (0.05, 500.0)


@pytest.mark.parametrize("seed", range(4))
def test_round_trip_random_cameras(seed):
    rng = np.random.default_rng(10 + seed)
    cam = random_camera(rng, square=seed % 2 == 0)
    pts = points_in_view(cam, rng, margin=30)
    assert_same_pixels(cam, Camera.from_colmap(*cam.to_colmap(), near=0.05, far=500.0), pts, ROUND_TRIP_TOL_PX)
    frame, angle = cam.to_blender()
    assert ("fl_x" in frame) == (cam.fx != cam.fy or cam.cx != cam.width / 2 or cam.cy != cam.height / 2)
    assert_same_pixels(cam, Camera.from_blender(frame, angle, cam.width, cam.height), pts, ROUND_TRIP_TOL_PX)
    if cam.fx == cam.fy:
        assert_same_pixels(cam, Camera.from_mitsuba(cam.to_mitsuba()), pts, ROUND_TRIP_TOL_PX)
    else:
        one_line_error(cam.to_mitsuba, "fx, fy:", "square pixels")


# ---------------------------------------------------------------------- Mitsuba
@pytest.fixture
def mitsuba_variant(request):
    import mitsuba as mi

    before = mi.variant()
    mi.set_variant(request.param)
    yield mi
    if before is not None:
        mi.set_variant(before)


def mitsuba_ray_miss_px(mi, sensor, cam: Camera, pixels) -> np.ndarray:
    """For each pixel (i, j): Mitsuba's ray at film position ((j+0.5)/W, (i+0.5)/H),
    followed to depth-independent points, reprojected with ``cam``; returns |uv - centre|."""
    miss = []
    for i, j in pixels:
        pos = mi.Point2f(float((j + 0.5) / cam.width), float((i + 0.5) / cam.height))
        ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
        o = np.asarray(ray.o, dtype=np.float64).reshape(3)
        d = np.asarray(ray.d, dtype=np.float64).reshape(3)
        uv, z = cam.project(np.stack([o + t * d for t in (0.5, 3.0, 40.0)]))
        assert np.all(z > 0)
        miss.append(np.abs(uv - [j + 0.5, i + 0.5]).max())
    return np.array(miss)


def mitsuba_tolerance_px(cam: Camera) -> float:
    # Mitsuba's single-precision variants build the ray in float32 from a float32
    # to_world and sample-to-camera transform: ~10 roundings of relative size
    # eps32/2 on a direction, i.e. an angle error ≲ 10·eps32, which moves the
    # reprojected point by fx·(1 + tan²θ)·angle ≲ 2·fx·10·eps32 inside the image.
    # 64·fx·eps32 (≈4e-4 px for fx = 60) keeps a margin of ~3 and is still far below
    # any convention slip (>= 0.5 px).
    return 64 * max(cam.fx, cam.fy) * EPS32


@pytest.mark.parametrize("mitsuba_variant", ["scalar_rgb"], indirect=True)
def test_mitsuba_rays_pass_through_projected_points(mitsuba_variant):
    mi = mitsuba_variant
    rng = np.random.default_rng(3)
    cam = random_camera(rng, square=True, width=64, height=48)
    # off-centre principal point in both axes, so a mirrored offset sign would show
    assert abs(cam.cx - 32) > 1 and abs(cam.cy - 24) > 1
    sensor = mi.load_dict(cam.to_mitsuba())
    pixels = [(0, 0), (0, 63), (47, 0), (47, 63), (24, 32)] + [tuple(p) for p in rng.integers(0, 48, (5, 2))]
    miss = mitsuba_ray_miss_px(mi, sensor, cam, pixels)
    assert miss.max() <= mitsuba_tolerance_px(cam), miss
    # Sanity of the check itself: the same rays miss a camera with a mirrored
    # principal-point offset or a 180°-rotated frame by many pixels.
    mirrored = Camera(cam.width, cam.height, cam.fx, cam.fy, cam.width - cam.cx, cam.height - cam.cy,
                      cam.world_to_camera, cam.near, cam.far)
    assert mitsuba_ray_miss_px(mi, sensor, mirrored, pixels).min() > 1.0
    flip = np.diag([-1.0, -1.0, 1.0, 1.0]) @ cam.world_to_camera
    flipped = Camera(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, flip, cam.near, cam.far)
    assert mitsuba_ray_miss_px(mi, sensor, flipped, pixels)[:4].min() > 1.0


@pytest.mark.parametrize("mitsuba_variant", ["scalar_rgb", "llvm_ad_rgb"], indirect=True)
def test_from_loaded_mitsuba_sensor(mitsuba_variant):
    mi = mitsuba_variant
    rng = np.random.default_rng(4)
    cam = random_camera(rng, square=True)
    sensor = mi.load_dict(cam.to_mitsuba())
    back = Camera.from_mitsuba(sensor)
    assert (back.width, back.height) == (cam.width, cam.height)
    # the loaded sensor holds float32: compare to float32 resolution (see mitsuba_tolerance_px)
    assert_same_pixels(cam, back, points_in_view(cam, rng), mitsuba_tolerance_px(cam))
    assert back.near == pytest.approx(cam.near, rel=EPS32) and back.far == pytest.approx(cam.far, rel=EPS32)


@pytest.mark.parametrize("mitsuba_variant", ["scalar_rgb"], indirect=True)
def test_from_mitsuba_dict_written_by_hand(mitsuba_variant):
    mi = mitsuba_variant
    # A scene author's sensor: Mitsuba's own look_at, fov on the y axis.
    d = {"type": "perspective", "fov": 40.0, "fov_axis": "y",
         "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
         "film": {"type": "hdrfilm", "width": 80, "height": 40}}
    from_dict, from_sensor = Camera.from_mitsuba(d), Camera.from_mitsuba(mi.load_dict(d))
    expected_f = 20 / math.tan(math.radians(20))
    assert from_dict.fx == pytest.approx(expected_f, rel=1e-6) and from_dict.fy == from_dict.fx
    rng = np.random.default_rng(5)
    assert_same_pixels(from_dict, from_sensor, points_in_view(from_dict, rng), mitsuba_tolerance_px(from_dict))
    # Mitsuba's look_at with up +y: world +y is image up, world +x is image right seen from +z
    uv, _ = from_dict.project(np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0]]))
    np.testing.assert_allclose(uv[0], [40, 20], atol=1e-4)
    assert uv[1, 1] < 20 and uv[2, 0] > 40
    one_line_error(lambda: Camera.from_mitsuba({**d, "type": "thinlens"}), "sensor.type:")
    one_line_error(lambda: Camera.from_mitsuba({**d, "fov_axis": "z"}), "fov_axis:")


# ----------------------------------------------------------------------- COLMAP
def test_colmap_projection_matches_pycolmap():
    import pycolmap

    rng = np.random.default_rng(6)
    for model in ("PINHOLE", "SIMPLE_PINHOLE"):
        rot, t = random_rotation(rng), rng.normal(size=3)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(rot), t)
        params = [150.0, 143.0, 51.2, 29.7] if model == "PINHOLE" else [150.0, 51.2, 29.7]
        camera = pycolmap.Camera(model=model, width=97, height=61, params=params)
        cam = Camera.from_colmap(camera, pose)
        pts = points_in_view(cam, rng, margin=10)
        theirs = camera.img_from_cam(pose * pts)  # pycolmap's own projection
        ours, _ = cam.project(pts)
        # both are a few float64 operations on ~1e2 px values: ~1e-13 px apart
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)
        out_camera, out_pose = cam.to_colmap()
        assert out_camera.model_name == "PINHOLE"
        np.testing.assert_allclose(out_camera.img_from_cam(out_pose * pts), ours, rtol=0, atol=1e-9)


def test_from_colmap_registered_image():
    import pycolmap

    rng = np.random.default_rng(7)
    rec = pycolmap.Reconstruction()
    camera = pycolmap.Camera(model="PINHOLE", width=97, height=61, params=[150.0, 143.0, 51.2, 29.7], camera_id=1)
    rec.add_camera_with_trivial_rig(camera)
    pose = pycolmap.Rigid3d(pycolmap.Rotation3d(random_rotation(rng)), rng.normal(size=3))
    rec.add_image_with_trivial_frame(pycolmap.Image(name="a.jpg", camera_id=1, image_id=1), pose)
    image = rec.images[1]
    cam = Camera.from_colmap(image.camera, image)
    np.testing.assert_allclose(cam.world_to_camera[:3], pose.matrix(), atol=1e-15)
    np.testing.assert_allclose(cam.center, image.projection_center(), atol=1e-12)


def test_from_colmap_rejects_distortion_models():
    import pycolmap

    camera = pycolmap.Camera(model="OPENCV", width=10, height=10, params=[5, 5, 5, 5, 0.1, 0, 0, 0])
    one_line_error(lambda: Camera.from_colmap(camera, pycolmap.Rigid3d()), "camera.model:", "OPENCV")
    one_line_error(lambda: Camera.from_colmap(
        pycolmap.Camera(model="PINHOLE", width=10, height=10, params=[5, 5, 5, 5]), "pose"), "image:")


# ---------------------------------------------------------------------- Blender
def nerf_get_rays(frame: dict, focal_x: float, focal_y: float, cx: float, cy: float, pixels):
    """NeRF's ``get_rays`` (OpenGL camera: x right, y up, looking down -z) at pixel
    centres ``(j + 0.5, i + 0.5)`` -- written from the NeRF convention, not splatbench."""
    c2w = np.asarray(frame["transform_matrix"], dtype=np.float64)
    out = []
    for i, j in pixels:
        d_cam = np.array([(j + 0.5 - cx) / focal_x, -(i + 0.5 - cy) / focal_y, -1.0])
        out.append((c2w[:3, 3], c2w[:3, :3] @ d_cam))
    return out


def test_blender_rays_pass_through_projected_points():
    rng = np.random.default_rng(8)
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = random_rotation(rng), rng.normal(size=3)
    frame, angle = {"transform_matrix": c2w.tolist()}, 0.6911112070083618  # NeRF-synthetic's lego
    cam = Camera.from_blender(frame, angle, 80, 60)
    f = 0.5 * 80 / math.tan(angle / 2)
    assert cam.fx == cam.fy == pytest.approx(f, rel=1e-15) and (cam.cx, cam.cy) == (40, 30)
    pixels = [(0, 0), (59, 79), (13, 61), (30, 40)]
    for (i, j), (o, d) in zip(pixels, nerf_get_rays(frame, f, f, 40, 30, pixels)):
        uv, z = cam.project(np.stack([o + t * d for t in (0.7, 9.0)]))
        np.testing.assert_allclose(uv, [[j + 0.5, i + 0.5]] * 2, rtol=0, atol=1e-9)
        assert np.all(z > 0)  # -z in OpenGL is +z (forward) in OpenCV


def test_blender_nerfstudio_intrinsics():
    rng = np.random.default_rng(9)
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = random_rotation(rng), rng.normal(size=3)
    frame = {"transform_matrix": c2w.tolist(), "fl_x": 70.0, "fl_y": 66.0, "cx": 37.5, "cy": 31.25}
    cam = Camera.from_blender(frame, None, 80, 60)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (70.0, 66.0, 37.5, 31.25)
    pixels = [(0, 0), (59, 79), (22, 10)]
    for (i, j), (o, d) in zip(pixels, nerf_get_rays(frame, 70.0, 66.0, 37.5, 31.25, pixels)):
        uv, _ = cam.project((o + 4.0 * d)[None])
        np.testing.assert_allclose(uv[0], [j + 0.5, i + 0.5], rtol=0, atol=1e-9)
    out, angle = cam.to_blender()
    assert out["fl_x"] == 70.0 and out["fl_y"] == 66.0 and out["cx"] == 37.5 and out["cy"] == 31.25
    one_line_error(lambda: Camera.from_blender({"transform_matrix": c2w.tolist()}, None, 80, 60), "camera_angle_x:")
    one_line_error(lambda: Camera.from_blender({}, 0.7, 80, 60), "frame:", "transform_matrix")
    scaled = c2w.copy()
    scaled[:3, :3] *= 2
    one_line_error(lambda: Camera.from_blender({"transform_matrix": scaled.tolist()}, 0.7, 80, 60),
                   "transform_matrix:", "orthonormal")


def test_a_cameras_array_is_read_only_after_construction():
    """A camera is checked once, at construction; writing into its matrix afterwards
    (which would bypass the checks: a NaN there rendered an empty image) raises."""
    given = np.eye(4)
    cam = Camera(64, 48, 50.0, 50.0, 32.0, 24.0, given)
    with pytest.raises(ValueError, match="read-only"):
        cam.world_to_camera[0, 3] = float("nan")
    given[0, 3] = 5.0  # the caller's array stays theirs: the camera holds a checked copy
    assert cam.world_to_camera[0, 3] == 0.0
    moved = cam.scaled(0.5)
    assert not moved.world_to_camera.flags.writeable
