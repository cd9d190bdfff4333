"""`splatbench conform`: correct rasterizers pass, each deliberately broken one fails on its probe,
the probe scenes are well posed, and the command line reports and exits as documented."""

from __future__ import annotations

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
from splatbench.backends.conform import FAULT_CAUSE, PROBES, conform
from splatbench.backends.conform.oracle import conventions_of
from splatbench.cli import main
from tests.assertions import one_line_error
from tests.broken_backends import BUGS, dense

REPO = Path(__file__).resolve().parents[1]
APPROXIMATIONS = {p.build.__name__ for p in PROBES if p.kind == "approximation"}
SCENES = {p.build.__name__: p.build for p in PROBES}


# ----------------------------------------------------------------------------
# The probe scenes are well posed
# ----------------------------------------------------------------------------

def _per_pixel(scene, **conv):
    """Per pixel and Gaussian (depth order): Mahalanobis d^2, raw alpha o exp(-d^2 / 2), and opacity."""
    c = scene.camera
    proj = reference.project(scene.means, scene.log_scales, scene.quats, scene.opacity_logits, c.K,
                             c.world_to_camera, c.width, c.height, near=c.near, far=c.far, **conv)
    vis = np.flatnonzero(proj.visible)
    vis = vis[np.argsort(proj.depths[vis], kind="stable")]
    jj, ii = np.meshgrid(np.arange(c.width) + 0.5, np.arange(c.height) + 0.5)
    dx = jj.reshape(-1, 1) - proj.means2d[vis, 0]
    dy = ii.reshape(-1, 1) - proj.means2d[vis, 1]
    A, B, C = proj.conics[vis].T
    d2 = A * dx * dx + C * dy * dy + 2 * B * dx * dy
    return d2, proj.opacities[vis] * np.exp(-d2 / 2)


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


@pytest.mark.parametrize("bug", sorted(BUGS))
def test_each_broken_backend_fails_on_its_probe(bug):
    probe, what = BUGS[bug]
    report = conform(dense(bug))
    assert probe in report.failed, f"{bug} ({what}) passed {probe}; failed: {report.failed}"
    result = next(r for r in report.results if r.name == probe)
    assert result.cause and result.detail  # named and explained
    if result.deviation is not None:
        assert result.deviation > result.tolerance


def test_bugs_of_one_backward_pass_fail_only_gradient_probes():
    """The backward-only bugs leave every forward probe passing, and the halved off-diagonal conic
    gradient fails conic_B while conic_A and conic_C pass: the direction probes isolate the term."""
    forward = {p.name for p in PROBES if p.kind in ("forward", "approximation")}
    for bug in ("alpha_clamp_0999_bwd", "conic_b_grad_half", "sh_dir_detached", "opacity_grad_at_zero"):
        assert not forward & set(conform(dense(bug)).failed), bug
    failed = set(conform(dense("conic_b_grad_half")).failed)
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

    # A backend that cannot render a plain scene is stopped before the probes, in one line
    # (not 33 failures each blamed on its probe's convention).
    expect = {raises: "backend raised RuntimeError: kernel launch failed", wrong_shape: "rgb: shape [24, 16, 3]",
              nan: "non-finite rgb at pixel (row 0, col 0)",
              two_outputs: "backend returned a tuple of 2, expected the 3 outputs (rgb, alpha, depth)"}
    for fn, message in expect.items():
        msg = one_line_error(lambda: conform(_wrap(fn), probes=("intrinsics",)), "cannot be checked", message)
        assert "docs/backends.md" in msg

    # One that fails only on some probe's scene fails that probe, with the fault as its cause.
    def raises_on_six(means, *args, **kwargs):
        if means.shape[0] >= 6:  # the SH probes; the first probe (depth_order) has 4
            raise RuntimeError("too many Gaussians")
        return dense()(means, *args, **kwargs)

    report = conform(_wrap(raises_on_six))
    faulted = [r for r in report.results if r.detail.startswith("backend raised RuntimeError: too many Gaussians")]
    assert faulted and all(r.status == "fail" and r.cause == FAULT_CAUSE for r in faulted)


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
    """A user's rasterizer outside the repository: splatbench's, fed quaternions as (x, y, z, w)."""
    import splatbench


    def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        rgb, alpha, depth, _ = splatbench.rasterize(means, log_scales, quats[:, [1, 2, 3, 0]], opacity_logits, sh,
                                                    camera, sh_degree=sh_degree, background=background)
        return rgb, alpha, depth
''')


def test_cli_fails_a_broken_backend_given_as_module_function_from_outside(tmp_path):
    (tmp_path / "my_rasterizer.py").write_text(OUTSIDE)
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    cmd = [str(Path(sys.executable).parent / "splatbench"), "conform", "my_rasterizer:render", "--json",
           "--probe", "quat_order", "--probe", "pixel_centre", "--probe", "grad_quats"]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert proc.returncode == 1, proc.stderr
    out = json.loads(proc.stdout)
    status = {p["name"]: p["status"] for p in out["probes"]}
    assert status == {"quat_order": "fail", "pixel_centre": "pass", "grad_quats": "fail"}
    assert out["passed"] is False and out["backend"] == "my_rasterizer:render"
    failed = next(p for p in out["probes"] if p["name"] == "quat_order")
    assert "(x, y, z, w)" in failed["cause"] and failed["deviation"] > failed["tolerance"]


def test_cli_table_exit_codes_and_bad_specs():
    runner = CliRunner()
    ok = runner.invoke(main, ["conform", "torch", "--probe", "depth_order", "--probe", "radius"])
    assert ok.exit_code == 0, ok.output
    assert "torch: 2 pass, 0 warn, 0 fail, 0 skip" in ok.output
    for spec, message in (("no_such_module_xyz:render", "cannot import module 'no_such_module_xyz'"),
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
    assert result.output.rstrip().endswith("failed: depth_order")
