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
from splatbench.raster.pipeline import SH_ABS_MAX
from splatbench.stress.cases import nonfinite

FINITE_CATEGORIES = tuple(c for c in CATEGORIES if c != "nonfinite")
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
@given(category=st.sampled_from(CATEGORIES), seed=st.integers(0, 2**31 - 1))
def test_random_cases_keep_the_contract(category, seed):
    assert_contract(build_case(category, seed))


# Any finite float32 at all, in any field.
finite32 = st.floats(allow_nan=False, allow_infinity=False, width=32)


@settings(max_examples=10, deadline=None)
@given(category=st.sampled_from(FINITE_CATEGORIES), seed=st.integers(0, 2**31 - 1),
       field=st.sampled_from(FIELDS), where=st.integers(0, 2**31 - 1), value=finite32)
def test_any_finite_entry_keeps_outputs_and_gradients_finite(category, seed, field, where, value):
    case = build_case(category, seed)
    array = getattr(case, field).copy()
    array.reshape(-1)[where % array.size] = value
    case = dataclasses.replace(case, **{field: array})
    if field == "sh" and abs(value) > SH_ABS_MAX:  # outside the input domain: rejected
        assert_sh_rejected(case)
    else:
        assert_contract(case)


# ------------------------------------------------------------- per category
@pytest.mark.parametrize("category", CATEGORIES)
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
    params = [torch.tensor(a, requires_grad=True) for a in case.params().values()]
    with pytest.raises(InputError, match=rf"^{field}: ") as info:
        splatbench.rasterize(*params, case.camera)
    assert "\n" not in str(info.value)
    with pytest.raises(InputError, match=rf"^{field}: "):
        splatbench.Gaussians(**case.params())


def test_cases_are_deterministic():
    for category in CATEGORIES:
        a, b = build_case(category, 7), build_case(category, 7)
        for field in FIELDS:
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


# ------------------------------------------------------------- input domain
def assert_sh_rejected(case: StressCase) -> None:
    params = [torch.tensor(a, requires_grad=True) for a in case.params().values()]
    with pytest.raises(InputError, match=r"^sh: \|value\| .* exceeds the supported range") as info:
        splatbench.rasterize(*params, case.camera)
    assert "\n" not in str(info.value)


def test_huge_sh_is_rejected_naming_the_field():
    """|sh| ~ 3e38 is finite, but its true gradients exceed float32: outside the input
    domain (conventions.md), so rejected in one line instead of producing Inf."""
    case = build_case("needles", SEED)
    sh = case.sh.copy()
    sh[0, 0, 1] = 3e38
    assert_sh_rejected(dataclasses.replace(case, sh=sh))
    g = dataclasses.replace(case, sh=sh)
    with pytest.raises(InputError, match=r"^sh: \|value\| 3e\+38 at index \[0, 0, 1\]"):
        splatbench.render(splatbench.Gaussians(**g.params()), g.camera)


def test_tiny_quaternions_count_as_zero_with_zero_gradient():
    """max|q_i| < 1e-20 is treated as the zero quaternion (identity): same image, and a
    zero (not Inf/NaN) gradient, since the true one, ~1/|q|, would overflow float32."""
    case = build_case("needles", SEED)
    tiny = case.quats.copy()
    tiny[0] = [8e-21, 4e-21, -2e-21, 4e-21]
    zero = case.quats.copy()
    zero[0] = 0.0
    images = []
    for quats in (tiny, zero):
        params = [torch.tensor(a, requires_grad=True) for a in dataclasses.replace(case, quats=quats).params().values()]
        rgb, _, _, _ = splatbench.rasterize(*params, case.camera)
        rgb.sum().backward()
        assert torch.isfinite(params[2].grad).all() and (params[2].grad[0] == 0).all()
        images.append(rgb.detach())
    torch.testing.assert_close(images[0], images[1], rtol=0, atol=0)


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


def test_a_device_that_cannot_run_fails_before_any_case(monkeypatch):
    """'cuda' without a GPU (faked) is the caller's fault, not a robustness failure of every case:
    one `InputError` before the first case (the CLI's one line: tests/test_cli_device.py)."""
    from splatbench.raster import device as raster_device

    monkeypatch.setattr(raster_device, "cuda_available", lambda: False)
    raster_device.get_device.cache_clear()
    ran = []
    try:
        with pytest.raises(InputError, match=r"^device: 'cuda' asked for, but Dr\.Jit finds no CUDA device"):
            run(4, device="cuda", on_case=ran.append)
        with pytest.raises(InputError, match=r"^device: expected 'auto', 'cpu' or 'cuda', got 'tpu'$"):
            run(4, device="tpu", on_case=ran.append)
    finally:
        raster_device.get_device.cache_clear()
    assert ran == []
