"""3DGS PLY I/O: exact round trips, graphdeco-inria's layout, and one-line errors."""

from __future__ import annotations

import os

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from splatbench.ply import property_names
from splatbench.gaussians import Gaussians
from tests.assertions import one_line_error

FIELDS = ("means", "log_scales", "quats", "opacity_logits", "sh")


def make(n: int, k: int, seed: int = 0) -> Gaussians:
    rng = np.random.default_rng(seed)
    g = Gaussians(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 4)),
                  rng.normal(size=n), rng.normal(size=(n, k, 3)))
    # awkward bit patterns a float round trip through text or float64 might not keep
    specials = np.array([-0.0, np.finfo(np.float32).smallest_subnormal, np.finfo(np.float32).max,
                         -np.finfo(np.float32).tiny, 1 / 3], dtype=np.float32)
    for name in FIELDS:
        flat = getattr(g, name).reshape(-1)
        flat[: len(specials)] = specials[: flat.size]
    return g



# ------------------------------------------------------------------ round trip
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_round_trip_is_bit_exact(tmp_path, degree):
    k = (degree + 1) ** 2
    g = make(40, k, seed=degree)
    path = tmp_path / "scene.ply"
    g.to_ply(path)
    back = Gaussians.from_ply(path)
    assert back.sh_degree == degree and len(back) == 40
    for name in FIELDS:
        a, b = getattr(g, name), getattr(back, name)
        assert a.shape == b.shape and a.dtype == b.dtype == np.float32, name
        assert a.tobytes() == b.tobytes(), name  # bit-exact, including -0.0 and subnormals


def test_header_is_graphdeco_layout(tmp_path):
    path = tmp_path / "scene.ply"
    make(3, 16).to_ply(path)
    ply = PlyData.read(str(path))
    assert ply.byte_order == "<" and not ply.text
    assert [e.name for e in ply.elements] == ["vertex"]
    names = [p.name for p in ply["vertex"].properties]
    expected = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
                + [f"f_rest_{i}" for i in range(45)]
                + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    assert names == expected == property_names(3)
    assert all(p.val_dtype in ("f4", "float32") for p in ply["vertex"].properties)
    with open(path, "rb") as f:
        assert f.readline() == b"ply\n" and f.readline() == b"format binary_little_endian 1.0\n"


@pytest.mark.parametrize("k", [1, 4, 9, 16])
def test_f_rest_is_channel_major(tmp_path, k):
    n = 3
    # sh[n, k, c] = 1000 n + 10 k + c: every value says where it came from
    idx_n, idx_k, idx_c = np.meshgrid(np.arange(n), np.arange(k), np.arange(3), indexing="ij")
    sh = (1000 * idx_n + 10 * idx_k + idx_c).astype(np.float32)
    g = Gaussians(np.zeros((n, 3)), np.zeros((n, 3)), np.ones((n, 4)), np.zeros(n), sh)
    path = tmp_path / "layout.ply"
    g.to_ply(path)
    v = PlyData.read(str(path))["vertex"]
    # graphdeco's features_rest is [N, 15, 3] at degree 3 (zeros above the model's degree),
    # saved as features_rest.transpose(1, 2).flatten(): f_rest_{15 c + k - 1} = sh[:, k, c]
    for c in range(3):
        np.testing.assert_array_equal(v[f"f_dc_{c}"], sh[:, 0, c])
        for kk in range(1, 16):
            np.testing.assert_array_equal(v[f"f_rest_{15 * c + kk - 1}"], sh[:, kk, c] if kk < k else 0)
    if k > 2:
        np.testing.assert_array_equal(v["f_rest_0"], [10, 1010, 2010])  # (k=1, c=0), not (k=1, c=1)
        np.testing.assert_array_equal(v["f_rest_1"], [20, 1020, 2020])  # (k=2, c=0)
        np.testing.assert_array_equal(v["f_rest_15"], [11, 1011, 2011])  # (k=1, c=1)
    np.testing.assert_array_equal(v["nx"], 0)


GRAPHDECO_62 = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
                + [f"f_rest_{i}" for i in range(45)]
                + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_every_degree_writes_graphdecos_62_properties(tmp_path, degree):
    """graphdeco's load_ply asserts len(f_rest) == 3 (max_sh_degree + 1)^2 - 3 = 45 for its
    default degree 3, so every file carries all 62 properties, higher bands zero."""
    path = tmp_path / "scene.ply"
    g = make(5, (degree + 1) ** 2, seed=degree)
    g.to_ply(path)
    ply = PlyData.read(str(path))
    assert [p.name for p in ply["vertex"].properties] == GRAPHDECO_62 and len(GRAPHDECO_62) == 62
    for i in range((degree + 1) ** 2 - 1, 15):  # rest coefficients above the degree: zero
        for c in range(3):
            assert not np.asarray(ply["vertex"][f"f_rest_{15 * c + i}"]).any()
    assert f"splatbench sh_degree {degree}" in ply.comments


