"""Real data: the Mip-NeRF 360 "garden" SfM points and cameras (tests/data/NOTICE.md).

Seeds Gaussians from the points as graphdeco-inria does, checks the cameras against
pycolmap's own projection, and renders one view with the reference oracle.
"""

from __future__ import annotations


import numpy as np
import pytest

import splatbench  # noqa: F401 - sets DRJIT_LIBLLVM_PATH first
from splatbench.workloads import GARDEN_SFM
from splatbench.cameras import Camera
from splatbench.gaussians import SH_C0
from splatbench.gaussians_from_points import from_points

EPS32 = float(np.finfo(np.float32).eps)
N_POINTS = 138766


@pytest.fixture(scope="module")
def garden():
    with np.load(GARDEN_SFM) as d:
        return {k: d[k] for k in d.files}


@pytest.fixture(scope="module")
def gaussians(garden):
    return from_points(garden["means3d"], garden["colors"])


def garden_camera(garden, i: int) -> Camera:
    K = garden["Ks"][i].astype(np.float64)
    return Camera(int(garden["width"]), int(garden["height"]), K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                  garden["viewmats"][i].astype(np.float64))


def test_data_is_as_documented(garden):
    assert garden["means3d"].shape == (N_POINTS, 3) and garden["means3d"].dtype == np.float32
    assert garden["colors"].shape == (N_POINTS, 3) and garden["colors"].dtype == np.uint8
    assert garden["viewmats"].shape == (3, 4, 4) and garden["Ks"].shape == (3, 3, 3)
    assert (int(garden["width"]), int(garden["height"])) == (648, 420)


def test_from_points_seeds_one_gaussian_per_point(garden, gaussians):
    g = gaussians
    assert len(g) == N_POINTS and g.sh_degree == 3
    np.testing.assert_array_equal(g.means, garden["means3d"])
    # The degree-0 colour C0·sh0 + 0.5 is the point colour: |sh0| <= 0.5/C0 ≈ 1.8 is
    # stored in float32 (error <= 2^-24·2), so the colour is off by at most C0·1.2e-7.
    colour = SH_C0 * g.sh[:, 0, :].astype(np.float64) + 0.5
    np.testing.assert_allclose(colour, garden["colors"] / 255.0, rtol=0, atol=SH_C0 * 2 * EPS32)
    np.testing.assert_array_equal(g.sh[:, 1:, :], 0)
    np.testing.assert_array_equal(g.quats, np.tile([1, 0, 0, 0], (N_POINTS, 1)))
    np.testing.assert_allclose(g.opacities, 0.1, rtol=4 * EPS32)
    np.testing.assert_array_equal(g.log_scales[:, 0], g.log_scales[:, 1])  # isotropic
    np.testing.assert_array_equal(g.log_scales[:, 0], g.log_scales[:, 2])


def test_scales_are_three_nn_distances_by_brute_force(garden, gaussians):
    pts = garden["means3d"].astype(np.float64)
    rng = np.random.default_rng(0)
    # a few random points plus some that have exact duplicates (the SfM cloud has 2323
    # duplicated positions; a duplicate is a neighbour at distance 0)
    _, first, counts = np.unique(garden["means3d"], axis=0, return_index=True, return_counts=True)
    picks = np.concatenate([rng.choice(N_POINTS, 12, replace=False), first[counts > 1][:4]])
    for n in picks:
        d2 = np.sum((pts - pts[n]) ** 2, axis=1)
        d2[n] = np.inf  # exclude the point itself, but not its duplicates
        mean_d2 = max(np.mean(np.sort(d2)[:3]), 1e-7)  # graphdeco clamps the mean squared distance
        expected = np.log(np.sqrt(mean_d2))
        # log_scales is float32: rounding error <= |log|·2^-24 (plus float64 noise)
        assert gaussians.log_scales[n, 0] == pytest.approx(expected, rel=EPS32, abs=EPS32)


