"""examples/downstream/, used as its maintainer would (a copy, its folder on the path): a snapshot, a
one-line change to a gradient that `splatbench check` fails naming it, and the fix reported as an
improvement toward the oracle; its own test with the plugin's fixture. The small scene set keeps it
to under two minutes on 2 loaded cores (the toy is dense: every Gaussian at every pixel)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_pytest_plugin import plugin_args  # the installed entry point, or -p on a bare tree

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "downstream"
LINE = "    B = -b / det  # the conic's off-diagonal term\n"
BUG = "    B = 0.5 * (-b / det) + 0.5 * (-b / det).detach()  # the conic's off-diagonal term\n"


def _run(folder: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": f"{folder}{os.pathsep}{REPO}"}
    return subprocess.run([sys.executable, "-m", *args], cwd=folder, env=env, capture_output=True, text=True,
                          timeout=900)


def _edit(folder: Path, old: str, new: str) -> None:
    path = folder / "toy_splat" / "rasterizer.py"
    text = path.read_text()
    assert text.count(old) == 1
    path.write_text(text.replace(old, new))


def test_the_downstream_example_catches_a_gradient_change_and_reports_its_fix(tmp_path):
    project = tmp_path / "toy"
    shutil.copytree(EXAMPLE, project, ignore=shutil.ignore_patterns("__pycache__"))
    shipped = sorted(str(p.relative_to(project)) for p in project.rglob("*") if p.is_file())
    assert (project / "pyproject.toml").is_file() and (project / ".github" / "workflows" / "splatbench.yml").is_file()
    workflow = (project / ".github" / "workflows" / "splatbench.yml").read_text()
    assert "--splatbench-backend toy_splat:render" in workflow
    # splatbench is not on PyPI: installed from its git repository; apt's lists are fetched first;
    # no snapshot is shipped, so the workflow stops on its absence in one line
    assert "pip install splatbench" not in workflow and "git+https://" in workflow
    assert workflow.index("sudo apt-get update") < workflow.index("sudo apt-get install")
    assert not (project / "snapshots").exists() and "test -f snapshots/snapshot.json" in workflow
    assert "splatbench check toy_splat:render --against snapshots" in workflow

    snap = _run(project, "splatbench", "snapshot", "toy_splat:render", "--out", "snapshots", "--scenes", "small",
                "--quiet")
    assert snap.returncode == 0, snap.stderr
    _edit(project, LINE, BUG)  # the one-line change: the same value, half the gradient of B
    # --no-diagnose: conform's naming of the cause is checked in tests/test_regress.py (it costs ~25 s)
    bad = _run(project, "splatbench", "check", "toy_splat:render", "--against", "snapshots", "--quiet",
               "--no-diagnose")
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert "REGRESSIONS" in bad.stdout and "moved away from the oracle" in bad.stdout
    regressed = [line for line in bad.stdout.splitlines() if ": regression: " in line]
    assert any("::grad_log_scales: regression" in line for line in regressed)
    assert not any("::rgb:" in line or "::grad_sh:" in line for line in regressed)  # the forward did not move

    # The buggy release was snapshotted; the fix moves toward the oracle: exit 0, reported as improvements.
    again = _run(project, "splatbench", "snapshot", "toy_splat:render", "--out", "snapshots", "--scenes", "small",
                 "--quiet")
    assert again.returncode == 0, again.stderr
    _edit(project, BUG, LINE)
    fixed = _run(project, "splatbench", "check", "toy_splat:render", "--against", "snapshots", "--quiet",
                 "--no-diagnose")
    assert fixed.returncode == 0, fixed.stdout + fixed.stderr
    assert "toy-splat: improved:" in fixed.stdout and "moved toward the oracle" in fixed.stdout
    assert "0 regressed" in fixed.stdout

    own = _run(project, "pytest", *plugin_args(), "-q", "--junitxml=splatbench.xml")  # as its CI: a JUnit file
    assert own.returncode == 0 and "1 passed" in own.stdout, own.stdout + own.stderr

    # its .gitignore: what the run left is ignored, the snapshot (to be committed) and the shipped files are not
    git = shutil.which("git")
    if git is None:
        pytest.skip("no git to read the example's .gitignore with")
    subprocess.run([git, "init", "-q"], cwd=project, check=True)
    status = subprocess.run([git, "status", "--porcelain", "--untracked-files=all", "--ignored"], cwd=project,
                            capture_output=True, text=True, check=True).stdout.splitlines()
    untracked = sorted(line[3:] for line in status if line.startswith("?? "))
    assert untracked == sorted(shipped + [str(p.relative_to(project)) for p in (project / "snapshots").rglob("*")
                                          if p.is_file()]), status
    ignored = {line[3:].split("/")[0] for line in status if line.startswith("!! ")}
    assert {"splatbench.xml", ".pytest_cache"} <= ignored, ignored
    others = ["check.json", "toy_splat.egg-info/PKG-INFO", "toy_splat/__pycache__/rasterizer.cpython-311.pyc"]
    ci = subprocess.run([git, "check-ignore", *others], cwd=project, capture_output=True, text=True)
    assert ci.stdout.split() == others, ci.stdout + ci.stderr  # the workflow's other steps, pip -e, bytecode
