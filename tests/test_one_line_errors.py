"""Bad input and file-system faults give one line and a non-zero exit (issue #15,
items 5-7), never a traceback, a hang or a silently wrong image; image sizes are
bounded before anything is allocated; outputs get the umask's mode (item 9).
"""

from __future__ import annotations

import builtins
import errno
import io
import os
import stat
import struct
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import splatbench
from splatbench import Gaussians
from splatbench.guards import DRJIT_MAX_ENTRIES, check_image_size, image_size_problem
from splatbench.framing import framing_camera
from splatbench.errors import InputError

SWEEP = 'name = "sweep"\nkind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha"]\nseeds = [0, 1]\n'


def one_gaussian(sh_dc: float = 1.0) -> Gaussians:
    return Gaussians(means=np.zeros((1, 3)), log_scales=np.full((1, 3), -1.0), quats=np.array([[1.0, 0, 0, 0]]),
                     opacity_logits=np.array([3.0]), sh=np.full((1, 1, 3), sh_dc))


def cli(*args: str):
    """Run ``splatbench ARGS`` in-process; returns (exit code, the non-empty stderr lines)."""
    from splatbench.cli import main

    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, [line for line in res.stderr.splitlines() if line.strip()]


def assert_one_line(args, expected: str) -> str:
    code, lines = cli(*args)
    assert code == 2, (code, lines)
    assert len(lines) == 1 and lines[0].startswith("splatbench: error: "), lines
    assert expected in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """A COLMAP-layout dataset: `diffuse`, 16 px, 4 views, 1 spp."""
    from splatbench.scenes.render import render_dataset

    out = tmp_path_factory.mktemp("errors") / "diffuse-16"
    render_dataset("diffuse", out, resolution=16, views=4, spp=1, progress=False)
    return out


@pytest.fixture
def ply(tmp_path) -> Path:
    path = tmp_path / "one.ply"
    one_gaussian().to_ply(path)
    return path


# --------------------------------------------------------------------------- item 5: bad input
def test_a_ply_with_no_vertices(tmp_path):
    empty = Gaussians(means=np.zeros((0, 3)), log_scales=np.zeros((0, 3)), quats=np.zeros((0, 4)),
                      opacity_logits=np.zeros(0), sh=np.zeros((0, 1, 3)))
    empty.to_ply(tmp_path / "empty.ply")
    assert len(Gaussians.from_ply(tmp_path / "empty.ply")) == 0
    assert_one_line(["render", tmp_path / "empty.ply"], "holds 0 Gaussians")


def test_render_out_is_a_folder(tmp_path, ply):
    (tmp_path / "folder").mkdir()
    assert_one_line(["render", ply, "--out", tmp_path / "folder"], "--out: ")


def test_train_out_is_a_file(tmp_path, dataset):
    (tmp_path / "file").write_text("x")
    assert_one_line(["train", dataset, "--out", tmp_path / "file", "--quiet"], "out: ")


def test_experiment_file_not_utf8(tmp_path):
    (tmp_path / "bad.toml").write_bytes(b'name = "caf\xe9"\n')
    assert_one_line(["run", tmp_path / "bad.toml"], "is not UTF-8 text (byte 11)")


def test_truncated_cameras_bin_names_the_file(tmp_path, dataset):
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    # 30 bytes: 1 camera, id 1, model 1 (PINHOLE), width 64, then 6 of height's 8 bytes; no parameters
    (copy / "sparse" / "0" / "cameras.bin").write_bytes(struct.pack("<QiiQ", 1, 1, 1, 64) + b"\x40" + b"\0" * 5)
    line = assert_one_line(["train", copy, "--out", tmp_path / "o", "--quiet"], "cameras.bin")
    assert str(copy / "sparse" / "0") in line


def test_render_api_rejects_what_is_not_gaussians_or_a_camera():
    cam = framing_camera(one_gaussian(), 16, 16)
    with pytest.raises(InputError, match=r"^gaussians: expected splatbench.Gaussians, got NoneType$"):
        splatbench.render(None, cam)
    with pytest.raises(InputError, match=r"^camera: expected splatbench.Camera, got dict$"):
        splatbench.render(one_gaussian(), {})


