"""splatbench's own regression snapshot: the built-in ``drjit`` rasterizer on the ``parity`` scene
set (three parity scenes: standard, needles and tiny Gaussians, SH degrees 0, 3 and 1, black and
coloured backgrounds), taken by `splatbench snapshot` into tests/golden (`make golden`, never run
by the tests) and checked here by `splatbench check`, the tool splatbench offers for any rasterizer.

The tolerances are check's, derived (`splatbench.regress.measure`): outputs within twice the
float32 forward bound outside the oracle's boundary band, gradients within twice the float32
gradient bound outside the gradient band. A change of the maths moves a gradient by far more
(test_a_gradient_bug_fails_against_the_golden_snapshot). Retake the snapshot only after an
intended change of the maths, and say why in the commit.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from splatbench.cli import main
from splatbench.regress import check, read_snapshot

GOLDEN = Path(__file__).parent / "golden"


def test_the_golden_snapshot_is_the_parity_set_of_the_drjit_rasterizer():
    snap = read_snapshot(GOLDEN)  # verifies format, scene-set version and the scenes' names
    assert snap.manifest["scene_set"] == "parity"
    assert snap.manifest["backend"]["name"] == "drjit"
    assert [s["name"] for s in snap.manifest["scenes"]] == ["parity-0-standard-d0", "parity-7-needles-d3",
                                                            "parity-13-tiny-d1"]
    assert all(len(s["quantities"]) == 8 for s in snap.manifest["scenes"])  # rgb, alpha, depth, 5 gradients


def test_the_rasterizer_matches_its_golden_snapshot():
    report = check("drjit", GOLDEN, diagnose=False)
    assert not report.notes, report.notes  # the declared conventions are those of the snapshot
    assert len(report.results) == 3 * 8
    assert report.exit_code == 0 and not report.changed, "\n".join(r.line() for r in report.changed)


def test_make_golden_is_the_snapshot_command(tmp_path):
    """`make golden` runs `splatbench snapshot`, and what it takes passes `check` at once."""
    makefile = (Path(__file__).parent.parent / "Makefile").read_text()
    assert "snapshot drjit --scenes parity --out tests/golden" in makefile
    out = tmp_path / "golden"
    result = CliRunner().invoke(main, ["snapshot", "drjit", "--scenes", "parity", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert check("drjit", out, diagnose=False).exit_code == 0


@pytest.mark.parametrize("bug", ["tests.gradient_bugs:conic_b_half"])
def test_a_gradient_bug_fails_against_the_golden_snapshot(bug):
    report = check(bug, GOLDEN, diagnose=False)
    assert report.exit_code == 1
    assert any(r.status == "regression" and r.quantity.startswith("grad_") for r in report.results)