def test_padded_file_without_our_comment_reads_as_degree_3_with_zero_bands(tmp_path):
    """A 45-f_rest file from another writer keeps degree 3; its zero bands render exactly
    as the degree-0 model (0 * basis adds exact zeros)."""
    g0 = make(6, 1, seed=5)
    padded = np.zeros((6, 16, 3), np.float32)
    padded[:, :1] = g0.sh
    g3 = Gaussians(g0.means, g0.log_scales, g0.quats, g0.opacity_logits, padded)
    path = tmp_path / "graphdeco.ply"
    write_graphdeco_style(path, g3)
    back = Gaussians.from_ply(path)
    assert back.sh_degree == 3 and back.sh.tobytes() == padded.tobytes()


def write_graphdeco_style(path, g: Gaussians, drop=(), extra_element=None, rename=None):
    """Write a PLY the way graphdeco-inria's ``GaussianModel.save_ply`` does, independently
    of splatbench.ply: ``f_rest = features_rest.transpose(1, 2).flatten(start_dim=1)``."""
    n, k, _ = g.sh.shape
    f_rest = np.transpose(g.sh[:, 1:, :], (0, 2, 1)).reshape(n, -1)
    columns = [g.means, np.zeros((n, 3), np.float32), g.sh[:, 0, :], f_rest,
               g.opacity_logits[:, None], g.log_scales, g.quats]
    names = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
             + [f"f_rest_{i}" for i in range(f_rest.shape[1])]
             + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    values = np.concatenate(columns, axis=1)
    keep = [i for i, name in enumerate(names) if name not in drop]
    dtype = [(names[i] if rename is None else rename.get(names[i], names[i]), "f4") for i in keep]
    data = np.empty(n, dtype=dtype)
    data[:] = list(map(tuple, values[:, keep]))
    elements = [PlyElement.describe(data, "vertex" if extra_element is None else extra_element)]
    PlyData(elements).write(str(path))


@pytest.mark.parametrize("k", [1, 4, 9, 16])
def test_reads_independently_written_graphdeco_file(tmp_path, k):
    g = make(7, k, seed=k)
    path = tmp_path / "graphdeco.ply"
    write_graphdeco_style(path, g)
    back = Gaussians.from_ply(path)
    for name in FIELDS:
        assert getattr(back, name).tobytes() == getattr(g, name).tobytes(), name


# ----------------------------------------------------------------------- errors
def test_missing_property_named(tmp_path):
    path = tmp_path / "scene.ply"
    write_graphdeco_style(path, make(4, 16), drop=("rot_3",))
    msg = one_line_error(lambda: Gaussians.from_ply(path), "scene.ply", "missing vertex properties ['rot_3']")
    assert msg.endswith("missing vertex properties ['rot_3']")


def test_missing_positions_and_opacity_named(tmp_path):
    path = tmp_path / "scene.ply"
    write_graphdeco_style(path, make(4, 1), drop=("x", "opacity"))
    one_line_error(lambda: Gaussians.from_ply(path), "scene.ply", "['x', 'opacity']")


def test_gap_in_f_rest_named(tmp_path):
    path = tmp_path / "scene.ply"
    write_graphdeco_style(path, make(4, 9), drop=("f_rest_5",))
    one_line_error(lambda: Gaussians.from_ply(path), "missing vertex properties ['f_rest_5']")


def test_last_f_rest_missing_named(tmp_path):
    path = tmp_path / "scene.ply"
    write_graphdeco_style(path, make(4, 16), drop=("f_rest_44",))
    one_line_error(lambda: Gaussians.from_ply(path), "missing vertex properties ['f_rest_44']")


def test_too_many_f_rest_rejected(tmp_path):
    path = tmp_path / "scene.ply"
    g = make(2, 16)
    write_graphdeco_style(path, g, rename={"f_rest_44": "f_rest_47"})  # 48 f_rest slots, a gap
    one_line_error(lambda: Gaussians.from_ply(path), "scene.ply", "48 f_rest_* properties")


def test_wrong_element_named(tmp_path):
    path = tmp_path / "scene.ply"
    write_graphdeco_style(path, make(4, 1), extra_element="face")
    one_line_error(lambda: Gaussians.from_ply(path), "scene.ply", "missing element 'vertex'", "face")


