"""Numerical-stability stress test (docs/stress.md): degenerate and non-finite input
through `splatbench.rasterize`, forward and backward.

Contract (docs/conventions.md): non-finite input is rejected with a one-line
`InputError` naming the field; finite input is never rejected and never gives NaN or
Inf in an output or a gradient. Hypothesis drives the same case builders as
`splatbench stress`: it picks the category and the seed, and in a second property
overwrites one entry of one field with any finite float32.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

import splatbench
from splatbench import InputError
from splatbench.cli import main
from splatbench.stress import CATEGORIES, FIELDS, StressCase, build_case, run, run_case
from splatbench.stress import runner as stress_runner
from splatbench.stress.cases import nonfinite

# Known rasterizer bugs found by this test. TEMPORARY: each has a strict xfail below
# that must be removed (and the category put back into the property) once fixed.
TINY_QUATS_BUG = ("rasterizer bug (docs/stress.md): quaternion normalisation backward overflows "
                  "(d(1/max|q_i|) = -1/max|q_i|^2) for 0 < max|q_i| < ~5e-20: Inf/NaN quats gradients")
HUGE_SH_BUG = ("contract gap (docs/stress.md): |sh| ~ 3e38 (finite) gives Inf log_scales gradients; the true "
               "gradient exceeds float32, so conventions.md needs a domain bound or the boundary a check")
KNOWN_BUGS = {"tiny_quats": TINY_QUATS_BUG}
CLEAN_CATEGORIES = tuple(c for c in CATEGORIES if c not in KNOWN_BUGS)
FINITE_CATEGORIES = tuple(c for c in CLEAN_CATEGORIES if c != "nonfinite")
SEED = 20240611


def assert_contract(case: StressCase, device: str | None = None) -> stress_runner.CaseResult:
    result = run_case(case, device=device)
    assert result.error is None, result.describe()
    assert not result.nonfinite_outputs, result.describe()
    assert not result.nonfinite_grads, result.describe()
    assert result.rejected == (case.nonfinite_field is not None), result.describe()
    return result


# ------------------------------------------------------------- hypothesis
@settings(max_examples=20, deadline=None)
@given(category=st.sampled_from(CLEAN_CATEGORIES), seed=st.integers(0, 2**31 - 1))
def test_random_cases_keep_the_contract(category, seed):
    assert_contract(build_case(category, seed))


# Any finite float32, except the two ranges known to fail (see KNOWN_BUGS, HUGE_SH_BUG).
finite32 = st.floats(allow_nan=False, allow_infinity=False, width=32)


@settings(max_examples=10, deadline=None)
@given(category=st.sampled_from(FINITE_CATEGORIES), seed=st.integers(0, 2**31 - 1),
       field=st.sampled_from(FIELDS), where=st.integers(0, 2**31 - 1), value=finite32)
def test_any_finite_entry_keeps_outputs_and_gradients_finite(category, seed, field, where, value):
    if field == "sh":
        value = float(np.clip(value, -1e30, 1e30))
    if field == "quats" and 0 < abs(value) < 1e-19:
        value = 0.0
    case = build_case(category, seed)
    array = getattr(case, field).copy()
    array.reshape(-1)[where % array.size] = value
    if field == "quats":  # the whole quaternion must avoid the known bug, not just this entry
        row = array[(where % array.size) // 4]
        row[np.abs(row) < 1e-19] = 0.0
    assert_contract(dataclasses.replace(case, **{field: array}))


# ------------------------------------------------------------- per category
@pytest.mark.parametrize("category", [
    pytest.param(c, marks=pytest.mark.xfail(strict=True, reason=KNOWN_BUGS[c])) if c in KNOWN_BUGS else c
    for c in CATEGORIES])
def test_category_fixed_seed(category):
    for seed in (SEED, SEED + 1):
        result = assert_contract(build_case(category, seed))
        assert result.n >= 1


def test_degenerate_categories_cull_something():
    """The generators do reach the culling paths they are meant to exercise."""
    report = run(cases=8, seed=SEED, categories=("extreme_scales", "near_plane"))
    assert report.ok, [f for c in report.categories for f in c.failures]
    assert all(c.culled > 0 for c in report.categories)


@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_input_is_rejected_naming_the_field(field, bad):
    case = nonfinite(SEED, field=field)
    assert case.nonfinite_field == field
    array = getattr(case, field).copy()
    array.reshape(-1)[array.size // 2] = bad
    case = dataclasses.replace(case, **{field: array})
    assert_contract(case)  # rejected, with a one-line message starting "field:"
    params = [torch.tensor(a, requires_grad=True) for a in case.params]
    with pytest.raises(InputError, match=rf"^{field}: ") as info:
        splatbench.rasterize(*params, case.camera)
    assert "\n" not in str(info.value)
    with pytest.raises(InputError, match=rf"^{field}: "):
        splatbench.Gaussians(*case.params)


def test_cases_are_deterministic():
    for category in CATEGORIES:
        a, b = build_case(category, 7), build_case(category, 7)
        for field in FIELDS:
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


# ------------------------------------------------------------- known bugs (TEMPORARY)
@pytest.mark.xfail(strict=True, reason=HUGE_SH_BUG)
def test_huge_sh_gradients_stay_finite():
    cam = splatbench.Camera(32, 24, 30.0, 30.0, 16.0, 12.0, np.eye(4))
    params = [torch.tensor(a, requires_grad=True) for a in (
        np.array([[0.1, 0.05, 3.0]], np.float32), np.array([[-2.0, -3.0, -2.5]], np.float32),
        np.array([[0.8, 0.4, -0.2, 0.4]], np.float32), np.array([1.0], np.float32),
        np.full((1, 1, 3), 3e38, np.float32))]
    rgb, alpha, depth, _ = splatbench.rasterize(*params, cam)
    v = torch.from_numpy(np.random.default_rng(0).standard_normal((24, 32, 3)).astype(np.float32))
    ((rgb * v).sum() + alpha.sum() + depth.sum()).backward()
    assert all(bool(torch.isfinite(p.grad).all()) for p in params)


# ------------------------------------------------------------- CLI
def test_cli_prints_one_line_per_category_and_writes_json(tmp_path):
    out = tmp_path / "stress.json"
    result = CliRunner().invoke(main, ["stress", "--cases", "4", "--seed", "3", "--jobs", "1", "--json", str(out),
                                       "--category", "zero_quats", "--category", "nonfinite"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert any(line.startswith("zero_quats ") and line.split()[1] == "2" for line in lines)
    assert any(line.startswith("nonfinite ") and line.split()[3] == "2" for line in lines)  # 2 rejected
    data = json.loads(out.read_text())
    assert data["ok"] is True and [c["category"] for c in data["categories"]] == ["zero_quats", "nonfinite"]


def test_cli_exits_nonzero_on_a_failure(monkeypatch):
    def broken(case, device=None):
        return stress_runner.CaseResult(case.category, case.seed, case.n, nonfinite_grads=("quats",))

    monkeypatch.setattr(stress_runner, "run_case", broken)
    result = CliRunner().invoke(main, ["stress", "--cases", "2", "--jobs", "1", "--category", "needles"])
    assert result.exit_code == 1
    assert "FAIL build_case('needles'" in result.output and "non-finite gradients ['quats']" in result.output
