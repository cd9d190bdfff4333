"""Hypothesis properties of the float64 NumPy oracle in `reference/`."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from reference import covariance, quat_to_rotmat, render
from reference.sh import C0, C1

EPS = np.finfo(np.float64).eps
PROPERTY_SETTINGS = settings(max_examples=60, deadline=None)

finite = st.floats(allow_nan=False, allow_infinity=False)
# Any finite quaternion, with the zero quaternion and 1e30-sized ones drawn on purpose.
any_quat = st.one_of(
    hnp.arrays(np.float64, 4, elements=finite),
    st.just(np.zeros(4)),
    hnp.arrays(np.float64, 4, elements=st.floats(-1.0, 1.0)).map(lambda q: 1e30 * q),
)
log_scales3 = hnp.arrays(np.float64, 3, elements=st.floats(-30.0, 30.0))


def _covariance_tolerance(cov):
    """Round-off bound for Σ = (R S)(R S)ᵀ: each entry sums 3 products whose rounding
    is <= 3·eps·s_max², and eigvalsh is backward stable to a few eps·||Σ||. Both are
    below 32·eps·trace(Σ) (trace >= ||Σ||₂ >= s_max²·(1 - O(eps)) for PSD Σ)."""
    return 32 * EPS * np.trace(cov)


@PROPERTY_SETTINGS
@given(log_scales=log_scales3, quat=any_quat, clip=st.booleans())
def test_covariance_is_symmetric_psd(log_scales, quat, clip):
    cov = covariance(log_scales[None], quat[None], clip=clip)[0]
    assert np.all(np.isfinite(cov))
    tol = _covariance_tolerance(cov)
    assert np.max(np.abs(cov - cov.T)) <= tol
    assert np.min(np.linalg.eigvalsh(cov)) >= -tol
    # Σ's eigenvalues are the squared scales (R is a rotation, or I for q = 0).
    s2 = np.exp(2 * (np.clip(log_scales, -20, 20) if clip else log_scales))
    np.testing.assert_allclose(np.trace(cov), s2.sum(), rtol=1e-13)  # a few eps per entry


@PROPERTY_SETTINGS
@given(quat=any_quat)
def test_rotation_is_orthonormal(quat):
    R = quat_to_rotmat(quat[None])[0]
    # q̂ has unit length to ~2 eps, so R Rᵀ = I to ~ a dozen eps per entry.
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=32 * EPS)
    assert np.linalg.det(R) > 0


# Components 0 or with 1e-13 <= |q_i| <= 1e200 so that scaling by 1e±6 neither
# overflows nor crosses max|q_i| = 1e-20, below which a quaternion counts as zero
# (conventions.md; a different quaternion, not a property of Σ).
moderate = st.one_of(st.just(0.0), st.floats(1e-13, 1e200), st.floats(-1e200, -1e-13))
moderate_quat = hnp.arrays(np.float64, 4, elements=moderate)


@PROPERTY_SETTINGS
@given(log_scales=log_scales3, quat=moderate_quat, factor=st.floats(1e-6, 1e6))
def test_covariance_ignores_quaternion_sign_and_length(log_scales, quat, factor):
    cov = covariance(log_scales[None], quat[None])[0]
    # -q: every product in R takes two sign flips or none, and q / max|q_i| is
    # sign-symmetric in IEEE arithmetic, so the result is bit-identical.
    np.testing.assert_array_equal(covariance(log_scales[None], -quat[None])[0], cov)
    # c·q: q / max|q_i| changes by ~3 eps per component, R by ~10 eps, Σ by ~20 eps of
    # its trace: 64·eps·trace is a safe bound.
    scaled = covariance(log_scales[None], factor * quat[None])[0]
    np.testing.assert_allclose(scaled, cov, rtol=0, atol=64 * EPS * np.trace(cov))


# Small random scenes in front of (and partly behind) a 12x9 camera.
WIDTH, HEIGHT = 12, 9
CAM_K = np.array([[10.0, 0.0, 6.0], [0.0, 10.0, 4.5], [0.0, 0.0, 1.0]])


@st.composite
def scenes(draw):
    n = draw(st.integers(0, 6))
    xy = draw(hnp.arrays(np.float64, (n, 2), elements=st.floats(-3.0, 3.0)))
    # Distinct depths, so that the compositing order does not depend on the index.
    z = draw(st.lists(st.floats(-1.0, 6.0), min_size=n, max_size=n, unique=True))
    means = np.column_stack([xy, np.array(z, dtype=np.float64).reshape(n)])
    log_scales = draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(-6.0, 2.0)))
    quats = draw(hnp.arrays(np.float64, (n, 4), elements=finite))
    logits = draw(hnp.arrays(np.float64, n, elements=st.floats(-30.0, 30.0)))
    sh = draw(hnp.arrays(np.float64, (n, 4, 3), elements=st.floats(-2.0, 2.0)))
    return means, log_scales, quats, logits, sh


@PROPERTY_SETTINGS
@given(scene=scenes(), mode=st.sampled_from(["matched", "exact"]),
       antialiased=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_random_scene_outputs_are_bounded_and_order_independent(scene, mode, antialiased, seed):
    camera = dict(K=CAM_K, world_to_camera=np.eye(4), width=WIDTH, height=HEIGHT,
                  mode=mode, antialiased=antialiased)
    out = render(*scene, **camera)
    assert np.all(np.isfinite(out.rgb)) and np.all(np.isfinite(out.depth))
    assert np.all((out.alpha >= 0) & (out.alpha <= 1))
    assert np.all(out.depth >= 0)
    np.testing.assert_array_equal(out.visible, out.radii > 0)
    if mode == "matched":
        # The early stop keeps T_final >= transmittance_min = 1e-4 (up to 1 - T's rounding).
        assert np.all(out.alpha <= 1 - 1e-4 + EPS)
    # Background 0 and colours >= 0: rgb = Σ w_k c_k with Σ w_k = alpha, so
    # 0 <= rgb <= alpha·c_max, where |x|, |y|, |z| <= 1 bounds every degree-1 colour by
    # c_max = 0.5 + C0·|sh0| + C1·(|sh1| + |sh2| + |sh3|). Slack: alpha = 1 - T_final is
    # a difference, off by up to (n + 1)·eps in absolute terms (n <= 6 products in T plus
    # the subtraction), so allow c_max·16·eps absolute plus 1e-12 relative for the sum.
    sh = np.abs(scene[4])
    c_max = np.max(0.5 + C0 * sh[:, 0] + C1 * sh[:, 1:].sum(axis=1), initial=0.0)
    assert np.all(out.rgb >= 0)
    assert np.all(out.rgb <= out.alpha[..., None] * c_max * (1 + 1e-12) + c_max * 16 * EPS)
    # Permuting the Gaussians permutes radii and leaves the image unchanged (depths are
    # distinct, so every pixel composites the same sequence with the same arithmetic).
    perm = np.random.default_rng(seed).permutation(len(scene[0]))
    shuffled = render(*(p[perm] for p in scene), **camera)
    np.testing.assert_array_equal(shuffled.rgb, out.rgb)
    np.testing.assert_array_equal(shuffled.radii, out.radii[perm])
