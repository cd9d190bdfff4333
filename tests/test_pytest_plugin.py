"""The splatbench pytest plugin (splatbench/regress/pytest_plugin.py), run as a user runs it: pytest
in a fresh folder, the plugin named with -p (a source checkout; an installed splatbench registers it
as the pytest11 entry point ``splatbench``)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PLUGIN = "splatbench.regress.pytest_plugin"


def plugin_args() -> list[str]:
    """``-p PLUGIN`` where splatbench is not installed with its pytest11 entry point (a bare source
    tree on PYTHONPATH); nothing where it is (`make setup`'s editable install, as CI runs): pytest
    then loads the entry point itself, and naming the module again would register it twice."""
    from importlib.metadata import entry_points

    installed = any(ep.name == "splatbench" and ep.value == PLUGIN for ep in entry_points(group="pytest11"))
    return [] if installed else ["-p", PLUGIN]


def _pytest(folder: Path, *args: str, timeout: int = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "pytest", *plugin_args(), "-p", "no:cacheprovider", "-q", *args],
                          cwd=folder, env=env, capture_output=True, text=True, timeout=timeout)


def test_inert_without_its_option(tmp_path):
    """Loaded but not asked: it collects nothing and imports nothing heavy (the project's own suite
    neither slows down nor changes)."""
    (tmp_path / "test_mine.py").write_text(
        "import sys\n\ndef test_nothing_heavy_loaded():\n"
        "    assert not {'torch', 'drjit', 'splatbench.conform', 'splatbench.backends'} & set(sys.modules)\n")
    out = _pytest(tmp_path)
    assert out.returncode == 0 and "1 passed" in out.stdout, out.stdout + out.stderr
    bad = _pytest(tmp_path, "--splatbench-against", str(tmp_path))
    assert bad.returncode == 4 and "--splatbench-against needs --splatbench-backend" in bad.stderr


def test_drjit_passes_every_probe_and_a_one_bug_backend_fails_one_item_per_probe_that_catches_it(tmp_path):
    from splatbench.conform import conform
    from tests.broken_backends import dense

    good = _pytest(tmp_path, "--splatbench-backend", "drjit", "-rA")
    assert good.returncode == 0, good.stdout[-3000:]
    assert re.search(r"\b36 passed\b", good.stdout), good.stdout[-2000:]
    assert "PASSED splatbench::conform::conic_B" in good.stdout

    junit = tmp_path / "junit.xml"
    bad = _pytest(tmp_path, "--splatbench-backend", "tests.broken_backends:dense_conic_b_grad_half",
                  f"--junitxml={junit}")
    assert bad.returncode == 1, bad.stdout[-3000:]
    failed = set(re.findall(r"^FAILED splatbench::conform::(\w+)", bad.stdout, re.M))
    report = conform(dense("conic_b_grad_half"))
    assert failed == {r.name for r in report.results if r.status in ("fail", "explained")} and "conic_B" in failed
    root = next(line for line in bad.stdout.splitlines() if line.startswith("conic_B: "))
    assert "the gradient of conic term B (xy) is wrong" in root
    assert all(f"grad_{g}: follows from conic_B" in bad.stdout for g in ("means", "quats") if f"grad_{g}" in failed)
    assert junit.read_text().count("<failure") == len(failed)
    # every JUnit item has a class name (the CI's test view groups by it) and the probe as its name
    cases = re.findall(r'<testcase classname="([^"]*)" name="([^"]*)"', junit.read_text())
    assert len(cases) == 36 and {c for c, _ in cases} == {"splatbench.conform"}, cases[:3]
    assert {n for _, n in cases} >= failed


def test_bad_input_is_a_one_line_usage_error(tmp_path):
    for args, message in ((("--splatbench-backend", "no_such_module_xyz:render"), "cannot import module"),
                          (("--splatbench-backend", "torch", "--splatbench-against", str(tmp_path / "none")),
                           "no snapshot folder")):
        out = _pytest(tmp_path, *args)
        assert out.returncode == 4, out.stdout + out.stderr
        lines = [x for x in out.stderr.splitlines() if x.strip()]
        assert len(lines) == 1 and message in lines[0] and "Traceback" not in out.stderr, out.stderr


def test_a_builtin_by_path_is_its_factory_and_an_uncallable_spec_is_one_usage_line(tmp_path):
    """The documented path of a built-in (a factory annotated -> Backend) loads as its name does
    (configure succeeds: --collect-only lists every probe); a function whose signature cannot take
    conform's call is one usage line at configure (exit 4), never a traceback per item."""
    from splatbench.conform.probes import PROBES

    spec = "splatbench.backends.builtins.drjit_backend:make_drjit_backend"
    ok = _pytest(tmp_path, "--splatbench-backend", spec, "--collect-only")
    assert ok.returncode == 0, ok.stdout[-2000:] + ok.stderr
    listed = set(re.findall(r"^splatbench::conform::(\w+)$", ok.stdout, re.M))
    assert listed == {p.name for p in PROBES}, ok.stdout[-2000:]
    # collected as pytest collects any test: counted, not "no tests collected"
    assert f"{len(PROBES)} tests collected" in ok.stdout and "no tests collected" not in ok.stdout, ok.stdout[-500:]
    (tmp_path / "wrong_sig.py").write_text("def render(means, camera):\n    return None\n")
    bad = _pytest(tmp_path, "--splatbench-backend", "wrong_sig:render")
    lines = [x for x in bad.stderr.splitlines() if x.strip()]
    assert bad.returncode == 4 and len(lines) == 1 and "cannot be called as fn(" in lines[0], bad.stdout + bad.stderr
    assert "Traceback" not in bad.stdout + bad.stderr


def test_a_tampered_snapshot_is_one_usage_line_at_configure(tmp_path):
    """One byte changed in one scene file: the plugin verifies every file's SHA-256 once when it
    configures and stops with pytest's usage error (exit 4), before collecting or running an item."""
    from splatbench.regress import snapshot

    snap = snapshot("torch", tmp_path / "snap", scenes="small")
    path = sorted((snap / "scenes").glob("*.npz"))[-1]
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))
    out = _pytest(tmp_path, "--splatbench-backend", "torch", "--splatbench-against", str(snap))
    lines = [x for x in out.stderr.splitlines() if x.strip()]
    assert out.returncode == 4, out.stdout[-2000:] + out.stderr
    assert len(lines) == 1 and path.name in lines[0] and "SHA-256" in lines[0], out.stderr
    assert "Traceback" not in out.stdout + out.stderr and "passed" not in out.stdout and "failed" not in out.stdout


