"""The one device choice of splatbench: ``"cpu"``, ``"cuda"`` or ``"auto"`` (CUDA when available).

Every command's ``--device`` is `device_option` (the same choices, help text, default
and one-line error), and every config or settings object that names a device checks it
with `check_device`. What "CUDA when available" means depends on who runs the work:
Dr.Jit's CUDA backend for the rasterizer (`splatbench.raster.device.get_device`),
torch's CUDA for input tensors handed to other rasterizers (`torch_device`); ``"cuda"`` where
the one who looks finds no GPU is the one `no_cuda` line, whoever asks.
Torch- and Dr.Jit-free, so the command modules can import it at no cost.
"""

from __future__ import annotations

from typing import Callable, TypeVar

from splatbench.errors import InputError

DEVICES = ("cpu", "cuda", "auto")
DEFAULT_DEVICE = "auto"
DEVICE_HELP = "Where the work runs: cpu, cuda, or auto (CUDA when available)."

F = TypeVar("F", bound=Callable)


def check_device(device: object, field: str = "device") -> str:
    """``device`` if it is one of `DEVICES`, else a one-line `InputError` naming ``field``."""
    if device not in DEVICES:
        raise InputError(f"{field}: expected 'auto', 'cpu' or 'cuda', got {device!r}")
    return device  # type: ignore[return-value]


def no_cuda(finder: str, field: str = "device") -> InputError:
    """The one no-GPU error (every command and API says it the same way): ``"cuda"`` was asked
    for, but ``finder`` ("Dr.Jit" or "torch", whoever would run the work) sees no CUDA device."""
    return InputError(f"{field}: 'cuda' asked for, but {finder} finds no CUDA device (use cpu or auto)")


def torch_device(device: str, field: str = "device") -> str:
    """``"cpu"`` or ``"cuda"``: where torch tensors go for ``device`` (``"auto"``: CUDA when
    torch sees a GPU). A one-line `InputError` for an unknown device or ``"cuda"`` without one."""
    check_device(device, field)
    if device == "cpu":
        return "cpu"
    import torch

    if torch.cuda.is_available():
        return "cuda"
    if device == "cuda":
        raise no_cuda("torch", field)
    return "cpu"


def device_option(fn: F) -> F:
    """The ``--device`` option every command shares (choices `DEVICES`, default ``auto``); a bad
    value is one ``--device: ...`` line like any other `InputError`."""
    import click

    def check(ctx: click.Context, param: click.Parameter, value: str) -> str:
        return check_device(value, "--device")

    return click.option("--device", default=DEFAULT_DEVICE, show_default=True, metavar="|".join(DEVICES),
                        callback=check, help=DEVICE_HELP)(fn)
