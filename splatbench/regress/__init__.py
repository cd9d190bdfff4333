"""`splatbench snapshot` and `splatbench check`: regression-test a backend against its own past.

    from splatbench.regress import snapshot, check
    snapshot("mypkg.rast:render", "snap/")          # outputs and gradients on a versioned scene set
    report = check("mypkg.rast:render", "snap/")    # the same quantities now, against the snapshot
    report.status, report.exit_code, report.changed # "unchanged" / "improved" / "regressed" /
                                                    # "convention changed"; 0 or 1

A snapshot (`files`: NumPy ``.npz`` + JSON, no pickle, deterministic) holds, per scene of a
fixed, versioned set (`snapshot_scenes`: conform's probe scenes, synthetic workloads from random poses,
the bundled garden view, a real trained model), the backend's rgb, alpha and depth and its
gradients for seeded random cotangents, with the oracle's boundary band and gradient band
(`reference.band`) that set the tolerances, and the backend's declared conventions, package
versions and device. `check` (`against_snapshot`) measures each quantity now against it; one
that moved beyond its derived tolerance is an improvement (closer to the float64 oracle than
the snapshot was), a regression (farther), or a convention change (neither, or explained by a
convention conform's diagnosis finds). Modules:

    snapshot_scenes  the scene set, versioned       files             the snapshot format (write, read, verify)
    measure          rendering a scene, tolerances  against_snapshot  the verdicts (`check`)
    cli              the two commands               pytest_plugin     ``pytest --splatbench-backend``
"""

from __future__ import annotations

import importlib

# Loaded on first use: the pytest plugin (`pytest_plugin`, registered for every pytest run once
# splatbench is installed) imports this package, and must not load torch or Dr.Jit when it is not asked.
_PUBLIC = {"snapshot": "files", "read_snapshot": "files", "SNAPSHOT_FORMAT": "files",
           "check": "against_snapshot", "CheckReport": "against_snapshot", "QuantityResult": "against_snapshot",
           "scene_set": "snapshot_scenes", "SCENE_SETS": "snapshot_scenes",
           "SCENE_SET_VERSION": "snapshot_scenes"}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name in _PUBLIC:
        return getattr(importlib.import_module(f"splatbench.regress.{_PUBLIC[name]}"), name)
    raise AttributeError(f"module 'splatbench.regress' has no attribute {name!r}")