def test_node_ids_from_a_subfolder_and_the_path_hint_are_pytests(tmp_path):
    """Run from a folder below the rootdir (a project's tests/), the items read ``splatbench::...``
    (not ``..::splatbench/...``); a module that is not on the path gets pytest's ways to put it
    there, not the splatbench command's."""
    (tmp_path / "pyproject.toml").write_text("[tool.pytest.ini_options]\n")
    (tmp_path / "tests").mkdir()
    out = _pytest(tmp_path / "tests", "--splatbench-backend", "torch", "-k", "conic_B or basic_centred", "-rA")
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr
    assert re.findall(r"^PASSED (\S+)$", out.stdout, re.M) == ["splatbench::conform::basic_centred",
                                                              "splatbench::conform::conic_B"], out.stdout[-2000:]
    (tmp_path / "mine.py").write_text("def render(means, camera):\n    return None\n")  # imported, it is refused
    gone = _pytest(tmp_path / "tests", "--splatbench-backend", "mine:render")
    lines = [x for x in gone.stderr.splitlines() if x.strip()]
    assert gone.returncode == 4 and len(lines) == 1 and "cannot import module 'mine'" in lines[0], gone.stderr
    assert "pytest's path: pythonpath = " in lines[0] and "splatbench ..." not in lines[0], lines[0]
    (tmp_path / "pyproject.toml").write_text('[tool.pytest.ini_options]\npythonpath = ["."]\n')  # relative to the rootdir
    found = _pytest(tmp_path / "tests", "--splatbench-backend", "mine:render", "--collect-only")
    assert found.returncode == 4 and "cannot be called as fn(" in found.stderr, found.stderr  # imported: the hint works


