"""`splatbench conform`: correct rasterizers pass, each deliberately broken one fails on its probe,
the probe scenes are well posed, and the command line reports and exits as documented."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from importlib.util import find_spec
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

import reference
from splatbench.backends import Backend, BackendInfo
from splatbench.backends.base import AXIS
from splatbench.conform import FAULT_CAUSE, FAULT_DEFECT, PROBES, conform
from splatbench.conform.oracle import conventions_of
from splatbench.conform.probes import AXIS_PROBES
from splatbench.cli import main
from tests import dense_backends
from tests.assertions import one_line_error
from tests.broken_backends import BUGS, dense
from tests.dense_backends import BUGS as DENSE_BUGS

REPO = Path(__file__).resolve().parents[1]
APPROXIMATIONS = {p.build.__name__ for p in PROBES if p.kind == "approximation"}
SCENES = {p.build.__name__: p.build for p in PROBES}


# ----------------------------------------------------------------------------
# The probe scenes are well posed
# ----------------------------------------------------------------------------

def _per_pixel(scene, **conv):
    """Per pixel and Gaussian (depth order): Mahalanobis d^2 and raw alpha o exp(-d^2 / 2) (conform's own
    `_contributions` of the oracle's projection under ``conv``)."""
    from splatbench.conform.diagnose import _contributions

    c = scene.camera
    proj = reference.project(scene.means, scene.log_scales, scene.quats, scene.opacity_logits, c.K,
                             c.world_to_camera, c.width, c.height, near=c.near, far=c.far, **conv)
    return _contributions(scene, proj)


@pytest.mark.parametrize("name", sorted(set(SCENES) - APPROXIMATIONS))
def test_untested_approximations_cannot_matter(name):
    """Outside the approximation probes, the radius rule and the early stop change no pixel: the oracle
    renders the same image with 3 sigma, with no cutoff ("opacity"), and with no early stop."""
    s = SCENES[name]()
    from splatbench.backends.builtins.reference_backend import reference_render

    def render(**conv):
        out = reference_render(conv, *s.params().values(), s.camera, sh_degree=s.sh_degree, background=s.background)
        return np.concatenate([out.rgb.reshape(-1), out.alpha.reshape(-1), out.depth.reshape(-1)])

    base = render(radius="3sigma")
    for conv in ({"radius": "opacity"}, {"transmittance_min": 0.0}):
        assert np.abs(render(**conv) - base).max() <= 1e-12, (name, conv)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_no_pixel_sits_near_a_discrete_decision(name):
    """float32 and float64 must decide every pixel alike: raw alpha is at least 1e-4 (relative) from
    alpha_min and from the alpha_max clamps in use (0.99 graphdeco, 0.999 gsplat), d^2 at least 1e-3
    from the 3-sigma cutoff (9) where that decides, transmittance at least 10 % from 1e-4, colours
    at least 0.05 from the clamp at 0. float32
    perturbs alpha by at most (20 + 6 kappa) u ~ 2e-6 relative (kappa <= 10 here) and d^2 by ~1e-5,
    so the margins are 50 to 100 times that; the finite differences' step (1e-6) moves them less."""
    s = SCENES[name]()
    d2, raw = _per_pixel(s)
    for threshold in (1 / 255, 0.99, 0.999):
        assert np.abs(raw / threshold - 1).min() > 1e-4, (name, threshold)
    decides = raw >= 1 / 255  # the cutoff matters only for contributions alpha_min keeps
    assert np.abs(d2[decides] - 9).min(initial=np.inf) > 1e-3, name
    alpha = np.minimum(raw, 0.99) * (raw >= 1 / 255)
    T_next = np.cumprod(1 - alpha, axis=1)
    assert np.abs(T_next / 1e-4 - 1).min() > 0.1, name
    # The colour clamp max(SH + 0.5, 0): every channel at least 0.05 from its kink.
    dirs = s.means - reference.camera_centre(s.camera.world_to_camera)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    degree = {1: 0, 4: 1, 9: 2, 16: 3}[s.sh.shape[1]] if s.sh_degree is None else s.sh_degree
    basis = reference.sh_basis(dirs, degree)
    colour = np.einsum("nk,nkc->nc", basis, s.sh[:, :basis.shape[1]]) + 0.5
    assert np.abs(colour).min() > 0.05, name
    # The oracle's own band (reference/band.py) agrees: no pixel in it, no Gaussian in the gradient band.
    from splatbench.conform.oracle import gradient_band

    grad_band, widen = gradient_band(name, s, conventions_of(dense()))
    assert not grad_band.any() and widen == 0.0, name


def test_the_depth_probe_defeats_the_classic_wrong_sort_keys():
    """Index order, world z and a strided read of the camera points each give a different, wrong order."""
    s = SCENES["depth_order"]()
    t = s.means @ s.camera.rotation.T + s.camera.translation
    right = np.argsort(t[:, 2]).tolist()
    wrong = {"index": list(range(len(t))), "world z": np.argsort(s.means[:, 2]).tolist(),
             "strided": np.argsort(t.reshape(-1)[2:2 + len(t)]).tolist()}
    for key, order in wrong.items():
        assert order != right, key


# ----------------------------------------------------------------------------
# Correct rasterizers pass; broken ones fail on the right probe
# ----------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["drjit", "torch", "gsplat"])
def test_correct_backends_pass_every_probe(name):
    if name == "gsplat" and find_spec("gsplat") is None:
        pytest.skip("gsplat is not installed (pip install -e '.[gsplat]')")
    report = conform(name)
    assert report.passed, [(r.name, r.detail) for r in report.results if r.status == "fail"]
    assert report.counts()["pass"] == len(PROBES)  # they follow what they declare: no warnings either


def test_a_dense_renderer_following_every_convention_passes_with_warnings_only():
    """No radius cutoff, no tiles, no early stop, nothing declared: the two approximation probes warn."""
    report = conform(dense())
    assert report.passed
    warned = {r.name: r for r in report.results if r.status == "warn"}
    assert set(warned) == {"early_stop", "radius"}
    assert "transmittance_min=0" in warned["early_stop"].detail
    assert "radius=opacity" in warned["radius"].detail


def test_graphdecos_tile_granular_footprint_is_a_warning():
    """A Gaussian reaching the tiles its 3-sigma box touches, with no per-pixel cutoff (graphdeco's
    rule): beyond 3 sigma it draws in the touched tiles, not in the others; radius warns, nothing fails."""
    report = conform(dense(tile_box=True))
    assert report.passed
    radius = next(r for r in report.results if r.name == "radius")
    assert radius.status == "warn" and "match radius=opacity" in radius.detail
    assert {r.name for r in report.results if r.status == "warn"} == {"early_stop", "radius"}


def _root_causes(report) -> list[tuple[str, ...]]:
    """Each root cause a report gives, as the probes that isolate it: a diagnosed axis (its probes),
    then each defect (its probe)."""
    return [AXIS_PROBES[d.axis] for d in report.diagnosis] + [(d.probe,) for d in report.defects]


def _assert_one_root_cause(report, probe: str, what: str) -> None:
    roots = _root_causes(report)
    assert roots, f"{what}: no root cause given"
    assert probe in roots[0], f"{what}: first root cause {roots[0]}, expected {probe}; all: {roots}"
    assert len(roots) <= 2, f"{what}: {len(roots)} root causes: {roots}"
    assert not report.passed


# Two broken backends whose failure spreads to other probes, checked in the default suite; every one
# of BUGS is checked by the slow test below (each new convention costs a full set of finite
# differences, 5-30 s on 2 loaded cores).
FAST_BUGS = ("conic_b_grad_half", "tile_centre_only", "sort_camera_x")


@pytest.mark.parametrize("bug", [pytest.param(b, marks=() if b in FAST_BUGS else pytest.mark.slow)
                                 for b in sorted(BUGS)])
def test_each_broken_backend_gets_its_one_root_cause_first(bug):
    """One bug, one root cause named first (its probe, or the convention axis its probe isolates), and
    at most two root causes in all, however many probes the bug makes fail."""
    probe, what = BUGS[bug]
    report = conform(dense(bug))
    _assert_one_root_cause(report, probe, f"{bug} ({what})")
    for d in report.defects:
        r = next(r for r in report.results if r.name == d.probe)
        assert r.status == "fail" and d.cause == r.cause and r.detail
        if r.deviation is not None:
            assert r.deviation > r.tolerance
    for r in report.results:  # what a diagnosed convention explains is no longer a failure
        assert (r.status == "explained") == (r.explained_by is not None)


# The two bugs that change every probe's oracle (a full set of finite differences each) run in the slow suite.
DENSE_PARAMS = [pytest.param(b, marks=pytest.mark.slow if b in ("half_pixel", "raw_opacity") else ())
                for b in sorted(DENSE_BUGS)]


@pytest.mark.parametrize("bug", DENSE_PARAMS)
def test_a_dense_rasterizer_with_one_convention_bug_is_diagnosed(bug, monkeypatch):
    """The rasterizers a new user writes from docs/conventions.md, each with one convention bug:
    `splatbench conform X --json` names that convention, and nothing else."""
    monkeypatch.syspath_prepend(str(REPO))
    result = CliRunner().invoke(main, ["conform", f"tests.dense_backends:{bug}", "--json"])
    assert result.exit_code == 1, result.output
    out = json.loads(result.output)
    axis = DENSE_BUGS[bug][0]
    assert [d["axis"] for d in out["diagnosis"]] == [axis] and out["defects"] == [], (out["diagnosis"], out["defects"])
    assert out["diagnosis"][0]["expected"] == AXIS[axis].graphdeco
    explained = [p["name"] for p in out["probes"] if p["status"] == "explained"]
    assert explained == out["diagnosis"][0]["explains"] and explained
    assert {p["status"] for p in out["probes"]} <= {"pass", "explained"}
    assert out["version"] == "unknown"  # tests/ belongs to no installed distribution, and declares none


@pytest.mark.parametrize("bug", DENSE_PARAMS)
def test_a_backend_declaring_the_convention_it_follows_passes(bug):
    """The same rasterizers, each declaring in BackendInfo the convention it follows: every probe passes."""
    backend = dense_backends.make(bug)
    axis, _ = DENSE_BUGS[bug]
    found = {"half_pixel": "integer", "sh_origin": "world_origin", "background_added": "added", "raw_opacity": "raw"}
    declared = Backend(backend.fn, dataclasses.replace(backend.info, **{axis: found[bug]}))
    report = conform(declared)
    assert report.passed and not report.diagnosis and not report.defects
    assert report.counts()["pass"] == len(PROBES)


def test_the_vocabulary_is_checked_by_the_probes():
    """Every alternative of every axis renders in the oracle and changes some probe scene (so the
    fingerprint can find it), and each axis names the probes that isolate it."""
    from splatbench.backends.base import AXES
    from splatbench.conform.oracle import oracle

    assert set(AXIS_PROBES) == {a.name for a in AXES}
    base = BackendInfo(name="graphdeco").reference_options()
    scenes = [p for p in PROBES if p.kind in ("forward", "approximation")]
    for axis in AXES:
        for value in axis.alternatives:
            conv = {**base, axis.name: value}
            if value == "detached":  # renders alike by definition; the gradient probes tell it apart
                continue
            assert any(not np.array_equal(oracle(p.build.__name__, p.build(), conv), oracle(p.build.__name__,
                       p.build(), base)) for p in scenes), (axis.name, value)


def test_a_declared_value_outside_the_vocabulary_is_one_line():
    with pytest.raises(ValueError, match="BackendInfo.pixel_centre: 'corner' is not in the convention vocabulary"):
        BackendInfo(name="x", pixel_centre="corner")


def test_bugs_of_one_backward_pass_fail_only_gradient_probes():
    """The backward-only bugs leave every forward probe passing, and the halved off-diagonal conic
    gradient fails conic_B while conic_A and conic_C pass: the direction probes isolate the term."""
    forward = {p.name for p in PROBES if p.kind in ("forward", "approximation")}
    for bug in ("alpha_clamp_0999_bwd", "conic_b_grad_half", "sh_dir_detached", "opacity_grad_at_zero"):
        assert not forward & set(conform(dense(bug), diagnose=False).failed), bug
    failed = set(conform(dense("conic_b_grad_half"), diagnose=False).failed)
    assert "conic_B" in failed and not {"conic_A", "conic_C"} & failed


# ----------------------------------------------------------------------------
# Faults, skips and declared conventions
# ----------------------------------------------------------------------------

def _wrap(fn, **info):
    return Backend(fn, BackendInfo(name="wrapped", **info))


def test_faults_fail_the_probe_in_one_line():
    def raises(*args, **kwargs):
        raise RuntimeError("kernel launch failed\nsecond line")

    def wrong_shape(means, *args, **kwargs):
        rgb, alpha, depth = dense()(means, *args, **kwargs)
        return rgb.transpose(0, 1), alpha, depth

    def nan(*args, **kwargs):
        rgb, alpha, depth = dense()(*args, **kwargs)
        return rgb * torch.nan, alpha, depth

    def two_outputs(*args, **kwargs):
        return dense()(*args, **kwargs)[:2]

    # A backend wired up wrong (other than three outputs of the right shapes, a signature conform cannot
    # call) is stopped before the probes, in one line (not 33 failures each blamed on its probe's convention).
    def two_positional(means, camera):
        return dense()(means, camera)

    expect = {wrong_shape: "rgb: shape [24, 16, 3]",
              two_outputs: "backend returned a tuple of 2, expected the 3 outputs (rgb, alpha, depth)",
              two_positional: "its signature (means, camera) cannot be called as fn(means, log_scales"}
    for fn, message in expect.items():
        msg = one_line_error(lambda: conform(_wrap(fn), probes=("intrinsics",)), "cannot be checked", message)
        assert "docs/backends.md" in msg

    # A backend that raises, or returns NaN, on valid input has a defect: every probe still runs, each fault
    # is one defect (its exception and the last frame of its traceback), and the report fails (exit 1).
    for fn, message in ((raises, "backend raised RuntimeError: kernel launch failed (at "),
                        (nan, "non-finite rgb at pixel (row 0, col 0)")):
        report = conform(_wrap(fn), probes=("intrinsics", "depth_order", "grad_means"))
        assert not report.passed and len(report.results) == 3 and all(r.status == "fail" for r in report.results)
        assert report.defects[0].probe == "intrinsics", report.defects
        assert report.defects[0].cause.startswith(f"{FAULT_DEFECT}: {message}"), report.defects[0].cause
        assert "depth_order" in report.defects[0].follows  # the same fault: one defect
        assert all(d.cause.startswith(FAULT_DEFECT) for d in report.defects)  # NaN gradients: a fault of their own
        assert {n for d in report.defects for n in (d.probe, *d.follows)} == {"intrinsics", "depth_order", "grad_means"}
    where = conform(_wrap(raises), probes=("intrinsics",)).defects[0].cause
    assert f"test_conform.py:" in where and "in raises)" in where and "\n" not in where

    # One that fails only on some probe's scene fails that probe, with the fault as its cause.
    def raises_on_six(means, *args, **kwargs):
        if means.shape[0] >= 6:  # the SH probes; the first probe (depth_order) has 4
            raise RuntimeError("too many Gaussians")
        return dense()(means, *args, **kwargs)

    report = conform(_wrap(raises_on_six))
    faulted = [r for r in report.results if r.detail.startswith("backend raised RuntimeError: too many Gaussians")]
    assert faulted and all(r.status == "fail" and (r.cause == FAULT_CAUSE or r.cause.startswith(FAULT_DEFECT))
                           for r in faulted)
    assert [d.probe for d in report.defects if d.cause.startswith(FAULT_DEFECT)] == [faulted[0].name]


def test_an_empty_render_is_said_to_be_one():
    """A backend that draws nothing on a scene (metal-gauss culls every Gaussian whose 3-sigma radius
    reaches the image size, and the probe images are small) is told so: not "no autograd graph,
    declare gradients=False", and not only the probe's own cause."""
    def draws_nothing(means, log_scales, quats, opacity_logits, sh, camera, **kwargs):
        zeros = torch.zeros(camera.height, camera.width, dtype=means.dtype)
        return torch.zeros(camera.height, camera.width, 3, dtype=means.dtype), zeros, zeros

    report = conform(_wrap(draws_nothing), probes=("depth_order", "grad_means"), diagnose=False)
    forward, gradient = report.results
    assert forward.status == "fail" and forward.detail.startswith("the backend drew nothing (alpha 0 everywhere")
    assert gradient.status == "fail" and "drew nothing on this scene" in gradient.detail
    assert "declare gradients=False" not in gradient.detail


def test_probes_a_backend_cannot_run_are_skipped():
    report = conform(_wrap(dense().fn, gradients=False, outputs=("rgb", "alpha")),
                     probes=("expected_depth", "grad_means", "conic_B", "background"))
    assert [r.status for r in report.results] == ["skip", "skip", "skip", "pass"]


def test_declared_conventions_are_the_ones_checked():
    """gsplat's alpha_max = 0.999, declared, passes alpha_max; the same renderer declaring nothing fails it."""
    declared = _wrap(dense("alpha_clamp_0999_fwd").fn, alpha_max=0.999)
    assert conventions_of(declared)["alpha_max"] == 0.999
    # Its backward still clamps at 0.99: the forward probe passes, the gradient probe does not.
    report = conform(declared, probes=("alpha_max", "alpha_max_grad"))
    assert [r.status for r in report.results] == ["pass", "fail"]


# ----------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------

OUTSIDE = textwrap.dedent('''
    """A user's rasterizer outside the repository: splatbench's, reading quaternions as (x, y, z, w)."""
    import splatbench


    def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        rgb, alpha, depth, _ = splatbench.rasterize(means, log_scales, quats[:, [3, 0, 1, 2]], opacity_logits, sh,
                                                    camera, sh_degree=sh_degree, background=background)
        return rgb, alpha, depth
''')


def test_cli_fails_a_broken_backend_given_as_module_function_from_outside(tmp_path):
    (tmp_path / "my_rasterizer.py").write_text(OUTSIDE)
    # The folder of the user's module on PYTHONPATH, and this checkout's splatbench (not only the installed one).
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(REPO)])}
    cmd = [str(Path(sys.executable).parent / "splatbench"), "conform", "my_rasterizer:render", "--json",
           "--probe", "quat_order", "--probe", "pixel_centre", "--probe", "grad_quats"]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert proc.returncode == 1, proc.stderr
    out = json.loads(proc.stdout)
    status = {p["name"]: p["status"] for p in out["probes"]}
    # Diagnosed, not failed: the quaternion order explains both the forward and the gradient probe.
    assert status == {"quat_order": "explained", "pixel_centre": "pass", "grad_quats": "explained"}
    assert out["diagnosis"] == [{"axis": "quat_order", "expected": "wxyz", "found": "xyzw",
                                 "explains": ["quat_order", "grad_quats"], "alike": []}]
    assert out["defects"] == [] and out["passed"] is False and out["backend"] == "my_rasterizer:render"
    explained = next(p for p in out["probes"] if p["name"] == "quat_order")
    assert explained["explained_by"] == "quat_order" and explained["deviation"] > explained["tolerance"]