@pytest.mark.parametrize("content, expect", [
    (b"", "not a valid PLY file"),
    (b"hello, not a ply\n", "not a valid PLY file"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n", "not a valid PLY file"),  # header cut
])
def test_not_a_ply(tmp_path, content, expect):
    path = tmp_path / "scene.ply"
    path.write_bytes(content)
    one_line_error(lambda: Gaussians.from_ply(path), "scene.ply", expect)


@pytest.mark.parametrize("cut", [1, 4, 123])
def test_truncated_data(tmp_path, cut):
    path = tmp_path / "scene.ply"
    make(20, 16).to_ply(path)
    data = path.read_bytes()
    path.write_bytes(data[:-cut])
    one_line_error(lambda: Gaussians.from_ply(path), "scene.ply", "truncated", "claims 20 entries")


def test_missing_file(tmp_path):
    one_line_error(lambda: Gaussians.from_ply(tmp_path / "nope.ply"), "nope.ply", "no such file")


def test_non_finite_value_names_file_and_field(tmp_path):
    path = tmp_path / "scene.ply"
    write_graphdeco_style(path, make(4, 1))
    v = PlyData.read(str(path), mmap=False)  # not memory-mapped: we overwrite the same file
    v["vertex"].data["y"][2] = np.nan
    v.write(str(path))
    one_line_error(lambda: Gaussians.from_ply(path), "scene.ply", "means:", "[2, 1]")


# ------------------------------------------------------------------ atomic write
def test_write_replaces_atomically_and_cleans_up(tmp_path, monkeypatch):
    path = tmp_path / "scene.ply"
    first, second = make(5, 4, seed=1), make(6, 9, seed=2)
    first.to_ply(path)
    before = path.read_bytes()

    def boom(self, stream):
        stream.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(PlyData, "write", boom)
    with pytest.raises(OSError, match="disk full"):
        second.to_ply(path)
    assert path.read_bytes() == before  # the old file is untouched
    assert os.listdir(tmp_path) == ["scene.ply"]  # and no temporary file is left behind
    monkeypatch.undo()
    second.to_ply(path)
    assert Gaussians.from_ply(path).sh.tobytes() == second.sh.tobytes()
    assert os.listdir(tmp_path) == ["scene.ply"]


# ------------------------------------------------------------------ view hints
def test_view_hints_round_trip_and_leave_graphdecos_62_properties(tmp_path):
    """Up and background go into header comments only: the vertex layout and data are
    those of a file without them, and the values come back exactly (repr round trip)."""
    from splatbench.ply import ViewHints, read_view_hints

    g = make(5, 4, seed=3)
    plain, hinted = tmp_path / "plain.ply", tmp_path / "hinted.ply"
    g.to_ply(plain)
    g.to_ply(hinted, ViewHints(up=(0.0, 2.0, 0.0), background=(0.5, 1 / 3, 0.0)))
    assert read_view_hints(plain) == ViewHints(None, None)
    hints = read_view_hints(hinted)
    assert hints.up == (0.0, 1.0, 0.0)                  # normalised on construction
    assert hints.background == (0.5, 1 / 3, 0.0)        # bit-exact floats
    a, b = PlyData.read(str(plain)), PlyData.read(str(hinted))
    assert [p.name for p in b["vertex"].properties] == [p.name for p in a["vertex"].properties] == GRAPHDECO_62
    assert b["vertex"].data.tobytes() == a["vertex"].data.tobytes()
    assert "splatbench up 0.0 1.0 0.0" in b.comments
    assert "splatbench background 0.5 0.3333333333333333 0.0" in b.comments
    back = Gaussians.from_ply(hinted)
    assert all(getattr(back, f).tobytes() == getattr(Gaussians.from_ply(plain), f).tobytes() for f in FIELDS)


@pytest.mark.parametrize("comment, expect", [
    ("splatbench up 0 0 0", "non-zero direction"),
    ("splatbench up 0 1", "3 finite numbers"),
    ("splatbench up 0 nan 1", "3 finite numbers"),
    ("splatbench background 0.5 2 0", "in [0, 1]"),
    ("splatbench background a b c", "3 numbers"),
])
def test_malformed_view_hint_is_one_line_naming_file_and_comment(tmp_path, comment, expect):
    from splatbench.ply import read_view_hints

    good, path = tmp_path / "good.ply", tmp_path / "bad.ply"
    write_graphdeco_style(good, make(2, 1))
    ply = PlyData.read(str(good))
    ply.comments = [comment]
    ply.write(str(path))
    one_line_error(lambda: read_view_hints(path), str(path), repr(comment), expect)
