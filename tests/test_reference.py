"""Closed-form checks of the float64 NumPy oracle in `reference/`.

Each expected value below is derived by hand from docs/conventions.md, never from
splatbench. Unless a test says otherwise, tolerances are float64 round-off: the oracle
and the closed form evaluate the same few (< 50) float64 operations in a different
order, so they agree to a few hundred ulps: rtol = 1e-12 (ulp = 2.2e-16).
"""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

import reference
from reference import (composite, covariance, eval_sh, finite_difference_grad, project,
                       quat_to_rotmat, render)
from reference.sh import C0, C1, C2, C3

RTOL = 1e-12  # float64 round-off, see the module docstring
ATOL = 1e-15  # for values that are exactly 0 in the closed form

# A 32x24 camera at the origin looking down +z; a point on the optical axis lands on
# the centre of pixel (row 12, column 16), so its pixel offsets are whole numbers.
WIDTH, HEIGHT = 32, 24
F = 40.0
CX, CY = 16.5, 12.5
CAM_K = np.array([[F, 0.0, CX], [0.0, F, CY], [0.0, 0.0, 1.0]])
EYE = np.eye(4)
CENTRE = (12, 16)  # (row, column) of the pixel whose centre is (CX, CY)


def logit(o):
    return float(np.log(o / (1.0 - o)))


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def dc(colour):
    """sh [1, 1, 3] whose degree-0 colour is `colour` (each channel > 0)."""
    return ((np.asarray(colour, dtype=float) - 0.5) / C0).reshape(1, 1, 3)


