"""The rasterizer against Gaussians ray-traced by Mitsuba's volprim_rf_basic (docs/validation.md).

Where the splatting approximation is tight (small, isotropic, screen-disjoint,
depth-separated Gaussians) the two renderers must agree within a bound *derived*
from their definitions (`isotropic_prediction`), and the measured difference must
equal the closed-form one; away from it, the error must grow with size and overlap.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner

import splatbench  # noqa: F401 - configures libLLVM before drjit loads
from splatbench import Camera, InputError
from splatbench.backends.builtins.mitsuba_scene import mitsuba_volprim
from splatbench.validate import mitsuba as vm
from splatbench.validate.mitsuba import cases

WIDTH = 64  # every scene here is 64x64 (or smaller): the suite shares 2 cores


def test_sh_basis_is_graphdeco_s():
    """Mitsuba's dr.sh_eval (used by volprim_rf_basic) is the basis of conventions.md, term by term."""
    import drjit as dr

    from reference.sh import sh_basis

    mi = mitsuba_volprim()
    rng = np.random.default_rng(3)
    d = rng.normal(size=(64, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    theirs = dr.sh_eval(mi.Vector3f(*[np.ascontiguousarray(d[:, k], np.float32) for k in range(3)]), 3)
    theirs = np.stack([np.broadcast_to(np.asarray(t, np.float64), (64,)) for t in theirs], axis=1)
    np.testing.assert_allclose(theirs, sh_basis(d, 3), atol=2e-6)


def _image_orientation(img: np.ndarray) -> float:
    """Principal-axis angle (degrees, mod 180) of an image's intensity distribution."""
    w = img.sum(-1).astype(np.float64)
    jj, ii = np.meshgrid(np.arange(img.shape[1]), np.arange(img.shape[0]))
    mx, my = (w * jj).sum() / w.sum(), (w * ii).sum() / w.sum()
    cxx = (w * (jj - mx) ** 2).sum()
    cyy = (w * (ii - my) ** 2).sum()
    cxy = (w * (jj - mx) * (ii - my)).sum()
    return math.degrees(0.5 * math.atan2(2 * cxy, cxx - cyy)) % 180


def test_rotation_convention_matches():
    """A needle rotated about the view axis points the same way in both images (quaternion order)."""
    cam = cases._camera(WIDTH)
    s = 6.0 * cases._DISTANCE / cam.fx  # 6 px long axis
    half = math.radians(35.0) / 2
    quat = np.array([[math.cos(half), 0.0, 0.0, math.sin(half)]])  # 35 degrees about world z (= view axis)
    g = cases._gaussians(np.zeros((1, 3)), np.array([[s, s / 8, s / 8]]), np.full((1, 3), 0.9), quats=quat)
    c = vm.compare(g, cam)
    a_splat, a_traced = _image_orientation(c.splat), _image_orientation(c.traced)
    assert abs(a_splat - a_traced) < 0.5, (a_splat, a_traced)
    assert abs(a_splat - 35.0) < 1.0 or abs(a_splat - 145.0) < 1.0, a_splat


def test_dedup_changes_nothing_without_rehits():
    """volprim_rf_dedup equals the shipped integrator bit for bit where no primitive is re-entered."""
    cam = Camera.look_at(eye=[0, 0, -4], target=[0, 0, 0], up=[0, -1, 0], width=32, height=32, fov_x_deg=50)
    rng = np.random.default_rng(0)
    g = cases._gaussians(rng.uniform(-0.8, 0.8, (6, 3)), np.full((6, 3), 0.3), rng.uniform(0.2, 0.9, (6, 3)))
    shipped = vm.render_traced(g, cam, shipped=True)
    dedup = vm.render_traced(g, cam)
    np.testing.assert_array_equal(dedup, shipped)
    assert shipped.max() > 0.1


def test_tight_regime_within_derived_bound():
    """Small isotropic Gaussians (sigma <= 1 px): PSNR >= the derived bound >= 40 dB, closed form exact."""
    checks = vm.check_tight(WIDTH, max_sigma_px=1.0)
    assert len(checks) == 9  # three sizes x (bound >= 40 dB, measured within bound, closed form)
    failed = [f"{c.name}: {c.detail}" for c in checks if not c.passed]
    assert not failed, failed


def test_error_grows_with_size_and_overlap():
    rows = vm.run_sweeps(WIDTH, ["size", "overlap"])
    checks = vm.check_trends(rows)
    assert [c.name for c in checks] == ["error grows with size", "error grows with overlap"]
    failed = [f"{c.name}: {c.detail}" for c in checks if not c.passed]
    assert not failed, failed


def test_prediction_rejects_what_it_cannot_bound():
    case = vm.size_cases(WIDTH)[0]
    with pytest.raises(InputError, match="overlap"):
        g = case.gaussians
        vm.isotropic_prediction(g.subset(np.array([0, 0])), case.camera)  # the same Gaussian twice
    aniso = vm.anisotropy_cases(WIDTH, ratios=(4,))[0]
    with pytest.raises(InputError, match="isotropic"):
        vm.isotropic_prediction(aniso.gaussians, aniso.camera)


def test_cli_writes_table_and_plot(tmp_path):
    from splatbench.cli import main

    result = CliRunner().invoke(main, ["validate", "mitsuba", "--resolution", "32", "--sweep", "size",
                                       "--sweep", "overlap", "--no-probe", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    for name in ("table.csv", "table.md", "plot.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert "PASS  error grows with size" in result.output
    header = (tmp_path / "table.csv").read_text().splitlines()[0]
    assert header.startswith("sweep,parameter,value,options,gaussians,psnr,max_error")


def test_cli_lists_the_package_sweeps_and_default_folder():
    """The CLI keeps its own copy of the sweep names and the default folder (so that `splatbench
    validate --help` does not load Dr.Jit and Mitsuba): they must be the package's."""
    from splatbench.validate import cli

    assert cli._SWEEP_NAMES == tuple(vm.SWEEPS)
    assert cli.mitsuba.params[0].name == "out" and cli.mitsuba.params[0].default == vm.DEFAULT_OUT


def test_report_of_the_committed_rows_is_byte_identical(tmp_path):
    """`SweepRow` holds a `ComparisonMetrics` (not a copy of its fields); the CSV and markdown
    it writes are the committed baseline's, byte for byte, when built from that baseline's rows
    (its numbers are printed with 4 significant digits, which re-print unchanged)."""
    import csv
    from dataclasses import fields
    from pathlib import Path

    committed = Path(__file__).resolve().parents[1] / "reports" / "validate_mitsuba"
    ints = {"gaussians", "rehit_pixels"}
    rows = []
    with open(committed / "table.csv", newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames == vm.SweepRow.column_names()
        for r in reader:
            v = {k: (int(x) if k in ints else x if k in ("sweep", "parameter", "options") else float(x))
                 for k, x in r.items()}
            metrics = vm.ComparisonMetrics(**{f.name: v[f.name] for f in fields(vm.ComparisonMetrics)})
            rows.append(vm.SweepRow(v["sweep"], v["parameter"], v["value"], v["options"], v["gaussians"], metrics))
    assert len(rows) == 32 and {r.sweep for r in rows} == set(vm.SWEEPS)
    paths = vm.write_report(rows, tmp_path, width=128)
    assert paths.csv.read_bytes() == (committed / "table.csv").read_bytes()
    table = paths.markdown.read_text(encoding="utf-8")  # no probe or checks given: the table alone
    assert table == vm.sweep_markdown(rows, 128) and (committed / "table.md").read_text(encoding="utf-8").startswith(
        table)
