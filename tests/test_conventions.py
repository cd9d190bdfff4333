"""The convention constants are defined once outside ``reference/`` (`splatbench.conventions`);
the oracle and the independent ``torch`` backend keep their own copies on purpose (they
share no code with the rasterizer). This pins every copy equal, so a change to one is a
test failure until the others follow (and docs/conventions.md with them)."""

from __future__ import annotations

import importlib
import math

import pytest

from splatbench import conventions, gaussians
from splatbench.backends.builtins import torch_backend

# reference/__init__ exports functions named like its modules (`project`), so look the modules up
ORACLE_PROJECT, ORACLE_SH, ORACLE_BAND = (importlib.import_module(f"reference.{m}") for m in ("project", "sh", "band"))

# (name in splatbench.conventions, the oracle's module and name, the torch backend's name)
COPIES = [
    ("LOG_SCALE_CLIP", ORACLE_PROJECT, "LOG_SCALE_CLIP", "LOG_SCALE_CLIP"),
    ("BIG_FACTOR", ORACLE_PROJECT, "BIG_FACTOR", "BIG_FACTOR"),
    ("JACOBIAN_GUARD", ORACLE_PROJECT, "JACOBIAN_GUARD", "JACOBIAN_GUARD"),
    ("QUAT_MIN", ORACLE_PROJECT, "QUAT_MIN", "QUAT_MIN"),
    ("SH_C0", ORACLE_SH, "C0", "C0"),
    ("SH_C1", ORACLE_SH, "C1", "C1"),
    ("SH_C2", ORACLE_SH, "C2", "C2"),
    ("SH_C3", ORACLE_SH, "C3", "C3"),
    ("U32", ORACLE_BAND, "U", None),  # float32 unit roundoff: the oracle's band, compare's and conform's bounds
]


@pytest.mark.parametrize("name, oracle, oracle_name, torch_name", COPIES, ids=[c[0] for c in COPIES])
def test_every_copy_equals_the_one_definition(name, oracle, oracle_name, torch_name):
    value = getattr(conventions, name)
    assert getattr(oracle, oracle_name) == value, f"reference {oracle_name} != splatbench.conventions.{name}"
    if torch_name is not None:
        assert getattr(torch_backend, torch_name) == value, f"torch backend {torch_name} != conventions.{name}"


def test_the_rasterizer_side_uses_the_one_definition():
    from splatbench.raster import projection, sh

    assert (projection.LOG_SCALE_CLIP, projection.QUAT_MIN, projection.JACOBIAN_GUARD, projection.BIG_FACTOR) == (
        conventions.LOG_SCALE_CLIP, conventions.QUAT_MIN, conventions.JACOBIAN_GUARD, conventions.BIG_FACTOR)
    assert (sh.C0, sh.C1, sh.C2, sh.C3) == (conventions.SH_C0, conventions.SH_C1, conventions.SH_C2, conventions.SH_C3)
    assert gaussians.SH_C0 is conventions.SH_C0 and gaussians.QUAT_MIN is conventions.QUAT_MIN


def test_u32_is_float32_unit_roundoff():
    import numpy as np

    assert conventions.U32 == np.finfo(np.float32).eps / 2 == 2.0 ** -24


def test_sh_c0_is_its_closed_form():
    assert conventions.SH_C0 == pytest.approx(1 / (2 * math.sqrt(math.pi)), rel=1e-15)