def gaussians(positions, scales, opacities, colours):
    """Isotropic, unrotated Gaussians: (means, log_scales, quats, opacity_logits, sh)."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    n = len(positions)
    log_scales = np.repeat(np.log(np.asarray(scales, dtype=float)).reshape(n, 1), 3, axis=1)
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    logits = np.array([logit(o) for o in np.atleast_1d(opacities)])
    sh = np.concatenate([dc(c) for c in np.asarray(colours, dtype=float).reshape(n, 3)])
    return positions, log_scales, quats, logits, sh


def draw(params, **kwargs):
    kwargs = {"K": CAM_K, "world_to_camera": EYE, "width": WIDTH, "height": HEIGHT, **kwargs}
    return render(*params, **kwargs)


def pixel_offsets():
    """d² of every pixel centre from the centre (CX, CY): [H, W] (whole numbers)."""
    j, i = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)
    return (j - CX) ** 2 + (i - CY) ** 2


# ----------------------------------------------------------------------------
# Closed forms of one and two Gaussians
# ----------------------------------------------------------------------------

Z, SCALE, OPACITY, COLOUR = 2.0, 0.1, 0.7, (0.9, 0.6, 0.3)
SIGMA2 = (F * SCALE / Z) ** 2 + 0.3  # (fx·s/z)² + eps2d = 4.3 px²


@pytest.mark.parametrize("mode", ["matched", "exact"])
def test_single_isotropic_gaussian_matches_closed_form(mode):
    out = draw(gaussians([0, 0, Z], [SCALE], [OPACITY], [COLOUR]), mode=mode)
    d2 = pixel_offsets()
    a = OPACITY * np.exp(-d2 / (2 * SIGMA2))
    if mode == "matched":
        # Drawn inside the 3-sigma cutoff only. d² is a whole number and 9·σ² = 38.7,
        # so no pixel sits near the cutoff; alpha >= 0.7·exp(-38/8.6) = 0.0084 > 1/255.
        a = np.where(d2 <= 9 * SIGMA2, a, 0.0)
    np.testing.assert_allclose(out.alpha, a, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(out.rgb, a[..., None] * np.array(COLOUR), rtol=RTOL, atol=ATOL)
    assert out.rgb[CENTRE] == pytest.approx(OPACITY * np.array(COLOUR), rel=RTOL)
    assert out.rgb[12, 18, 0] == pytest.approx(OPACITY * np.exp(-4 / (2 * SIGMA2)) * 0.9, rel=RTOL)
    assert out.rgb[14, 19, 2] == pytest.approx(OPACITY * np.exp(-13 / (2 * SIGMA2)) * 0.3, rel=RTOL)
    # Pixel (12, 23) is at d² = 49 > 9σ²: cut off in matched mode only.
    assert (out.alpha[12, 23] == 0.0) == (mode == "matched")
    assert out.radii.tolist() == [int(np.ceil(3 * np.sqrt(SIGMA2)))]  # ceil(6.22) = 7


def test_two_overlapping_gaussians_front_one_attenuates_the_back_one():
    # Index 0 is the *back* Gaussian, so sorting by depth (not index) is exercised.
    z_back, z_front, o_back, o_front = 4.0, 2.0, 0.6, 0.5
    c_back, c_front = np.array([0.2, 0.9, 0.4]), np.array([0.8, 0.3, 0.6])
    params = gaussians([[0, 0, z_back], [0, 0, z_front]], [0.2, 0.1], [o_back, o_front],
                       [c_back, c_front])
    out = draw(params)
    # At the centre pixel both Gaussians have sigma = 0, so alpha = o.
    expected_rgb = o_front * c_front + (1 - o_front) * o_back * c_back
    expected_alpha = 1 - (1 - o_front) * (1 - o_back)
    expected_depth = (o_front * z_front + (1 - o_front) * o_back * z_back) / expected_alpha
    np.testing.assert_allclose(out.rgb[CENTRE], expected_rgb, rtol=RTOL)
    assert out.alpha[CENTRE] == pytest.approx(expected_alpha, rel=RTOL)
    assert out.depth[CENTRE] == pytest.approx(expected_depth, rel=RTOL)


def _stack(n, opacities, depths, colours):
    """Inputs of `composite` for n Gaussians centred on pixel CENTRE, wide (σ² = 100)."""
    return dict(means2d=np.tile([CX, CY], (n, 1)), conics=np.tile([0.01, 0.0, 0.01], (n, 1)),
                opacities=np.asarray(opacities, float), colors=np.asarray(colours, float),
                depths=np.asarray(depths, float), cutoff_sq=np.full(n, 9.0),
                visible=np.ones(n, bool), width=WIDTH, height=HEIGHT)


def test_equal_depths_are_composited_in_index_order():
    red, green = [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]
    out = composite(**_stack(2, [0.5, 0.8], [3.0, 3.0], [red, green]))
    np.testing.assert_allclose(out.rgb[CENTRE], [0.5, 0.5 * 0.8, 0.0], rtol=RTOL)


@pytest.mark.parametrize("mode, expected", [("matched", 0.99), ("exact", 0.999)])
def test_alpha_max_clamp(mode, expected):
    out = composite(**_stack(1, [0.999], [1.0], [[1.0, 0.5, 0.25]]), mode=mode)
    np.testing.assert_allclose(out.rgb[CENTRE], expected * np.array([1.0, 0.5, 0.25]), rtol=RTOL)
    assert out.alpha[CENTRE] == pytest.approx(expected, rel=RTOL)


def test_alpha_min_skip_is_strict():
    # alpha = o·exp(0) = o exactly at the centre pixel.
    below = composite(**_stack(1, [0.9 / 255], [1.0], [[1.0, 1.0, 1.0]]), background=(0.1, 0.2, 0.3))
    assert below.alpha[CENTRE] == 0.0
    np.testing.assert_array_equal(below.rgb[CENTRE], [0.1, 0.2, 0.3])  # untouched background
    exact = composite(**_stack(1, [0.9 / 255], [1.0], [[1.0, 1.0, 1.0]]), mode="exact")
    assert exact.alpha[CENTRE] == pytest.approx(0.9 / 255, rel=RTOL)
    # alpha == alpha_min is kept: the rule is "skip if alpha < alpha_min".
    at = composite(**_stack(1, [1 / 255], [1.0], [[1.0, 1.0, 1.0]]))
    assert at.rgb[CENTRE][0] == 1 / 255  # T·alpha·c = 1·(1/255)·1, exact


def test_early_stop_drops_the_gaussian_and_everything_behind_it():
    r, g, b, w = np.eye(3)[0], np.eye(3)[1], np.eye(3)[2], np.ones(3)
    # T: 1 -> 0.01 -> 0.01·0.02 = 2e-4 (kept) -> 2e-4·0.1 = 2e-5 < 1e-4: stop without the
    # third. The fourth (alpha 0.05) would give T = 1.9e-4 >= 1e-4 if the rule were "skip".
    out = composite(**_stack(4, [0.99, 0.98, 0.9, 0.05], [1.0, 2.0, 3.0, 4.0], [r, g, b, w]),
                    background=(0.0, 0.0, 0.5))
    T_final = 0.01 * 0.02
    np.testing.assert_allclose(out.rgb[CENTRE], 0.99 * r + 0.01 * 0.98 * g + T_final * np.array([0, 0, 0.5]),
                               rtol=RTOL, atol=ATOL)
    assert out.alpha[CENTRE] == pytest.approx(1 - T_final, rel=RTOL)
    # Exact mode has no early stop: all four contribute.
    exact = composite(**_stack(4, [0.99, 0.98, 0.9, 0.05], [1.0, 2.0, 3.0, 4.0], [r, g, b, w]), mode="exact")
    assert exact.rgb[CENTRE][2] == pytest.approx(T_final * 0.9 + T_final * 0.1 * 0.05, rel=RTOL)


def test_early_stop_threshold_is_strict():
    # With powers of two everything is exact: T_next = 0.25 == transmittance_min is kept,
    # the next one (T_next = 0.125) stops.
    out = composite(**_stack(3, [0.5, 0.5, 0.5], [1.0, 2.0, 3.0], np.eye(3)), transmittance_min=0.25)
    np.testing.assert_array_equal(out.rgb[CENTRE], [0.5, 0.25, 0.0])
    assert out.alpha[CENTRE] == 0.75


def test_depth_of_one_opaque_gaussian_is_its_camera_z():
    z = 3.7
    out = draw(gaussians([0.05, -0.02, z], [0.2], [0.995], [COLOUR]))
    covered = out.alpha > 0
    assert covered.sum() > 20
    np.testing.assert_allclose(out.depth[covered], z, rtol=RTOL)
    assert np.all(out.depth[~covered] == 0.0)


def test_background_mixing():
    bg = np.array([0.2, 0.4, 0.6])
    params = gaussians([0, 0, Z], [SCALE], [OPACITY], [COLOUR])
    out = draw(params, background=bg)
    a = out.alpha[..., None]
    np.testing.assert_allclose(out.rgb, a * np.array(COLOUR) + (1 - a) * bg, rtol=RTOL)
    assert np.all(out.rgb[out.alpha == 0] == bg)
    empty = draw(tuple(p[:0] for p in params), background=bg)
    assert np.all(empty.rgb == bg) and np.all(empty.alpha == 0) and np.all(empty.depth == 0)


# ----------------------------------------------------------------------------
# Spherical harmonics
# ----------------------------------------------------------------------------

S3 = 1 / np.sqrt(3)
# Basis values worked out by hand from the polynomials in conventions.md.
BASIS = {
    (1.0, 0.0, 0.0): [C0, 0, 0, -C1, 0, 0, -C2[2], 0, C2[4], 0, 0, 0, 0, -C3[4], 0, C3[6]],
    (0.0, 1.0, 0.0): [C0, -C1, 0, 0, 0, 0, -C2[2], 0, -C2[4], -C3[0], 0, -C3[2], 0, 0, 0, 0],
    (0.0, 0.0, 1.0): [C0, 0, C1, 0, 0, 0, 2 * C2[2], 0, 0, 0, 0, 0, 2 * C3[3], 0, 0, 0],
    # x = y = z = s: xy = yz = xz = 1/3, y(3x²-y²) = 2s/3, xyz = s/3, z(2z²-3x²-3y²) = -4s/3.
    (S3, S3, S3): [C0, -C1 * S3, C1 * S3, -C1 * S3, C2[0] / 3, C2[1] / 3, 0, C2[3] / 3, 0,
                   C3[0] * 2 * S3 / 3, C3[1] * S3 / 3, C3[2] * 2 * S3 / 3, C3[3] * -4 * S3 / 3,
                   C3[4] * 2 * S3 / 3, 0, C3[6] * -2 * S3 / 3],
    # Two distinct non-zero components, so xy, yz and xz cannot stand in for each other.
    (0.6, 0.0, 0.8): [C0, 0, C1 * 0.8, -C1 * 0.6, 0, 0, C2[2] * 0.92, C2[3] * 0.48, C2[4] * 0.36,
                      0, 0, 0, C3[3] * 0.16, C3[4] * 1.32, C3[5] * 0.288, C3[6] * 0.216],
    (0.0, 0.6, 0.8): [C0, -C1 * 0.6, C1 * 0.8, 0, 0, C2[1] * 0.48, C2[2] * 0.92, 0, C2[4] * -0.36,
                      C3[0] * -0.216, 0, C3[2] * 1.32, C3[3] * 0.16, 0, C3[5] * -0.288, 0],
    (0.6, 0.8, 0.0): [C0, -C1 * 0.8, 0, -C1 * 0.6, C2[0] * 0.48, 0, -C2[2], 0, C2[4] * -0.28,
                      C3[0] * 0.352, 0, C3[2] * -0.8, 0, C3[4] * -0.6, 0, C3[6] * -0.936],
}


@pytest.mark.parametrize("direction", list(BASIS))
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_eval_sh_at_known_directions(direction, degree):
    rng = np.random.default_rng(degree)
    sh = rng.uniform(-0.3, 0.3, size=(1, 16, 3))  # small: the max(., 0) clamp stays inactive
    bases = (degree + 1) ** 2
    expected = np.array(BASIS[direction][:bases]) @ sh[0, :bases] + 0.5
    got = eval_sh(sh, np.array([direction]), degree)
    np.testing.assert_allclose(got[0], expected, rtol=RTOL, atol=ATOL)


def test_eval_sh_clamps_negative_colour_to_zero():
    sh = np.zeros((1, 1, 3))
    sh[0, 0] = [-10.0, 0.0, 10.0]
    np.testing.assert_allclose(eval_sh(sh, np.array([[0.0, 0.0, 1.0]]), 0)[0], [0.0, 0.5, 10 * C0 + 0.5])


def test_sh_degree_truncation_ignores_higher_bands():
    rng = np.random.default_rng(3)
    sh = rng.uniform(-0.3, 0.3, size=(1, 16, 3))
    d = np.array([[S3, S3, S3]])
    np.testing.assert_array_equal(eval_sh(sh, d, 1), eval_sh(sh[:, :4], d, 1))
    assert not np.allclose(eval_sh(sh, d, 1), eval_sh(sh, d, 3))
    # Through render: sh_degree=1 on 16 bases == all bands of the first 4.
    means, log_scales, quats, logits, _ = gaussians([0.1, 0.1, Z], [SCALE], [OPACITY], [COLOUR])
    low = draw((means, log_scales, quats, logits, sh), sh_degree=1)
    same = draw((means, log_scales, quats, logits, sh[:, :4]))
    np.testing.assert_array_equal(low.rgb, same.rgb)
    with pytest.raises(ValueError, match="sh_degree"):
        draw((means, log_scales, quats, logits, sh[:, :4]), sh_degree=2)
    with pytest.raises(ValueError, match="K"):
        draw((means, log_scales, quats, logits, sh[:, :5]))


def test_colour_direction_uses_the_camera_centre():
    # Camera rotated 90° about y (camera z = world x) and placed at world (-3, 0.2, 0).
    R = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    centre = np.array([-3.0, 0.2, 0.0])
    w2c = np.eye(4)
    w2c[:3, :3], w2c[:3, 3] = R, -R @ centre
    mean = np.array([0.0, 0.5, 0.4])
    sh = np.zeros((1, 4, 3))
    sh[0, 1:4, 0] = [0.2, -0.1, 0.3]  # degree-1 bands, red channel
    params = gaussians(mean, [0.3], [0.5], [COLOUR])[:4] + (sh,)
    out = draw(params, world_to_camera=w2c)
    x, y, z = (mean - centre) / np.linalg.norm(mean - centre)
    red = 0.5 - C1 * y * 0.2 + C1 * z * -0.1 - C1 * x * 0.3
    # The Gaussian lies at camera (x, y, z) = (-0.4, 0.3, 3): pixel (u, v) = (11.17, 16.5).
    proj = project(*params[:4], CAM_K, w2c, WIDTH, HEIGHT)
    np.testing.assert_allclose(proj.means2d[0], [F * -0.4 / 3 + CX, F * 0.3 / 3 + CY], rtol=RTOL)
    assert proj.depths[0] == pytest.approx(3.0, rel=RTOL)
    row, col = 16, 11  # the pixel centre (11.5, 16.5) nearest the mean
    assert out.rgb[row, col, 0] / out.alpha[row, col] == pytest.approx(red, rel=RTOL)


# ----------------------------------------------------------------------------
# 3D covariance and projection
# ----------------------------------------------------------------------------

def test_covariance_axis_aligned():
    s = np.array([0.5, 2.0, 3.0])
    cov = covariance(np.log(s)[None], [[1.0, 0, 0, 0]])
    np.testing.assert_allclose(cov[0], np.diag(s**2), rtol=RTOL, atol=ATOL)


@pytest.mark.parametrize("axis, rotation, swapped", [
    (3, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], [1, 0, 2]),  # 90° about z: x -> y, y -> -x
    (1, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], [0, 2, 1]),  # 90° about x: y -> z, z -> -y
])
def test_covariance_90_degree_rotation(axis, rotation, swapped):
    s = np.array([0.5, 2.0, 3.0])
    q = np.zeros(4)
    q[0] = q[axis] = np.sqrt(0.5)
    np.testing.assert_allclose(quat_to_rotmat(q[None])[0], rotation, atol=ATOL)
    cov = covariance(np.log(s)[None], 7.0 * q[None])  # the length of q does not matter
    np.testing.assert_allclose(cov[0], np.diag(s[swapped] ** 2), rtol=RTOL, atol=1e-14)


def test_quaternion_edge_cases():
    np.testing.assert_array_equal(quat_to_rotmat(np.zeros((1, 4)))[0], np.eye(3))
    big = quat_to_rotmat([[1e300, 0, 0, 1e300]])[0]  # |q|² overflows without the max rule
    np.testing.assert_allclose(big, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=ATOL)
    cov = covariance([[25.0, 0.0, 0.0]], [[1.0, 0, 0, 0]])  # clipped to exp(20)
    assert cov[0, 0, 0] == pytest.approx(np.exp(40.0), rel=RTOL)
    assert covariance([[25.0, 0, 0]], [[1.0, 0, 0, 0]], clip=False)[0, 0, 0] == pytest.approx(np.exp(50.0), rel=RTOL)


def test_projection_conic_of_isotropic_gaussian():
    proj = project(*gaussians([0, 0, Z], [SCALE], [OPACITY], [COLOUR])[:4], CAM_K, EYE, WIDTH, HEIGHT)
    np.testing.assert_allclose(proj.conics[0], [1 / SIGMA2, 0, 1 / SIGMA2], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(proj.means2d[0], [CX, CY], rtol=RTOL)
    assert proj.opacities[0] == pytest.approx(OPACITY, rel=RTOL)
    assert proj.cutoff_sq[0] == 9.0


def test_antialiased_opacity_compensation():
    params = gaussians([0, 0, Z], [SCALE], [OPACITY], [COLOUR])[:4]
    proj = project(*params, CAM_K, EYE, WIDTH, HEIGHT, antialiased=True)
    raw = (F * SCALE / Z) ** 2  # isotropic: sqrt(det raw / det) = raw / (raw + eps2d)
    assert proj.opacities[0] == pytest.approx(OPACITY * raw / (raw + 0.3), rel=RTOL)


@pytest.mark.parametrize("mode", ["matched", "exact"])
def test_jacobian_clamp(mode):
    # x/z = 1.5 beyond lim_x+ = (W - cx)/fx + 0.3·(W/2)/fx = 15.5/40 + 4.8/40 = 0.5075.
    # Isotropic: Σ2D_xx = (fx·s/z)²·(1 + (tx/z)²) + eps2d, Σ2D_yy = (fx·s/z)² + eps2d, xy = 0.
    s, z = 0.5, 1.0
    proj = project(*gaussians([1.5 * z, 0, z], [s], [OPACITY], [COLOUR])[:4], CAM_K, EYE, WIDTH, HEIGHT, mode=mode)
    lim = (WIDTH - CX) / F + 0.3 * (WIDTH / 2) / F
    slope = lim  # the clamp is part of the projection model: exact mode keeps it too
    xx = (F * s / z) ** 2 * (1 + slope**2) + 0.3
    yy = (F * s / z) ** 2 + 0.3
    assert proj.visible[0]
    np.testing.assert_allclose(proj.conics[0], [1 / xx, 0, 1 / yy], rtol=RTOL, atol=ATOL)
    assert proj.means2d[0, 0] == pytest.approx(F * 1.5 + CX, rel=RTOL)  # unclamped mean


def test_exact_mode_keeps_the_jacobian_clamp_so_far_off_screen_gaussians_do_not_smear():
    # A small Gaussian beside the eye: x/z = 50, mean2d x = 40·50 + 16.5 = 2016.5 px, far right
    # of the 32-px image. Unclamped, Σ2D_xx = (fx·s/z)²·(1 + 50²) = 16²·2501 (std 800 px) and its
    # tail would put alpha = 0.7·exp(-(2016.5 - 31.5)²/(2·Σ2D_xx)) ≈ 0.03 on the right edge;
    # with the clamp (slope 0.5075) std is 18 px and nothing reaches the image (exp(-6000)).
    s, z, x = 0.02, 0.05, 2.5
    params = gaussians([x, 0, z], [s], [OPACITY], [COLOUR])
    lim = (WIDTH - CX) / F + 0.3 * (WIDTH / 2) / F
    unclamped = OPACITY * np.exp(-((F * x / z + CX - 31.5) ** 2) / (2 * ((F * s / z) ** 2 * (1 + (x / z) ** 2) + 0.3)))
    clamped = OPACITY * np.exp(-((F * x / z + CX - 31.5) ** 2) / (2 * ((F * s / z) ** 2 * (1 + lim**2) + 0.3)))
    assert unclamped > 0.02 and clamped == 0.0  # the closed forms the test tells apart
    out = draw(params, mode="exact")
    assert out.alpha.max() == 0.0  # exp underflows to exactly 0 in float64


def test_culling():
    positions = [
        [0, 0, 2.0],      # 0 visible
        [0, 0, 0.005],    # 1 closer than near = 0.01 (culled in both modes: the planes are the camera's)
        [0, 0, -1.0],     # 2 behind the camera (culled in both modes)
        [0, 0, 200.0],    # 3 beyond far = 100 (culled in both modes)
        [-6.0, 0, 2.0],   # 4 u = -103.5, box about [-103.5 ± 7]: off-screen
        [-0.5, 0, 2.0],   # 5 u = 6.5: on screen
        [-0.92, 0, 2.0],  # 6 u = -1.9, centre off-screen but box about [-8.7, 4.9] overlaps
        [0, 0, 2.0],      # 7 log-scale 20: Σ2D_xx ~ 1e20 > (1e4·32)², too large
    ]
    scales = [SCALE] * 7 + [np.exp(20.0)]
    params = gaussians(positions, scales, [OPACITY] * 8, [COLOUR] * 8)[:4]
    matched = project(*params, CAM_K, EYE, WIDTH, HEIGHT, far=100.0)
    assert matched.visible.tolist() == [True, False, False, False, False, True, True, False]
    assert np.all((matched.radii == 0) == ~matched.visible)
    assert matched.radii.dtype == np.int32
    exact = project(*params, CAM_K, EYE, WIDTH, HEIGHT, far=100.0, mode="exact")
    assert exact.visible.tolist() == [True, False, False, False, True, True, True, True]
    assert np.all(np.isinf(exact.cutoff_sq))


def test_opacity_radius_culls_faint_gaussians():
    alpha_min = 1 / 255
    ops = [0.9 * alpha_min, 1.1 * alpha_min, 0.5]
    params = gaussians([[0, 0, Z]] * 3, [SCALE] * 3, ops, [COLOUR] * 3)[:4]
    proj = project(*params, CAM_K, EYE, WIDTH, HEIGHT, radius="opacity")
    assert proj.visible.tolist() == [False, True, True]
    # The logit -> sigmoid round trip moves o by a few ulps and ln(1.1) = 0.095 magnifies
    # that relative error 10x: still far inside RTOL.
    np.testing.assert_allclose(proj.cutoff_sq[1:], 2 * np.log(np.array(ops[1:]) / alpha_min), rtol=RTOL)
    # R = sqrt(2 ln(0.5·255)) = 3.11: radius ceil(3.11·sqrt(4.3)) = 7.
    assert proj.radii[2] == int(np.ceil(np.sqrt(2 * np.log(0.5 * 255)) * np.sqrt(SIGMA2)))
    # With the 3-sigma radius nothing is culled for low opacity.
    assert project(*params, CAM_K, EYE, WIDTH, HEIGHT).visible.all()


@pytest.mark.parametrize("field, index", [("means", [1, 2]), ("quats", [0, 3]), ("opacity_logits", [1])])
def test_non_finite_input_is_rejected_naming_field_and_index(field, index):
    params = dict(zip(["means", "log_scales", "quats", "opacity_logits", "sh"],
                      gaussians([[0, 0, 2], [0, 0, 3]], [0.1, 0.1], [0.5, 0.5], [COLOUR] * 2)))
    params[field][tuple(index)] = np.nan
    with pytest.raises(ValueError, match=re.escape(f"{field}: non-finite value nan at index {index}")):
        render(**params, K=CAM_K, world_to_camera=EYE, width=WIDTH, height=HEIGHT)


# ----------------------------------------------------------------------------
# Finite differences
# ----------------------------------------------------------------------------

# Central differences with step eps = 1e-6 err by about eps²·|f'''|/6 (truncation,
# <= 1e-10 for the smooth functions below, whose scale is ~0.1 in world units or
# O(1) in logits) plus ulp(f)/eps = 2e-16/1e-6 = 2e-10 (cancellation). 1e-8 leaves a
# 25x margin.
FD_ATOL = 1e-8


@pytest.mark.parametrize("mode", ["matched", "exact"])
def test_fd_opacity_logit_matches_sigmoid_derivative(mode):
    params = gaussians([0, 0, Z], [SCALE], [OPACITY], [COLOUR])
    row, col, d2 = 12, 18, 4.0  # well inside the cutoff: matched mode is smooth here too

    def loss(out):
        return out.rgb[row, col, 0]

    got = finite_difference_grad(loss, *params, wrt="opacity_logits", mode=mode,
                                 K=CAM_K, world_to_camera=EYE, width=WIDTH, height=HEIGHT)
    o = sigmoid(params[3][0])
    expected = o * (1 - o) * np.exp(-d2 / (2 * SIGMA2)) * COLOUR[0]
    assert got.shape == (1,)
    assert got[0] == pytest.approx(expected, abs=FD_ATOL)


def test_fd_mean_x_matches_analytic_derivative():
    # value = o·c·exp(-dx²/(2σ²)) on the mean's row, dx = px - (fx·x/z + cx), so
    # d value / d x = value·dx/σ²·fx/z. σ² does not change to first order: in exact mode
    # Σ2D_xx = (fx·s/z)²(1 + (x/z)²) + eps2d is even in x.
    params = gaussians([0, 0, Z], [SCALE], [OPACITY], [COLOUR])
    row, col, dx = 12, 18, 2.0

    def loss(out):
        return out.rgb[row, col, 1]

    got = finite_difference_grad(loss, *params, wrt="means", indices=[0], mode="exact",
                                 K=CAM_K, world_to_camera=EYE, width=WIDTH, height=HEIGHT)
    value = OPACITY * np.exp(-dx**2 / (2 * SIGMA2)) * COLOUR[1]
    assert got.shape == (1,)
    # f''' ~ value·(F/Z/σ)³ ~ 300 here, so truncation is eps²·300/6 = 5e-11: FD_ATOL holds.
    assert got[0] == pytest.approx(value * dx / SIGMA2 * F / Z, abs=FD_ATOL)


def test_fd_sh_full_gradient_and_indices():
    means, log_scales, quats, logits, _ = gaussians([[0, 0, Z], [0.3, 0, 2.5]], [SCALE] * 2, [OPACITY] * 2, [COLOUR] * 2)
    sh = np.zeros((2, 4, 3))
    sh[:, 0] = 0.2
    kwargs = dict(mode="exact", K=CAM_K, world_to_camera=EYE, width=WIDTH, height=HEIGHT, sh_degree=0)

    def loss(out):
        return out.rgb[CENTRE].sum()

    full = finite_difference_grad(loss, means, log_scales, quats, logits, sh, wrt="sh", **kwargs)
    assert full.shape == sh.shape
    # rgb_c = w·(C0·sh0_c + 0.5) with w the Gaussian's weight T·alpha: d/d sh0_c = w·C0.
    out = render(means, log_scales, quats, logits, sh, **kwargs)
    colour = C0 * 0.2 + 0.5
    assert full[:, 0].sum() == pytest.approx(out.rgb[CENTRE].sum() / colour * C0, abs=FD_ATOL)
    np.testing.assert_array_equal(full[:, 1:], 0.0)  # bands above sh_degree: zero gradient
    picked = finite_difference_grad(loss, means, log_scales, quats, logits, sh, wrt="sh",
                                    indices=[0, 13, 5], **kwargs)
    np.testing.assert_array_equal(picked, full.ravel()[[0, 13, 5]])
    with pytest.raises(ValueError, match="wrt"):
        finite_difference_grad(loss, means, log_scales, quats, logits, sh, wrt="colors", **kwargs)


def test_public_api():
    for name in ["project", "eval_sh", "composite", "render", "finite_difference_grad",
                 "quat_to_rotmat", "covariance", "Projection", "Composite", "RenderOutput"]:
        assert hasattr(reference, name), name
    assert reference.Projection._fields == ("means2d", "conics", "depths", "opacities",
                                            "cutoff_sq", "radii", "visible")
    assert reference.RenderOutput._fields == ("rgb", "alpha", "depth", "radii", "visible", "band", "tie_slack",
                                              "grad_band", "grad_weight")
    assert reference.Composite._fields == ("rgb", "alpha", "depth", "band", "tie_slack", "grad_band", "grad_weight")


def test_reference_imports_nothing_from_splatbench():
    # The oracle must not share code (or bugs) with the fast path.
    code = "import sys, reference; sys.exit('splatbench' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