# --------------------------------------------------------------------------- item 5: read-only outputs
@pytest.fixture
def read_only(tmp_path, monkeypatch) -> Path:
    """A folder nothing can be written into. Mode 0555 stops an ordinary user; root
    ignores modes, so for root the write calls under the folder are made to fail as the
    kernel would for anyone else (EACCES), at the functions every writer goes through."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    if os.geteuid() != 0:
        yield folder
        folder.chmod(0o755)
        return

    def inside(path) -> bool:
        try:
            return Path(os.fsdecode(path)).absolute().is_relative_to(folder)
        except TypeError:  # a file descriptor
            return False

    def deny(path):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fsdecode(path))

    def guard(real, writes=lambda *a, **k: True):
        def wrapped(path, *args, **kwargs):
            if inside(path) and writes(*args, **kwargs):
                deny(path)
            return real(path, *args, **kwargs)
        return wrapped

    def opens_for_writing(mode="r", *args, **kwargs):
        return any(c in mode for c in "wax+")

    def creates(flags, *args, **kwargs):
        return bool(flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT))

    monkeypatch.setattr(builtins, "open", guard(builtins.open, opens_for_writing))
    monkeypatch.setattr(io, "open", guard(io.open, opens_for_writing))
    monkeypatch.setattr(os, "open", guard(os.open, creates))
    monkeypatch.setattr(os, "mkdir", guard(os.mkdir))
    for name in ("replace", "rename", "link"):
        real = getattr(os, name)
        monkeypatch.setattr(os, name, lambda src, dst, *a, _real=real, **k:
                            deny(dst) if inside(dst) or inside(src) else _real(src, dst, *a, **k))
    yield folder
    folder.chmod(0o755)


def _results(tmp_path) -> tuple[Path, Path]:
    from splatbench.experiments import load_experiment, run_experiment

    exp = tmp_path / "sweep.toml"
    exp.write_text(SWEEP)
    run_experiment(load_experiment(exp), workers=1, results_dir=tmp_path / "results", progress=False)
    return exp, tmp_path / "results"


@pytest.mark.parametrize("command", ["render", "train", "run", "report", "scenes render"])
def test_read_only_output_folder(tmp_path, read_only, dataset, ply, command):
    args = {
        "render": lambda: ["render", ply, "--out", read_only / "x.png"],
        "train": lambda: ["train", dataset, "--out", read_only / "run", "--quiet", "--set", "iterations=1"],
        "run": lambda: ["run", _results(tmp_path)[0], "--results", read_only, "--no-progress"],
        "report": lambda: ["report", _results(tmp_path)[0], "--results", tmp_path / "results", "--out",
                           read_only / "report"],
        "scenes render": lambda: ["scenes", "render", "diffuse", "--resolution", "8", "--views", "2", "--spp",
                                  "1", "--out", read_only / "ds"],
    }[command]()
    line = assert_one_line(args, str(read_only))
    assert "Permission denied (make it writable" in line


# --------------------------------------------------------------------------- item 6: sizes
def test_image_size_bound_is_drjits_entry_limit_over_three_channels():
    limit = DRJIT_MAX_ENTRIES // 3  # the RGB image, [H*W*3], is the largest per-pixel array
    assert image_size_problem(limit, 1, memory=False) is None
    assert "Dr.Jit's limit" in image_size_problem(limit + 1, 1, memory=False)
    assert "memory available" in image_size_problem(30000, 30000)  # 9e8 px x 256 B = 230 GB
    with pytest.raises(InputError, match=r"^data\.resolution: 100000x100000 is 1e\+10 pixels"):
        check_image_size(100000, 100000, field="data.resolution")


def test_huge_sizes_are_refused_before_allocating(tmp_path, ply):
    assert_one_line(["render", ply, "--size", "100000x100000", "--out", tmp_path / "x.png"], "--size: ")
    assert_one_line(["bench", "raster", "--synthetic", "10", "100000x100000", "--out", tmp_path / "b"],
                    "--synthetic: 100000x100000 is 1e+10 pixels, above Dr.Jit's limit")
    exp = tmp_path / "res.toml"
    exp.write_text('name = "res"\nkind = "train"\nscenes = ["diffuse"]\n[base]\ndata.resolution = 100000\n')
    assert_one_line(["run", exp, "--results", tmp_path / "r"], "data.resolution: 100000x100000")


# --------------------------------------------------------------------------- item 7: silent wrong results
def test_clip_planes_and_background_are_checked():
    g = one_gaussian()
    cam = framing_camera(g, 16, 16)
    with pytest.raises(InputError, match=r"^near: expected a value below far \(1\), got 10"):
        splatbench.render(g, cam, options=splatbench.RasterOptions(near=10, far=1))
    with pytest.raises(InputError, match=r"^background: expected 3 values in \[0, 1\]"):
        splatbench.render(g, cam, background=(2, 0, 0))


def test_one_gaussian_ply_is_framed_and_visible(tmp_path, ply):
    code, _ = cli("render", ply, "--size", "32x32", "--out", tmp_path / "one.png")
    assert code == 0
    g = Gaussians.from_ply(ply)
    res = splatbench.render(g, framing_camera(g, 32, 32))
    # centre pixel: alpha = sigmoid(3) * exp(-d^2/2) with d ~ 0 at the Gaussian's mean = 0.95, clamped at 0.99
    assert res.alpha[16, 16] > 0.9
    # the 3-sigma footprint fills most of the view, not a speck: the camera frames radius 3 sigma
    assert (res.alpha > 1 / 255).mean() > 0.3


# --------------------------------------------------------------------------- item 9: modes
def test_outputs_get_the_umask_mode(tmp_path):
    from splatbench.fsutil import replace_dir
    from splatbench.images import save_png

    old = os.umask(0o022)
    try:
        png = save_png(np.zeros((2, 2, 3)), tmp_path / "a.png")
        one_gaussian().to_ply(tmp_path / "a.ply")
        tmp = Path(__import__("tempfile").mkdtemp(dir=tmp_path))  # 0700, as datasets' temp folders are
        replace_dir(tmp, tmp_path / "dataset")
        os.umask(0o027)
        png2 = save_png(np.zeros((2, 2, 3)), tmp_path / "b.png")
    finally:
        os.umask(old)
    mode = lambda p: stat.S_IMODE(p.stat().st_mode)  # noqa: E731
    assert (mode(png), mode(tmp_path / "a.ply"), mode(tmp_path / "dataset"), mode(png2)) == (0o644, 0o644, 0o755,
                                                                                            0o640)


# --------------------------------------------------------------------------- unknown keys
def _raises(call) -> str:
    with pytest.raises(InputError) as info:
        call()
    return str(info.value)


def test_a_misspelt_key_gets_one_wording_and_a_suggestion_everywhere():
    """Every mapping checked against a dataclass's fields (train config and its strategy
    options, rasterizer options, the raster and train run kinds, scene rigs, experiment
    files) words an unknown key one way: ``FIELD: unknown key (did you mean 'x'?)``."""
    from splatbench.experiments import raster_kind, train_kind
    from splatbench.experiments.spec import parse_experiment
    from splatbench.raster.options import RasterOptions
    from splatbench.scenes.catalog import RigSpec
    from splatbench.train.config import TrainConfig, apply_overrides

    cases = {
        "strategy 'default': strategy.grad_treshold: unknown key (did you mean 'grad_threshold'?)":
            lambda: apply_overrides(TrainConfig(), ["strategy.grad_treshold=1e-4"]),
        "--set: iteration: unknown key (did you mean 'iterations'?)":
            lambda: apply_overrides(TrainConfig(), ["iteration=10"]),
        "alpha_mn: unknown key (did you mean 'alpha_min'?)": lambda: RasterOptions.from_kwargs(alpha_mn=0.1),
        "repeat: unknown key (did you mean 'repeats'?)":
            lambda: raster_kind.validate({"scene": "garden", "repeat": 9}),
        "data.resolutoin: unknown key (did you mean 'resolution'?)":
            lambda: train_kind.validate({"scene": "glossy", "data": {"resolutoin": 64}}),
        "rig: fov: unknown key (did you mean 'fov_deg'?)":
            lambda: RigSpec.from_mapping({"kind": "orbit", "radius": 2.0, "fov": 40.0}),
        "experiment: seed: unknown key (did you mean 'seeds'?)":
            lambda: parse_experiment({"kind": "tests.kinds_for_tests:DUMMY", "scenes": ["alpha"], "seed": [0]}),
    }
    for message, call in cases.items():
        assert _raises(call) == message
    # nothing close: the known names instead
    assert _raises(lambda: RasterOptions.from_kwargs(zzz=1)).startswith("zzz: unknown key (known: alpha_max, ")