def test_cli_table_exit_codes_and_bad_specs():
    runner = CliRunner()
    ok = runner.invoke(main, ["conform", "torch", "--probe", "depth_order", "--probe", "radius"])
    assert ok.exit_code == 0, ok.output
    assert "torch: 2 pass, 0 explained, 0 warn, 0 fail, 0 skip" in ok.output
    for spec, message in (("no_such_module_xyz:render", "cannot import module 'no_such_module_xyz'"),
                          ("no_such_module_xyz:render", "must be on PYTHONPATH (the current folder is not"),
                          ("no-such-backend", "unknown backend 'no-such-backend'")):
        bad = runner.invoke(main, ["conform", spec])
        assert bad.exit_code == 2 and message in bad.output, bad.output
    gpu = runner.invoke(main, ["conform", "torch", "--device", "cuda"])  # the torch backend declares cpu only
    import torch  # without a GPU the cause is that (tests/test_cli_device.py), with one the backend's devices

    why = "device: backend 'torch' runs on cpu, not 'cuda'" if torch.cuda.is_available() else \
        "device: 'cuda' asked for, but torch finds no CUDA device (use cpu or auto)"
    assert gpu.exit_code == 2 and why in gpu.output
    unknown = runner.invoke(main, ["conform", "torch", "--probe", "nope"])
    assert unknown.exit_code == 2 and "probes: unknown probe 'nope'" in unknown.output
    listed = runner.invoke(main, ["conform", "drjit", "--list"])
    assert listed.exit_code == 0 and all(p.name in listed.output for p in PROBES)


