"""Every command's ``--device`` is the one shared option (`splatbench.devices.device_option`):
the same choices, help text, default and one-line error; ``train --set device=`` says the same."""

from __future__ import annotations

import re

import click
import pytest
from click.testing import CliRunner

from splatbench.cli import COMMANDS, LazyGroup, main
from splatbench.devices import DEVICE_HELP, DEVICES, check_device, torch_device
from splatbench.errors import InputError

# The commands whose work runs on a device (docs/: README "Command line").
DEVICE_COMMANDS = {
    "stress": ["stress"],
    "compare": ["compare", "--backend", "torch"],
    "conform": ["conform", "torch"],
    "bench raster": ["bench", "raster"],
    "bench train": ["bench", "train"],
    "snapshot": ["snapshot", "torch", "--out", "."],
    "check": ["check", "torch", "--against", "."],
}
EXPECTED = "splatbench: error: --device: expected 'auto', 'cpu' or 'cuda', got 'tpu'"


def _commands():
    """(path, click command) of every command and subcommand of `splatbench`."""
    ctx = click.Context(main)
    for name in COMMANDS:
        cmd = LazyGroup.get_command(main, ctx, name)
        if isinstance(cmd, click.Group):
            for sub in cmd.list_commands(ctx):
                yield f"{name} {sub}", cmd.get_command(ctx, sub)
        else:
            yield name, cmd


def _stderr_lines(args: list[str]) -> tuple[int, list[str]]:
    res = CliRunner().invoke(main, args)
    return res.exit_code, [line for line in res.stderr.splitlines() if line.strip()]


def test_every_device_option_is_the_shared_one():
    found = {path: p for path, cmd in _commands() for p in cmd.params if p.name == "device"}
    assert set(found) == set(DEVICE_COMMANDS), "a command gained or lost --device: update DEVICE_COMMANDS and docs"
    for path, p in found.items():
        assert (p.opts, p.default, p.help, p.metavar) == (["--device"], "auto", DEVICE_HELP, "cpu|cuda|auto"), path


@pytest.mark.parametrize("path", sorted(DEVICE_COMMANDS))
def test_bad_device_is_the_same_one_line_everywhere(path):
    code, lines = _stderr_lines([*DEVICE_COMMANDS[path], "--device", "tpu"])
    assert (code, lines) == (2, [EXPECTED])


def test_train_set_device_says_the_same(tmp_path):
    # TrainConfig names its fields without the flag (as every `--set` error does); the rest is the same text.
    code, lines = _stderr_lines(["train", str(tmp_path / "data"), "--set", "device=tpu"])
    assert (code, lines) == (2, [EXPECTED.replace("--device:", "device:")])


def test_check_device_and_torch_device():
    assert [check_device(d) for d in DEVICES] == list(DEVICES)
    with pytest.raises(InputError, match=r"^where: expected 'auto', 'cpu' or 'cuda', got 'gpu'$"):
        check_device("gpu", "where")
    import torch

    assert torch_device("cpu") == "cpu"
    assert torch_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")
    if not torch.cuda.is_available():
        with pytest.raises(InputError, match=r"^--device: 'cuda' asked for, but torch finds no CUDA device"):
            torch_device("cuda", "--device")


def test_auto_takes_cuda_only_where_the_backends_run(monkeypatch):
    """compare and conform under "auto" with a GPU torch can see (faked): CUDA only for backends that
    list it, so a CPU-only backend still runs instead of becoming an error row."""
    import torch

    from splatbench.backends.base import BackendInfo
    from splatbench.compare.run import _device
    from splatbench.conform import conform
    from splatbench.backends.registry import get_backend

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    cpu_only = get_backend("torch")
    assert cpu_only.info.devices == ("cpu",)
    both = type(cpu_only)(cpu_only.fn, BackendInfo(name="both", devices=("cpu", "cuda")))
    assert _device("auto", [cpu_only]) == "cpu" and _device("auto", [cpu_only, both]) == "cpu"
    assert _device("auto", [both]) == "cuda" and _device("cuda", [cpu_only]) == "cuda"  # then an error row
    assert conform(cpu_only, probes=("depth_order",)).device == "cpu"
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert _device("auto", [both]) == "cpu"


# 'cuda' on a machine without a GPU (faked, so this runs everywhere): one line before any work,
# in the one wording of `splatbench.devices.no_cuda`, naming who looked (Dr.Jit runs the
# rasterizer; torch holds the inputs handed to other rasterizers) and the fix.
NO_GPU = "'cuda' asked for, but {} finds no CUDA device (use cpu or auto)"
NO_GPU_COMMANDS = {
    "stress": (["stress", "--cases", "3"], "device: " + NO_GPU.format("Dr.Jit")),
    "bench raster": (["bench", "raster"], "device: " + NO_GPU.format("Dr.Jit")),
    "bench train": (["bench", "train"], "device: " + NO_GPU.format("Dr.Jit")),
    "compare": (["compare", "--backend", "torch"], "--device: " + NO_GPU.format("torch")),
    "conform drjit": (["conform", "drjit"], "device: " + NO_GPU.format("torch")),
    "conform torch": (["conform", "torch"], "device: " + NO_GPU.format("torch")),
}


@pytest.fixture
def no_gpu(monkeypatch):
    import torch

    from splatbench.raster import device as raster_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(raster_device, "cuda_available", lambda: False)
    raster_device.get_device.cache_clear()  # a real GPU's "cuda" backend may be cached
    yield
    raster_device.get_device.cache_clear()


@pytest.mark.parametrize("path", sorted(NO_GPU_COMMANDS))
def test_cuda_without_a_gpu_is_one_line_everywhere(no_gpu, path):
    args, expected = NO_GPU_COMMANDS[path]
    code, lines = _stderr_lines([*args, "--device", "cuda"])
    assert (code, lines) == (2, ["splatbench: error: " + expected])


def test_no_cuda_is_said_in_one_place(no_gpu):
    from splatbench.raster.device import get_device

    with pytest.raises(InputError, match="^device: " + re.escape(NO_GPU.format("Dr.Jit")) + "$"):
        get_device("cuda")
    with pytest.raises(InputError, match="^where: " + re.escape(NO_GPU.format("torch")) + "$"):
        torch_device("cuda", "where")
    assert get_device("auto").name == "llvm" and torch_device("auto") == "cpu"
