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


def _pytest(folder: Path, *args: str, timeout: int = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "pytest", "-p", PLUGIN, "-p", "no:cacheprovider", "-q", *args],
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