def test_cli_prints_cause_and_tolerance_of_a_failure(monkeypatch):
    monkeypatch.syspath_prepend(str(REPO))
    result = CliRunner().invoke(main, ["conform", "tests.broken_backends:dense_sort_strided",
                                       "--probe", "depth_order"])
    assert result.exit_code == 1, result.output
    assert "FAIL depth_order: Gaussians are not composited in ascending camera depth" in result.output
    assert "tolerance: 3 ((2 L + 20) max|c| + 6 kappa) u" in result.output
    assert "defects: what no convention explains" in result.output
    assert result.output.rstrip().endswith("defects: depth_order")


def test_json_names_the_loaded_version_and_keeps_the_backends_prints_out(monkeypatch, tmp_path):
    """gsplat's version is the one imported; what a backend prints goes into "backend_output", not into
    the JSON stream; --save-images writes three PNGs per probe."""
    def noisy(*args, **kwargs):
        print("hello from the backend")
        os.write(2, b"native stderr\n")
        return dense_backends.correct(*args, **kwargs)

    noisy.backend_info = dense_backends.correct.info
    module = type(sys)("noisy_backend_mod")
    module.render = noisy
    monkeypatch.setitem(sys.modules, "noisy_backend_mod", module)
    result = CliRunner().invoke(main, ["conform", "noisy_backend_mod:render", "--json", "--probe", "basic_overlap",
                                       "--save-images", str(tmp_path)])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert "hello from the backend" in out["backend_output"] and "native stderr" in out["backend_output"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"basic_overlap_{k}.png" for k in
                                                          ("backend", "difference", "oracle")]
    if find_spec("gsplat") is not None:
        import gsplat

        report = conform("gsplat", probes=("basic_centred",))
        assert report.version == gsplat.__version__ and report.passed