@pytest.mark.parametrize("i", [0, 1, 2])
def test_cameras_project_like_pycolmap(garden, i):
    import pycolmap

    cam = garden_camera(garden, i)
    K, V = garden["Ks"][i].astype(np.float64), garden["viewmats"][i].astype(np.float64)
    # pycolmap built from the raw arrays, not from Camera.to_colmap
    camera = pycolmap.Camera(model="PINHOLE", width=648, height=420, params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    pose = pycolmap.Rigid3d(V[:3, :4])
    pts = garden["means3d"].astype(np.float64)
    ours, z = cam.project(pts)
    theirs = camera.img_from_cam(pose * pts, check_cheirality=False)
    in_view = (z > 0.1) & np.all((ours >= 0) & (ours <= [648, 420]), axis=1)
    assert in_view.sum() > 10_000
    # pycolmap stores the rotation as a unit quaternion, i.e. it re-orthonormalises the
    # float32-rounded viewmat: its R differs from ours by delta = ||R - R_colmap||_2 (~1e-8).
    # A camera point moves by <= delta·|p|, hence the pixel by <= delta·|p|·(f + |uv - c|)/z.
    delta = np.linalg.norm(V[:3, :3] - pose.rotation.matrix(), 2)
    centre = np.array([K[0, 2], K[1, 2]])
    bound = (delta * np.linalg.norm(pts, axis=1) * (max(K[0, 0], K[1, 1]) + np.abs(ours - centre).max(axis=1))
             / np.where(z > 0, z, np.inf)) * 1.01 + 1e-9  # 1e-9: float64 rounding of ~1e3 px values
    err = np.abs(ours - theirs).max(axis=1)
    assert np.all(err[in_view] <= bound[in_view]), (err[in_view] / bound[in_view]).max()
    assert err[in_view].max() < 1e-3  # the bound above evaluates to < 1e-3 px for this data


@pytest.fixture(scope="module")
def rendered(garden, gaussians):
    from splatbench.backends import reference_render

    cam = garden_camera(garden, 0).scaled(0.25)  # 162 x 105: the oracle is per pixel
    g = gaussians
    out = reference_render(None, g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, cam)
    return cam, out


def test_reference_render_of_garden(garden, gaussians, rendered):
    cam, out = rendered
    h, w = cam.height, cam.width
    assert (w, h) == (162, 105)
    assert out.rgb.shape == (h, w, 3) and out.alpha.shape == (h, w) and out.depth.shape == (h, w)
    assert np.all(np.isfinite(out.rgb)) and np.all(np.isfinite(out.alpha)) and np.all(np.isfinite(out.depth))
    assert np.all((out.alpha >= 0) & (out.alpha <= 1))
    # The first training view looks at the SfM cloud it came from: most pixels are
    # covered (about 98% reach alpha > 0.5 here; half is a loose floor).
    assert np.mean(out.alpha > 0.5) > 0.5

    # Depth is D/alpha with D = Σ T·α·z and alpha = Σ T·α: a convex combination of the
    # depths of the drawn Gaussians, so it lies within the range of their depths.
    _, z = cam.project(gaussians.means)
    drawn = np.asarray(out.visible) if hasattr(out, "visible") else (z >= cam.near)
    z_lo, z_hi = z[drawn].min(), z[drawn].max()
    covered = out.alpha > 0
    assert np.all(out.depth[covered] >= z_lo * (1 - 1e-9)) and np.all(out.depth[covered] <= z_hi * (1 + 1e-9))
    np.testing.assert_array_equal(out.depth[~covered], 0)

    # Colour: black background, so rgb/alpha is a convex combination of the drawn
    # Gaussians' colours, which are the point colours (degree-0 SH, higher bands 0).
    colours = garden["colors"][drawn] / 255.0
    ratio = out.rgb[covered] / out.alpha[covered][:, None]
    tol = 1e-6  # float32 SH storage (see above) plus float64 compositing
    assert np.all(ratio >= colours.min(axis=0) - tol) and np.all(ratio <= colours.max(axis=0) + tol)


# ------------------------------------------------------- from_points on small inputs
def test_from_points_small_cloud_closed_form():
    # Unit-square corners plus its centre: the centre's 3 nearest neighbours are corners
    # at distance sqrt(0.5); each corner's are the centre (sqrt(0.5)) and two corners (1).
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 0]])
    g = from_points(pts, np.full((5, 3), 0.25), sh_degree=0, opacity=0.5)
    corner = np.log(np.sqrt((0.5 + 1 + 1) / 3))
    centre = np.log(np.sqrt(0.5))
    np.testing.assert_allclose(g.log_scales, [[corner] * 3] * 4 + [[centre] * 3], rtol=2 * EPS32)
    assert g.sh.shape == (5, 1, 3) and np.all(g.opacity_logits == 0)
    np.testing.assert_allclose(SH_C0 * g.sh[:, 0] + 0.5, 0.25, rtol=2 * EPS32)


def test_from_points_duplicates_are_clamped_not_degenerate():
    pts = np.zeros((4, 3))  # four copies of one point: every neighbour at distance 0
    g = from_points(pts, np.zeros((4, 3), np.uint8))
    np.testing.assert_allclose(g.log_scales, np.log(np.sqrt(1e-7)), rtol=2 * EPS32)
    assert np.all(np.isfinite(g.log_scales))


@pytest.mark.parametrize("kwargs, parts", [
    (dict(points=np.zeros((3, 2)), colors=np.zeros((3, 3))), ["points:", "[M, 3]"]),
    (dict(points=np.zeros((3, 3)), colors=np.zeros((4, 3))), ["colors:", "M=3"]),
    (dict(points=np.zeros((3, 3)), colors=np.full((3, 3), 1.5)), ["colors:", "[0, 1]", "1.5"]),
    (dict(points=np.zeros((3, 3)), colors=np.zeros((3, 3), np.int32)), ["colors:", "uint8", "int32"]),
    (dict(points=np.zeros((3, 3)), colors=np.zeros((3, 3)), opacity=1.0), ["opacity:", "(0, 1)"]),
    (dict(points=np.zeros((3, 3)), colors=np.zeros((3, 3)), sh_degree=4), ["sh_degree:", "4"]),
    (dict(points=np.zeros((1, 3)), colors=np.zeros((1, 3))), ["points:", "at least 2"]),
    (dict(points=np.full((3, 3), np.nan), colors=np.zeros((3, 3))), ["points:", "non-finite"]),
])
def test_from_points_errors(kwargs, parts):
    from splatbench.errors import InputError

    with pytest.raises(InputError) as info:
        from_points(kwargs.pop("points"), kwargs.pop("colors"), **kwargs)
    msg = str(info.value)
    assert "\n" not in msg and all(p in msg for p in parts), msg