def test_a_failing_scene_fixture_is_its_one_line_and_a_changed_declaration_fails_an_item(tmp_path):
    """splatbench_scene on a gradient bug: the failure is one line naming the gradient (no traceback,
    no array dumps), as is a backend that raises. A snapshot's check adds the item
    ``declared_conventions``, which fails when only the declaration changed (as `check` exits 1), and
    its JUnit items' class name is the scene's."""
    from splatbench.regress import snapshot

    (tmp_path / "test_mine.py").write_text(textwrap.dedent('''
        import numpy as np
        from splatbench import Camera

        def scene():
            rng = np.random.default_rng(0)
            n = 12
            return (rng.normal(0, 0.4, (n, 3)), np.full((n, 3), -2.0), np.tile([1.0, 0, 0, 0], (n, 1)), np.zeros(n),
                    rng.normal(0, 0.3, (n, 1, 3)),
                    Camera.look_at(eye=[0.3, 0.2, -3], target=[0, 0, 0], up=[0, -1, 0], width=24, height=16,
                                   fov_x_deg=50))

        def test_bug(splatbench_scene):
            splatbench_scene(*scene(), backend="tests.gradient_bugs:conic_b_half")

        def raising(means, *args, **kwargs):
            raise RuntimeError("no kernel for this")

        def test_raises(splatbench_scene):
            splatbench_scene(*scene(), backend=raising)

        def test_fine(splatbench_scene):
            splatbench_scene(*scene(), backend="torch")
    '''))
    out = _pytest(tmp_path, "test_mine.py")
    assert out.returncode == 1 and "1 passed" in out.stdout and "2 failed" in out.stdout, out.stdout[-3000:]
    failures = out.stdout[out.stdout.index("= FAILURES ="):out.stdout.index("short test summary")]
    body = [line for line in failures.splitlines()[1:] if line.strip() and not line.startswith(("_", "="))]
    assert len(body) == 2, failures
    assert re.fullmatch(r"torch\[conic_b_half\]: grad_\w+: relative L2 .* bound .*", body[0]), body
    assert body[1].startswith("splatbench_scene: backend raised RuntimeError: no kernel for this"), body
    assert "Traceback" not in out.stdout and "array(" not in out.stdout and "def check_scene" not in out.stdout

    snap = snapshot("torch", tmp_path / "snap", scenes="small", only=("probe-conic",))
    (tmp_path / "redeclared.py").write_text(textwrap.dedent('''
        import dataclasses
        from splatbench.backends import Backend, get_backend

        def make() -> Backend:
            torch = get_backend("torch")
            return Backend(torch.fn, dataclasses.replace(torch.info, alpha_max=0.999))
    '''))
    junit = tmp_path / "junit.xml"
    args = ("--splatbench-against", str(snap), "-k", "check and not conform and not test_", f"--junitxml={junit}", "-rA")
    same = _pytest(tmp_path, "--splatbench-backend", "torch", *args)
    assert same.returncode == 0 and "9 passed" in same.stdout, same.stdout[-2000:]
    assert "PASSED splatbench::check::declared_conventions" in same.stdout
    cases = re.findall(r'<testcase classname="([^"]*)" name="([^"]*)"', junit.read_text())
    assert ("splatbench.check.probe-conic", "grad_means") in cases and ("splatbench.check", "declared_conventions") \
        in cases and all(c for c, _ in cases), cases
    moved = _pytest(tmp_path, "--splatbench-backend", "redeclared:make", *args)
    assert moved.returncode == 1 and "1 failed, 8 passed" in moved.stdout, moved.stdout[-2000:]
    assert "FAILED splatbench::check::declared_conventions - " in moved.stdout
    assert ("\nthe declared conventions changed since the snapshot: alpha_max 0.99 -> 0.999; take the snapshot "
            "again if that is intended\n") in moved.stdout  # the item's failure: one line