def _ellipse(angle_deg: float, *, shift=(0.0, 0.0), size: int = 24) -> np.ndarray:
    """A render [H, W, 5] whose alpha is one anisotropic Gaussian footprint at ``angle_deg``."""
    a = np.radians(angle_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    cov = rot @ np.diag([16.0, 2.0]) @ rot.T
    ii, jj = np.mgrid[:size, :size] + 0.5
    d = np.stack([jj - size / 2 - shift[0], ii - size / 2 - shift[1]], -1)
    out = np.zeros((size, size, 5))
    out[..., 3] = 0.9 * np.exp(-0.5 * np.einsum("hwi,ij,hwj->hw", d, np.linalg.inv(cov), d))
    return out


def test_what_differs_is_said_in_words():
    """The evidence behind "unexplained: ...": a mirrored ellipse, a shifted one, an empty render."""
    from splatbench.conform.evidence import coverage, describe, undrawn

    ref = _ellipse(30)
    said = describe(_ellipse(-30), ref, True)
    assert "orientation -30 deg, oracle 30 deg (mirrored)" in said and "centroid" not in said, said
    said = describe(_ellipse(30, shift=(0.5, 0.0)), ref, True)
    assert "centroid shifted by (+0.50, " in said and "orientation" not in said, said
    empty = np.zeros_like(ref)
    assert undrawn(empty, ref, True) and not undrawn(_ellipse(30, shift=(0.5, 0.0)), ref, True)
    want, have = coverage(empty, ref, True)
    assert want > 0 and have == 0


def test_scenes_drawn_empty_are_one_defect_of_their_own():
    """A backend that culls every scene of two Gaussians or more (a rule outside the vocabulary, like
    metal-gauss's cull of Gaussians large on screen): one defect saying nothing is drawn, not a cause
    of the probe that happens to come first (depth_order)."""
    from splatbench.conform import UNDRAWN_CAUSE

    def culls_pairs(means, log_scales, quats, opacity_logits, sh, camera, **kwargs):
        rgb, alpha, depth = dense().fn(means, log_scales, quats, opacity_logits, sh, camera, **kwargs)
        keep = float(means.shape[0] < 2)
        return rgb * keep, alpha * keep, depth * keep

    report = conform(_wrap(culls_pairs), probes=("basic_centred", "depth_order", "quat_order"))
    assert not report.diagnosis and len(report.defects) == 1, report.defects
    d = report.defects[0]
    assert d.probe == "depth_order" and d.cause.startswith(UNDRAWN_CAUSE) and d.follows == ("quat_order",)
    assert "draws 0 of the" in d.cause
    assert next(r for r in report.results if r.name == "depth_order").cause == d.cause


# LiteSplat's design (reports/conform_public/litesplat): a dense renderer differing from graphdeco on
# five approximations at once, none of which alone (or in pairs) makes a basic probe pass.
DENSE_DESIGN = dict(eps2d=0.0, jacobian_clamp="none", alpha_max=1.0, alpha_min=0.0, radius="none",
                    transmittance_min=0.0, sort_key="distance")


@pytest.mark.slow  # the greedy step renders a few hundred tiny oracle scenes: ~15 s on 2 loaded cores
def test_several_conventions_at_once_are_found_when_nothing_is_declared():
    """The greedy multi-axis step: the oracle itself under DENSE_DESIGN, declaring nothing, is diagnosed
    with those conventions (alpha_max 1 and 0.999 alike on the probes), and no defect."""
    from splatbench.backends.builtins.reference_backend import reference_render

    design = BackendInfo(name="design", **DENSE_DESIGN)

    def fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        out = reference_render(design, means, log_scales, quats, opacity_logits, sh, camera,
                               sh_degree=sh_degree, background=background)
        return tuple(torch.from_numpy(np.asarray(x, np.float32)) for x in (out.rgb, out.alpha, out.depth))

    probes = ("basic_centred", "basic_overlap", "basic_offaxis", "depth_order", "eps2d", "jacobian_clamp",
              "alpha_max", "alpha_min", "early_stop", "radius")
    report = conform(_wrap(fn, gradients=False), probes=probes)
    found = {d.axis: (d.found, *d.alike) for d in report.diagnosis}
    assert not report.defects and not report.failed, (found, report.defects)
    for axis in ("eps2d", "jacobian_clamp", "alpha_min", "sort_key"):
        assert found[axis][0] == DENSE_DESIGN[axis], (axis, found)
    assert 1.0 in found["alpha_max"], found


def test_cli_reports_a_backend_that_raises_on_valid_input_as_a_defect(tmp_path, monkeypatch):
    """A third-party rasterizer raising UnboundLocalError on conform's plain preflight scene (as a real torch
    path from PyPI does) is a finding about the backend: exit 1, every probe run, the exception and its
    place named in one line; exit 2 stays for what the user got wrong (here: a module that does not import)."""
    (tmp_path / "crashy.py").write_text(textwrap.dedent('''
        def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
            if means.shape[0] > 100:
                scale = 1.0
            return scale * means
    '''))
    (tmp_path / "broken_import.py").write_text("import no_such_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    runner = CliRunner()
    result = runner.invoke(main, ["conform", "crashy:render", "--probe", "basic_centred", "--probe", "depth_order"])
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    line = next(x for x in result.output.splitlines() if x.startswith("  basic_centred: "))
    assert "backend raised UnboundLocalError" in line and "crashy.py:5 in render)" in line, line
    assert "also fails because of it: depth_order" in line
    bad = runner.invoke(main, ["conform", "broken_import:render"])
    assert bad.exit_code == 2 and "cannot import module" in bad.output, bad.output
