"""`splatbench snapshot` and `splatbench check`: regression-test a backend against its own past.

    from splatbench.regress import snapshot, check
    snapshot("mypkg.rast:render", "snap/")          # outputs and gradients on a versioned scene set
    report = check("mypkg.rast:render", "snap/")    # the same quantities now, against the snapshot
    report.status, report.exit_code, report.changed # "unchanged" / "improved" / "regressed"; 0 or 1

A snapshot (`files`: NumPy ``.npz`` + JSON, no pickle, deterministic) holds, per scene of a
fixed, versioned set (`scenes`: conform's probe scenes, synthetic workloads from random poses,
the bundled garden view, a real trained model), the backend's rgb, alpha and depth and its
gradients for seeded random cotangents, with the oracle's boundary band and gradient band
(`reference.band`) that set the tolerances, and the backend's declared conventions, package
versions and device. `check` (`compare_snapshot`) measures each quantity now against it; one
that moved beyond its derived tolerance is an improvement (closer to the float64 oracle than
the snapshot was), a regression (farther), or a convention change (neither, or explained by a
convention conform's diagnosis finds). Modules:

    scenes      the scene set, versioned       files     the snapshot format (write, read, verify)
    measure     rendering a scene, tolerances  check     the verdicts
    cli         the two commands               pytest_plugin   ``pytest --splatbench-backend``
"""

from __future__ import annotations

from splatbench.regress.check import CheckReport, QuantityResult, check
from splatbench.regress.files import SNAPSHOT_FORMAT, read_snapshot, snapshot
from splatbench.regress.scenes import SCENE_SET_VERSION, SCENE_SETS, scene_set

__all__ = ["snapshot", "check", "CheckReport", "QuantityResult", "read_snapshot", "scene_set", "SCENE_SETS",
           "SCENE_SET_VERSION", "SNAPSHOT_FORMAT"]
