"""`splatbench snapshot` and `splatbench check` (splatbench/regress): deterministic snapshots,
derived tolerances, improvement / regression / convention-change verdicts, bad input in one line.

Most tests run on three scenes of the set (a probe scene with gradients, the depth-order probe
and a synthetic workload from a random pose) by narrowing `scene_set`, to stay quick; the must-show
command on the full set is run by hand (docs/regression.md)."""

from __future__ import annotations

import json
import shutil
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import splatbench  # noqa: F401 - configures libLLVM before drjit loads
from splatbench.cli import main
from splatbench.errors import InputError
from splatbench.regress import check, snapshot
from splatbench.regress import files as regress_files
from splatbench.regress import snapshot_scenes as regress_scenes
from splatbench.regress.files import MANIFEST, read_snapshot, write_npz
from tests.gradient_bugs import conic_b_half

SCENE_SET = regress_scenes.scene_set  # the whole set (the fixture `few_scenes` narrows the module's while it is active)
FEW = ("probe-depth_order", "probe-gradients", "synthetic-300-64x64-s1-posed")  # in the set's order


@pytest.fixture(scope="module")
def few_scenes():
    full = regress_scenes.scene_set

    def narrowed(name="full", only=None):
        return [s for s in full(name, only) if s.name in FEW]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(regress_scenes, "scene_set", narrowed)
        mp.setattr(regress_files, "scene_set", narrowed)
        yield


@pytest.fixture(scope="module")
def torch_snapshot(tmp_path_factory, few_scenes):
    out = tmp_path_factory.mktemp("snap") / "torch"
    snapshot("torch", out, scenes="small")
    return out


