"""Gaussians: boundary validation, activations and covariance maths."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from splatbench.errors import InputError
from splatbench.gaussians import SH_C0, Gaussians, normalize_quats, quat_to_rotmat
from splatbench.train.config import SHConfig
from tests.assertions import one_line_error

EPS64 = np.finfo(np.float64).eps
EPS32 = float(np.finfo(np.float32).eps)


def make(n: int = 5, k: int = 16, seed: int = 0, **override) -> Gaussians:
    rng = np.random.default_rng(seed)
    fields = dict(
        means=rng.normal(size=(n, 3)),
        log_scales=rng.normal(size=(n, 3)),
        quats=rng.normal(size=(n, 4)),
        opacity_logits=rng.normal(size=n),
        sh=rng.normal(size=(n, k, 3)),
    )
    fields.update(override)
    return Gaussians(**fields)



# ------------------------------------------------------------------ validation
@pytest.mark.parametrize("field, value, expect", [
    ("means", np.zeros((5, 2)), "[N, 3]"),
    ("means", np.zeros(15), "got [15]"),
    ("log_scales", np.zeros((4, 3)), "N=5"),
    ("quats", np.zeros((5, 3)), "[N, 4]"),
    ("opacity_logits", np.zeros((5, 1)), "[N]"),
    ("opacity_logits", np.zeros(6), "N=5"),
    ("sh", np.zeros((5, 5, 3)), "got [5, 5, 3]"),
    ("sh", np.zeros((5, 16, 4)), "K in (1, 4, 9, 16)"),
    ("sh", np.zeros((5, 3)), "got [5, 3]"),
    ("sh", np.zeros((6, 4, 3)), "N=5"),
    ("means", np.array([["a", "b", "c"]] * 5), "dtype"),
    ("quats", np.ones((5, 4), dtype=bool), "dtype"),
])
def test_shape_and_dtype_errors_name_the_field(field, value, expect):
    msg = one_line_error(lambda: make(**{field: value}), field + ":")
    assert expect in msg


def test_sh_error_message_matches_documented_form():
    msg = one_line_error(lambda: make(n=10, sh=np.zeros((10, 5, 3))))
    assert msg == "sh: expected shape [N, K, 3] with K in (1, 4, 9, 16), got [10, 5, 3]"


@pytest.mark.parametrize("field", ["means", "log_scales", "quats", "opacity_logits", "sh"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_rejected_with_index(field, bad):
    g = make()
    value = getattr(g, field).copy()
    flat = value.reshape(-1)
    flat[7 % flat.size] = bad
    where = [int(i) for i in np.unravel_index(7 % flat.size, value.shape)]
    msg = one_line_error(lambda: make(**{field: value}), field + ":", "non-finite", str(where))
    assert msg.startswith(field + ":")


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
def test_float64_values_overflowing_float32_are_rejected():
    # 1e39 is finite in float64 but not representable in float32 (max ~3.4e38).
    one_line_error(lambda: make(means=np.full((5, 3), 1e39)), "means:", "non-finite")


def test_stored_as_contiguous_float32():
    g = make(means=np.asfortranarray(np.ones((5, 3), dtype=np.float64)), quats=np.ones((5, 4), dtype=np.int64))
    for name in ("means", "log_scales", "quats", "opacity_logits", "sh"):
        array = getattr(g, name)
        assert array.dtype == np.float32 and array.flags.c_contiguous, name
    assert len(g) == 5 and g.sh_degree == 3


@pytest.mark.parametrize("k, degree", [(1, 0), (4, 1), (9, 2), (16, 3)])
def test_sh_degree(k, degree):
    assert make(k=k).sh_degree == degree


def test_empty_set_is_valid():
    g = make(n=0)
    assert len(g) == 0 and g.covariances().shape == (0, 3, 3)


# ----------------------------------------------------------------- activations
def test_activations():
    log_scales = np.array([[0.0, math.log(2.0), -1.0], [25.0, -25.0, 3.0]])  # ±25 exercise the ±20 clip
    logits = np.array([0.0, 2.0])
    quats = np.array([[2.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
    g = make(n=2, log_scales=log_scales, opacity_logits=logits, quats=quats)
    # float32 exp/sigmoid are correctly rounded to within a few ulp
    np.testing.assert_allclose(g.scales, [[1, 2, math.exp(-1)], [math.exp(20), math.exp(-20), math.exp(3)]],
                               rtol=4 * EPS32)
    np.testing.assert_allclose(g.opacities, [0.5, 1 / (1 + math.exp(-2))], rtol=4 * EPS32)
    np.testing.assert_array_equal(g.rotations, [[1, 0, 0, 0], [0, 0, 0, 0]])
    assert g.scales.dtype == g.opacities.dtype == g.rotations.dtype == np.float32


def test_sigmoid_does_not_overflow_for_extreme_logits():
    with np.errstate(over="raise", invalid="raise", divide="raise"):  # underflow of exp(-1e30) is fine
        o = make(n=2, opacity_logits=np.array([-1e30, 1e30])).opacities
    np.testing.assert_array_equal(o, [0.0, 1.0])


def test_zero_quaternion_maps_to_identity():
    q = normalize_quats(np.zeros((1, 4)))
    np.testing.assert_array_equal(q, 0)
    np.testing.assert_array_equal(quat_to_rotmat(q)[0], np.eye(3))


def test_huge_quaternions_normalise_and_tiny_ones_count_as_zero():
    # conventions.md: max|q_i| < 1e-20 counts as the zero quaternion (identity).
    q = np.array([[1e30, 1e30, 0, 0], [1e-19, 0, 1e-19, 0], [1e-40, 0, 1e-40, 0], [0, 9e-21, 0, 0]],
                 dtype=np.float32)  # 1e-40: subnormal
    with np.errstate(all="raise"):
        u = normalize_quats(q)
    s = 1 / math.sqrt(2)
    np.testing.assert_allclose(u, [[s, s, 0, 0], [s, 0, s, 0], [0, 0, 0, 0], [0, 0, 0, 0]], rtol=2 * EPS32)


# ------------------------------------------------------------------ covariance
def test_covariance_axis_aligned():
    g = make(n=1, log_scales=np.log([[1.0, 2.0, 3.0]]), quats=np.array([[1.0, 0, 0, 0]]))
    # log_scales are stored in float32, so exp(log s)^2 is s^2 to a few float32 ulp
    np.testing.assert_allclose(g.covariances()[0], np.diag([1.0, 4.0, 9.0]), rtol=8 * EPS32, atol=0)
    assert g.covariances().dtype == np.float64


def test_covariance_90_degrees_about_z():
    # q = (cos 45°, 0, 0, sin 45°) rotates x onto y: Σ = R diag(1,4,9) Rᵀ = diag(4, 1, 9)
    c = math.cos(math.pi / 4)
    g = make(n=1, log_scales=np.log([[1.0, 2.0, 3.0]]), quats=np.array([[c, 0, 0, c]]))
    R = quat_to_rotmat(normalize_quats(np.array([[c, 0, 0, c]])))[0]
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=4 * EPS32)
    # off-diagonals come from rounding of cos45 in float32 (~1 ulp) times the scales
    np.testing.assert_allclose(g.covariances()[0], np.diag([4.0, 1.0, 9.0]), rtol=8 * EPS32, atol=9 * 4 * EPS32)


def test_covariance_matches_rotated_closed_form():
    rng = np.random.default_rng(3)
    g = make(n=50, seed=3)
    s = np.exp(g.log_scales.astype(np.float64))
    for n in rng.integers(0, 50, 5):
        q = g.quats[n].astype(np.float64)
        R = quat_to_rotmat((q / np.linalg.norm(q))[None])[0]
        # independent: eigen-decomposition of Σ has eigenvalues s², eigenvectors = columns of R
        cov = g.covariances()[n]
        np.testing.assert_allclose(cov @ R, R * s[n] ** 2, rtol=1e-12, atol=1e-12 * s[n].max() ** 2)


# A float32 log-scale in [-30, 30] and quaternions including zero and huge ones.
log_scales_st = hnp.arrays(np.float32, (4, 3), elements=st.floats(-30, 30, width=32))
BIG = float(np.float32(1e30))
quat_el = st.one_of(st.floats(-BIG, BIG, width=32), st.just(0.0), st.sampled_from([BIG, -BIG, float(np.float32(1e-30))]))
quats_st = hnp.arrays(np.float32, (4, 4), elements=quat_el)


def _quats_with_zero(q: np.ndarray) -> np.ndarray:
    q = q.copy()
    q[0] = 0.0  # always include the zero quaternion
    return q


@settings(max_examples=60, deadline=None)
@given(log_scales=log_scales_st, quats=quats_st)
def test_covariance_symmetric_psd(log_scales, quats):
    g = make(n=4, log_scales=log_scales, quats=_quats_with_zero(quats))
    cov = g.covariances()
    assert np.all(np.isfinite(cov))
    np.testing.assert_array_equal(cov, np.swapaxes(cov, -1, -2))  # M Mᵀ is exactly symmetric
    eig = np.linalg.eigvalsh(cov)
    # eigvalsh is backward stable: eigenvalue errors are a few eps·‖Σ‖₂ (≤ max eig)
    bound = 16 * EPS64 * np.abs(eig).max(axis=1, keepdims=True)
    assert np.all(eig >= -bound)


@settings(max_examples=60, deadline=None)
@given(log_scales=log_scales_st, quats=quats_st,
       magnitude=st.floats(-19, 30), sign=st.sampled_from([-1.0, 1.0]))
def test_covariance_invariant_to_quaternion_sign_and_length(log_scales, quats, magnitude, sign):
    # magnitude >= -19: below max|q| = 1e-20 a quaternion counts as zero (conventions.md)
    q = _quats_with_zero(quats).astype(np.float64)
    peak = np.abs(q).max(axis=1, keepdims=True)
    # invariance holds inside the normalising domain; rows already below 1e-20 count as
    # zero (tested in test_huge_quaternions_normalise_and_tiny_ones_count_as_zero)
    q = np.where(peak >= 1e-20, q, 0.0)
    peak = np.abs(q).max(axis=1, keepdims=True)
    # rescale every non-zero row to max|q| = 1.7·10^magnitude (inside float32's range)
    factor = np.where(peak > 0, sign * 1.7 * 10.0 ** magnitude / np.where(peak > 0, peak, 1), 1)
    g1 = make(n=4, log_scales=log_scales, quats=q)
    g2 = make(n=4, log_scales=log_scales, quats=q * factor)
    g3 = make(n=4, log_scales=log_scales, quats=-q)
    cov1, cov2 = g1.covariances(), g2.covariances()
    # negation is exact in float32 and R is quadratic in q: bit-identical
    np.testing.assert_array_equal(g3.covariances(), cov1)
    # the zero quaternion stays zero, i.e. R = I and Σ = S²
    s2 = np.exp(np.clip(log_scales.astype(np.float64), -20, 20)) ** 2
    np.testing.assert_array_equal(np.diagonal(cov2[0]), s2[0])
    # Rescaled quaternions are rounded to float32 (half an ulp per entry), so the unit
    # quaternion moves by ~eps32, R by ~4·eps32 per entry and Σ = R S² Rᵀ by at most
    # ~2·|ΔR|·3·max(s²); 64·eps32·max(s²) leaves a margin of a few.
    err = np.abs(cov1 - cov2).max(axis=(1, 2))
    assert np.all(err <= 64 * EPS32 * s2.max(axis=1)), err / s2.max(axis=1)


# --------------------------------------------------------------------- editing
def test_with_sh_degree_truncates_and_pads():
    g = make(k=9)
    lower, higher = g.with_sh_degree(1), g.with_sh_degree(3)
    assert lower.sh.shape == (5, 4, 3) and higher.sh.shape == (5, 16, 3)
    np.testing.assert_array_equal(lower.sh, g.sh[:, :4])
    np.testing.assert_array_equal(higher.sh[:, :9], g.sh)
    np.testing.assert_array_equal(higher.sh[:, 9:], 0)
    np.testing.assert_array_equal(higher.means, g.means)
    one_line_error(lambda: g.with_sh_degree(4), "degree")
    one_line_error(lambda: g.with_sh_degree(1.5), "degree")


def test_subset_mask_and_index():
    g = make(n=6)
    mask = np.array([True, False, True, False, False, True])
    by_mask, by_index = g.subset(mask), g.subset([0, 2, 5])
    for name in ("means", "log_scales", "quats", "opacity_logits", "sh"):
        np.testing.assert_array_equal(getattr(by_mask, name), getattr(g, name)[[0, 2, 5]])
        np.testing.assert_array_equal(getattr(by_index, name), getattr(g, name)[[0, 2, 5]])
    assert len(g.subset([])) == 0
    one_line_error(lambda: g.subset(np.ones(5, dtype=bool)), "index", "[6]")
    one_line_error(lambda: g.subset([6]), "index", "6")
    one_line_error(lambda: g.subset([0.5]), "index", "dtype")


def test_dc_constant():
    # C0 = 1 / (2 sqrt(pi)), the degree-0 real SH basis
    assert SH_C0 == pytest.approx(1 / (2 * math.sqrt(math.pi)), rel=EPS64)


@pytest.mark.parametrize("value", [4, -1, True, 1.5, "2"])
def test_sh_degree_is_checked_by_one_function_everywhere(value):
    """`guards.check_sh_degree` is the SH-degree check of init, workloads, with_sh_degree,
    TrainConfig and the raster run kind: the same one-line message from each."""
    from splatbench.guards import check_sh_degree
    from splatbench.experiments.raster_kind import validate as validate_raster_config
    from splatbench.gaussians_from_points import from_points
    from splatbench.train import TrainConfig
    from splatbench.workloads import synthetic

    with pytest.raises(InputError) as first:
        check_sh_degree("sh_degree", value)
    message = str(first.value)
    assert message.startswith("sh_degree: expected an int in 0..3, got ")
    for call in (lambda: from_points(np.zeros((2, 3)), np.zeros((2, 3)), sh_degree=value),
                 lambda: synthetic(4, 8, 8, sh_degree=value),
                 lambda: validate_raster_config({"scene": "synthetic-10-8x8", "sh_degree": value})):
        with pytest.raises(InputError, match="^" + re.escape(message) + "$"):
            call()
    if type(value) is int:  # TrainConfig's field types are checked before its ranges
        with pytest.raises(InputError, match=r"^sh\.degree: expected an int in 0\.\.3 or 'auto', got "):
            TrainConfig(dataset="x", sh=SHConfig(degree=value)).validate()
    assert check_sh_degree("d", "auto", allow_auto=True) == "auto"
