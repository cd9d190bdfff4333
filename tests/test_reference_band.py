"""The boundary band the oracle derives (`reference.band`): a pixel is in it exactly when some
contribution lies within its float32 error bound of a discrete decision, and a depth tie widens
the pixel's bound by what the swap changes instead.

The scenes are Gaussians centred on one pixel (`composite` inputs, as tests/test_reference.py
builds them) with error bounds set by hand, so each decision's margin is known exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

import reference
from reference.band import U, ProjectionError, projection_error

WIDTH, HEIGHT = 32, 24
CX, CY = 16.5, 12.5            # the centre of pixel CENTRE
CENTRE = (12, 16)
ALPHA_MIN = 1 / 255


def _errors(n, *, mean_px=0.0, depth=0.0, opacity_rel=0.0, position_id=None):
    z = np.zeros(n)
    return ProjectionError(z + mean_px, z + depth, z.copy(), z.copy(), z + opacity_rel, z.copy(),
                           np.arange(n) if position_id is None else np.asarray(position_id))


def _composite(opacities, depths, colours, errors, *, conic=(0.01, 0.0, 0.01), offset=0.0):
    n = len(opacities)
    means2d = np.tile([CX + offset, CY], (n, 1))
    return reference.composite(means2d, np.tile(conic, (n, 1)), np.asarray(opacities, float),
                               np.asarray(colours, float), np.asarray(depths, float), np.full(n, 9.0),
                               np.ones(n, bool), WIDTH, HEIGHT, errors=errors)


@pytest.mark.parametrize("factor, in_band", [(1 + 1e-9, True), (1 - 1e-9, True), (1.01, False), (0.99, False)])
def test_alpha_min(factor, in_band):
    # At the centre sigma = 0, so alpha = o; its bound is opacity_rel + 3 u (here 1e-6).
    out = _composite([ALPHA_MIN * factor], [2.0], [[1.0, 1.0, 1.0]], _errors(1, opacity_rel=1e-6 - 3 * U))
    assert out.band[CENTRE] == in_band
    assert out.tie_slack[CENTRE] == 0.0


def test_cutoff():
    # A Gaussian with conic (1, 0, 1) three pixels left of CENTRE: sigma = 0.5 * 3² = 4.5 at CENTRE,
    # exactly the 3-sigma cutoff; two pixels right of it (sigma = 2) is far from any decision.
    out = _composite([0.9], [2.0], [[1.0, 1.0, 1.0]], _errors(1, mean_px=1e-6), conic=(1.0, 0.0, 1.0), offset=-3.0)
    assert out.band[CENTRE]
    assert not out.band[CENTRE[0], CENTRE[1] - 1]
    assert out.alpha[CENTRE] > 0  # kept in float64 (sigma <= 4.5): float32 may drop it


def test_early_stop():
    # T after the second = (1 - 0.99)(1 - a2) = 1e-4 (1 + 1e-9): just above transmittance_min.
    a2 = 1 - 1e-2 * (1 + 1e-9)
    out = _composite([0.99, a2], [1.0, 2.0], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], _errors(2))
    assert out.band[CENTRE]
    far = _composite([0.99, 0.5], [1.0, 2.0], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], _errors(2))
    assert not far.band[CENTRE]


def test_depth_tie_widens_the_bound_by_the_swap():
    red, green = [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]
    out = _composite([0.5, 0.8], [3.0, 3.0 + 1e-9], [red, green], _errors(2, depth=1e-7))
    assert not out.band[CENTRE]
    # the two orders differ by T a1 a2 |c1 - c2| = 0.5 * 0.8 * 1 at the centre (alpha = o there)
    assert out.tie_slack[CENTRE] == pytest.approx(0.5 * 0.8)
    # ... and not at all when float32 cannot swap them: z further apart than the bounds, or bitwise
    # equal means (float32 computes the same z for both and breaks the tie by index as float64 does)
    assert _composite([0.5, 0.8], [3.0, 3.1], [red, green], _errors(2, depth=1e-7)).tie_slack.max() == 0
    same = _composite([0.5, 0.8], [3.0, 3.0], [red, green], _errors(2, depth=1e-7, position_id=[0, 0]))
    assert same.tie_slack.max() == 0


def test_exact_mode_has_no_band():
    with pytest.raises(ValueError, match="errors: the boundary band is a matched-mode notion"):
        reference.composite(np.array([[CX, CY]]), np.array([[0.01, 0.0, 0.01]]), np.array([0.5]), np.ones((1, 3)),
                            np.array([2.0]), np.array([9.0]), np.ones(1, bool), WIDTH, HEIGHT, mode="exact",
                            errors=_errors(1))


def test_projection_error_grows_with_distance_from_the_origin():
    """The float32 error of the camera-space point is relative to |W| |m| + |t|: the same view of
    the same Gaussian, translated 1000 units away along with its camera, has a larger bound."""
    K = np.array([[50.0, 0, 16], [0, 50.0, 12], [0, 0, 1]])
    means, scales, quats, logits = np.array([[0.1, 0.2, 3.0]]), np.full((1, 3), -2.0), np.array([[1.0, 0, 0, 0]]), [0.0]
    proj = reference.project(means, scales, quats, logits, K, np.eye(4), WIDTH, HEIGHT)
    near = projection_error(means, scales, quats, logits, K, np.eye(4), proj.conics)
    moved = np.eye(4)
    moved[:3, 3] = -1000.0
    far = projection_error(means + 1000.0, scales, quats, logits, K, moved, proj.conics)
    assert far.mean_px[0] > 100 * near.mean_px[0] and far.depth[0] > 100 * near.depth[0]
    assert all(np.isfinite(field).all() for field in near[:-1])


# ----------------------------------------------------------------------------- the gradient band
def test_gradient_band_holds_the_flipped_contribution_and_weights_the_others_by_its_alpha():
    # Two Gaussians over CENTRE: a plain one in front, and behind it one whose alpha sits at alpha_min.
    # Only the borderline one's own term may change whole; the front one's terms change by a relative
    # a_k <= 1/255 (the colour behind it), which is the pixel's weight.
    factor = 1 + 1e-9
    out = _composite([0.5, ALPHA_MIN * factor], [1.0, 2.0], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                     _errors(2, opacity_rel=1e-6 - 3 * U))
    assert out.band[CENTRE]
    assert out.grad_band.tolist() == [False, True]
    assert out.grad_weight[CENTRE] == pytest.approx(ALPHA_MIN * factor)
    far = _composite([0.5, ALPHA_MIN * 1.01], [1.0, 2.0], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                     _errors(2, opacity_rel=1e-6 - 3 * U))
    assert not far.grad_band.any() and far.grad_weight.max() == 0


def test_gradient_band_holds_a_swappable_pair_and_a_clamp_borderline_gaussian():
    red, green = [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]
    tie = _composite([0.5, 0.8, 0.3], [3.0, 3.0 + 1e-9, 5.0], [red, green, red], _errors(3, depth=1e-7))
    assert tie.grad_band.tolist() == [True, True, False]
    assert tie.grad_weight[CENTRE] == pytest.approx(0.5 * 0.8)
    # alpha at the 0.99 clamp: the image is continuous across it, the derivative is not (gradient only)
    clamp = _composite([0.99 * (1 + 1e-9)], [2.0], [red], _errors(1, opacity_rel=1e-6))
    assert not clamp.band.any() and clamp.grad_band.tolist() == [True] and clamp.grad_weight.max() == 0