def test_a_snapshot_is_deterministic_and_documented(torch_snapshot, tmp_path):
    import torch

    threads, deterministic = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    again = snapshot("torch", tmp_path / "again", scenes="small")
    # one torch thread and deterministic algorithms only while it renders: the caller's settings come back
    assert (torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()) == (threads, deterministic)
    files = sorted(p.relative_to(torch_snapshot) for p in torch_snapshot.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for f in files:  # byte for byte: no timestamps, sorted members
        assert (torch_snapshot / f).read_bytes() == (again / f).read_bytes(), f
    manifest = json.loads((torch_snapshot / MANIFEST).read_text())
    assert manifest["scene_set_version"] == regress_scenes.SCENE_SET_VERSION
    assert [s["name"] for s in manifest["scenes"]] == list(FEW)
    assert manifest["backend"]["name"] == "torch" and "torch" in manifest["versions"]
    # plain npy members: numpy reads them without pickle
    with np.load(torch_snapshot / "scenes" / "probe-gradients.npz", allow_pickle=False) as z:
        assert {"rgb", "alpha", "depth", "grad_means", "grad_sh", "band", "grad_band"} <= set(z.files)


def test_check_of_the_same_code_and_of_another_correct_backend_is_unchanged(torch_snapshot):
    same = check("torch", torch_snapshot, diagnose=False)
    assert same.exit_code == 0 and same.status == "unchanged"
    assert all(r.difference == 0.0 for r in same.results)  # the same float32 code: bit for bit
    other = check("drjit", torch_snapshot, diagnose=False)  # another float32 rasterizer: what the band allows
    assert other.exit_code == 0, [r.line() for r in other.changed]
    assert len(other.results) == 3 * 8


def test_a_gradient_bug_is_a_regression_named_and_moved_away_from_the_oracle(torch_snapshot):
    report = check(conic_b_half, torch_snapshot)
    assert report.exit_code == 1 and report.status == "regressed"
    bad = {r.quantity for r in report.results if r.status == "regression"}
    assert {"grad_log_scales", "grad_quats"} <= bad
    assert not bad & {"rgb", "alpha", "depth", "grad_sh", "grad_opacity_logits"}  # the forward is the same
    r = next(r for r in report.results if r.status == "regression" and r.quantity == "grad_log_scales")
    assert r.oracle_now > r.oracle_before + 1 and "moved away from the oracle" in r.line()
    assert "conform: defect conic_B" in r.cause


def test_moving_toward_the_oracle_is_an_improvement_and_passes(tmp_path, few_scenes):
    snap = snapshot(conic_b_half, tmp_path / "buggy", scenes="small")
    report = check("torch", snap, diagnose=False)
    assert report.exit_code == 0 and report.status == "improved"
    better = [r for r in report.results if r.status == "improvement"]
    assert {r.quantity for r in better} >= {"grad_log_scales", "grad_quats"}
    assert all(r.oracle_now < r.oracle_before for r in better)


@pytest.mark.parametrize("damage, message", [
    ("missing", "no snapshot folder"),
    ("tampered_npz", "SHA-256 is not the one snapshot.json records"),
    ("shape", "has shape"),
    ("version", "scene set version 0"),
    ("json", "not valid JSON"),
    ("path", "names the file"),
    ("selected", "are not those of set"),  # a record dropped from the manifest is not a selection
    ("manifest_file", "is a file, not a snapshot folder; give the folder holding it: --against "),
    ("other_file", "is a file, not a snapshot folder; give the folder `splatbench snapshot BACKEND --out DIR` wrote"),
])
def test_bad_snapshots_are_one_line_never_a_pass(torch_snapshot, tmp_path, damage, message):
    snap = tmp_path / "s"
    shutil.copytree(torch_snapshot, snap)
    manifest = json.loads((snap / MANIFEST).read_text())
    if damage == "missing":
        shutil.rmtree(snap)
    elif damage == "tampered_npz":
        path = snap / "scenes" / "probe-gradients.npz"
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["grad_means"] = arrays["grad_means"] * 1.01
        write_npz(path, arrays)
    elif damage == "shape":  # a consistent file (re-hashed) whose counts disagree with the scene
        path = snap / "scenes" / "probe-gradients.npz"
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["grad_means"] = arrays["grad_means"][:-1]
        write_npz(path, arrays)
        manifest["scenes"][1]["sha256"] = regress_files.sha256(path)
        (snap / MANIFEST).write_text(json.dumps(manifest))
    elif damage == "version":
        manifest["scene_set_version"] = 0
        (snap / MANIFEST).write_text(json.dumps(manifest))
    elif damage == "json":
        (snap / MANIFEST).write_text("{not json")
    elif damage == "path":
        manifest["scenes"][0]["file"] = "../../etc/passwd"
        (snap / MANIFEST).write_text(json.dumps(manifest))
    elif damage == "selected":
        manifest["selected"] = [s["name"] for s in manifest["scenes"][:-1]]
        (snap / MANIFEST).write_text(json.dumps(manifest))
    elif damage == "manifest_file":  # the manifest instead of its folder: the hint is its folder
        snap = snap / MANIFEST
    elif damage == "other_file":  # a file is never a snapshot, nor can `snapshot --out FILE` make one there
        snap = snap / "scenes" / "probe-gradients.npz"
    out = CliRunner().invoke(main, ["check", "torch", "--against", str(snap), "--quiet"])
    lines = [x for x in out.output.splitlines() if x.strip()]
    assert out.exit_code == 2 and len(lines) == 1 and lines[0].startswith("splatbench: error: "), out.output
    assert message in lines[0], lines[0]
    if damage == "manifest_file":
        assert lines[0].endswith(f"--against {snap.parent}"), lines[0]


def test_a_backend_that_raises_fails_every_quantity_said_once_per_scene(torch_snapshot, tmp_path, monkeypatch):
    (tmp_path / "crashy_check_backend.py").write_text(textwrap.dedent('''
        def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
            if means.shape[0] > 10 ** 6:
                scale = 1.0
            return scale * means
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    out = CliRunner().invoke(main, ["check", "crashy_check_backend:render", "--against", str(torch_snapshot), "--quiet",
                                    "--no-diagnose"])
    assert out.exit_code == 1 and "Traceback" not in out.output, out.output
    assert "backend raised UnboundLocalError" in out.output and "crashy_check_backend.py:5 in render)" in out.output
    # every quantity fails (the summary counts them), but the table says the exception once per scene
    raised = [line for line in out.output.splitlines() if "backend raised UnboundLocalError" in line]
    assert [line.split()[0] for line in raised] == list(FEW), out.output
    assert all("(8 quantities): regression: the backend fails on this scene" in line for line in raised)
    assert f"{3 * 8} regressed" in out.output.splitlines()[-1]
    taken = CliRunner().invoke(main, ["snapshot", "crashy_check_backend:render", "--out", str(tmp_path / "x"), "--quiet"])
    lines = [x for x in taken.output.splitlines() if x.strip()]
    assert taken.exit_code == 2 and len(lines) == 1 and "fails on scene" in lines[0], taken.output
    nope = CliRunner().invoke(main, ["check", "no_such_module_xyz:render", "--against", str(torch_snapshot)])
    assert nope.exit_code == 2 and "cannot import module" in nope.output


def test_cli_json_and_images(torch_snapshot, tmp_path):
    out = CliRunner().invoke(main, ["check", "tests.gradient_bugs:conic_b_half", "--against", str(torch_snapshot),
                                    "--json", "--no-diagnose", "--save-images", str(tmp_path / "img")])
    assert out.exit_code == 1, out.output
    data = json.loads(out.output)
    assert data["status"] == "regressed" and data["summary"]["regression"] > 0
    assert {q["status"] for q in data["quantities"]} <= {"unchanged", "regression", "improvement",
                                                         "convention change"}
    assert not (tmp_path / "img").exists() or not any((tmp_path / "img").iterdir())  # no output changed


def test_a_check_failing_on_convention_changes_alone_is_not_called_regressed():
    from splatbench.regress.against_snapshot import CheckReport, QuantityResult
    from splatbench.regress.cli import format_report

    moved = QuantityResult("s", "rgb", "convention change", 1.0, 0.1)
    report = CheckReport("b", "1", "snap", "b", "small", (moved, QuantityResult("s", "alpha", "unchanged", 0.0, 0.1)))
    assert report.exit_code == 1 and report.status == "convention changed"
    assert format_report(report).splitlines()[-1].startswith("b: convention changed: 1 unchanged, 0 improved, "
                                                              "0 regressed, 1 convention changes")
    worse = CheckReport("b", "1", "snap", "b", "small", (moved, QuantityResult("s", "alpha", "regression", 1.0, 0.1)))
    assert worse.status == "regressed"


def test_rotation_gradients_of_isotropic_gaussians_are_measured_against_the_covariance_scale():
    """An isotropic Gaussian's quats gradient is exactly 0 (float32 leaves noise of the covariance's
    scale): inside the gradient band and out, it is measured against log_scales' gradient, so noise
    reads as noise (a full drjit check against a torch snapshot hit this on garden)."""
    from splatbench.regress.measure import Band, gradient_difference

    n = 4
    band = Band(np.zeros((2, 2), bool), np.zeros((2, 2)), np.array([False, True, False, True]), np.zeros((2, 2)))
    ref = {"grad_quats": np.zeros((n, 4)), "grad_log_scales": np.ones((n, 3))}
    noise = np.full((n, 4), 1e-9)
    rest, inside, _ = gradient_difference("grad_quats", noise, ref["grad_quats"], band, ref)
    assert rest < 1e-8 and inside < 1e-8
    rest, inside, _ = gradient_difference("grad_means", noise[:, :3], np.zeros((n, 3)), band, ref)
    assert rest == inside == float("inf")  # other groups have no floor: a gradient where there was none


def test_a_changed_declaration_with_unchanged_code_fails_the_check_as_a_convention_change(torch_snapshot, tmp_path,
                                                                                          monkeypatch):
    """The same code declaring another alpha_max than at the snapshot: no quantity moves, and check
    exits 1 (docs/regression.md: a convention change fails) naming the declaration, not 0."""
    (tmp_path / "redeclared_backend.py").write_text(textwrap.dedent('''
        import dataclasses
        from splatbench.backends import Backend, get_backend

        def make() -> Backend:
            torch = get_backend("torch")
            return Backend(torch.fn, dataclasses.replace(torch.info, alpha_max=0.999))
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    report = check("redeclared_backend:make", torch_snapshot, diagnose=False)
    assert all(r.status == "unchanged" for r in report.results)  # the code, and so every quantity, is the same
    assert report.declared_changes == ("alpha_max 0.99 -> 0.999",)
    assert report.exit_code == 1 and report.status == "convention changed" and not report.to_dict()["passed"]
    out = CliRunner().invoke(main, ["check", "redeclared_backend:make", "--against", str(torch_snapshot), "--quiet"])
    assert out.exit_code == 1, out.output
    assert out.output.splitlines()[-1].startswith(
        "torch: convention changed: 24 unchanged, 0 improved, 0 regressed, 0 convention changes; the declared "
        "conventions changed (alpha_max 0.99 -> 0.999): take the snapshot again if that is intended"), out.output
    same = check("torch", torch_snapshot, diagnose=False)
    assert same.declared_changes == () and same.exit_code == 0


def test_snapshot_of_scenes_by_name_is_what_check_checks(few_scenes, tmp_path):
    """`snapshot --scene NAME` (repeatable, as check's): those scenes of the set in the set's order, recorded
    as selected; check checks exactly them; an unknown name is one line listing the set's names."""
    out = CliRunner().invoke(main, ["snapshot", "torch", "--out", str(tmp_path / "two"), "--scenes", "small",
                                    "--scene", FEW[2], "--scene", FEW[0], "--quiet"])
    assert out.exit_code == 0, out.output
    manifest = json.loads((tmp_path / "two" / MANIFEST).read_text())
    assert manifest["selected"] == [FEW[0], FEW[2]] == [s["name"] for s in manifest["scenes"]]
    report = check("torch", tmp_path / "two", diagnose=False)
    assert report.exit_code == 0 and {r.scene for r in report.results} == {FEW[0], FEW[2]}
    assert len(report.results) == 2 * 8
    bad = CliRunner().invoke(main, ["snapshot", "torch", "--out", str(tmp_path / "x"), "--scene", "no-such-scene"])
    lines = [x for x in bad.output.splitlines() if x.strip()]
    assert bad.exit_code == 2 and len(lines) == 1 and "'no-such-scene' is not in scene set 'full'" in lines[0]
    assert FEW[1] in lines[0] and not (tmp_path / "x").exists()
    other = CliRunner().invoke(main, ["check", "torch", "--against", str(tmp_path / "two"), "--scene", FEW[1]])
    assert other.exit_code == 2 and f"{FEW[1]!r} is not in the snapshot" in other.output


def test_the_large_scenes_are_loaded_only_when_named(monkeypatch):
    def refuse():
        raise AssertionError("loaded a large scene that was not named")

    monkeypatch.setattr(regress_scenes, "_garden", refuse)
    monkeypatch.setattr(regress_scenes, "_real_model", refuse)
    names = [s.name for s in SCENE_SET("full", only=("probe-conic", "probe-gradients"))]
    assert sorted(names) == ["probe-conic", "probe-gradients"]
    assert names == [s.name for s in SCENE_SET("small") if s.name in names]  # the set's order, not the call's
    with pytest.raises(InputError, match="'garden-view0-x0.125' is not in scene set 'small'"):
        SCENE_SET("small", only=("garden-view0-x0.125",))


def test_the_worked_example_of_the_docs_runs_as_it_says(tmp_path, monkeypatch):
    """docs/regression.md's worked example: its myrast.py as written, snapshotted, the bug it plants
    (0.9 x the opacity gradient) a regression of grad_opacity_logits alone named by conform; and its
    advice on the camera's read-only matrix holds (torch.tensor copies silently, torch.as_tensor warns)."""
    import re
    import warnings

    import torch

    from splatbench.cameras import Camera

    doc = (Path(__file__).resolve().parents[1] / "docs" / "regression.md").read_text()
    section = doc[doc.index("## A worked example"):doc.index("## Adopting it")]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    bug = "opacity_logits = 0.9 * opacity_logits + 0.1 * opacity_logits.detach()"
    assert bug in " ".join(section.split()).replace("` ", "").replace("`", "")  # the docs plant this line
    (tmp_path / "myrast.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    snap = snapshot("myrast:render", tmp_path / "snapshots", scenes="small",
                    only=("probe-basic_centred", "probe-gradients"))
    assert check("myrast:render", snap, diagnose=False).status == "unchanged"
    (tmp_path / "myrast.py").write_text(code.replace("    return _torch(", f"    {bug}\n    return _torch(", 1))
    monkeypatch.delitem(sys.modules, "myrast")  # the edited file, imported again
    report = check("myrast:render", snap)
    assert report.exit_code == 1 and {(r.quantity, r.status) for r in report.changed} == {
        ("grad_opacity_logits", "regression")}
    assert "conform: defect grad_opacity_logits" in report.conform
    cam = Camera.look_at(eye=[0, 0, -3], target=[0, 0, 0], up=[0, -1, 0], width=8, height=8, fov_x_deg=60)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        torch.tensor(cam.world_to_camera)
        with pytest.raises(UserWarning, match="not writable"):
            torch.as_tensor(cam.world_to_camera)
