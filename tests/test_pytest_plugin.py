"""The splatbench pytest plugin (splatbench/regress/pytest_plugin.py), run as a user runs it: pytest
in a fresh folder, the plugin named with -p (a source checkout; an installed splatbench registers it
as the pytest11 entry point ``splatbench``)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
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
    assert "PASSED ::splatbench/conform/conic_B" in good.stdout

    junit = tmp_path / "junit.xml"
    bad = _pytest(tmp_path, "--splatbench-backend", "tests.broken_backends:dense_conic_b_grad_half",
                  f"--junitxml={junit}")
    assert bad.returncode == 1, bad.stdout[-3000:]
    failed = set(re.findall(r"^FAILED ::splatbench/conform/(\w+)", bad.stdout, re.M))
    report = conform(dense("conic_b_grad_half"))
    assert failed == {r.name for r in report.results if r.status in ("fail", "explained")} and "conic_B" in failed
    root = next(line for line in bad.stdout.splitlines() if line.startswith("conic_B: "))
    assert "the gradient of conic term B (xy) is wrong" in root
    assert all(f"grad_{g}: follows from conic_B" in bad.stdout for g in ("means", "quats") if f"grad_{g}" in failed)
    assert junit.read_text().count("<failure") == len(failed)


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
    listed = set(re.findall(r"^::splatbench/conform/(\w+)$", ok.stdout, re.M))
    assert listed == {p.name for p in PROBES}, ok.stdout[-2000:]
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
