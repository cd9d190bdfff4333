"""libLLVM discovery (`splatbench._llvm`): the newest >= 16 wins, older ones are refused, and a
machine with none still imports splatbench (its CPU device then says why, in one line)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from splatbench import _llvm

REPO = Path(__file__).resolve().parents[1]


def _touch(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"")
    return path


def test_newest_usable_library_first(tmp_path):
    _touch(tmp_path / "libLLVM-15.so.1")
    _touch(tmp_path / "libLLVM.so.19.1")
    _touch(tmp_path / "llvm-17" / "lib" / "libLLVM.so")
    # candidates() also globs /usr/lib/llvm-*/ whatever the search dirs: keep only ours.
    found = [lib for lib in _llvm.candidates((str(tmp_path),)) if lib.path.startswith(str(tmp_path))]
    assert [lib.major for lib in found] == [19, 17, 15]


def test_user_path_must_exist_and_be_new_enough(tmp_path):
    with pytest.raises(_llvm.LLVMNotFoundError, match="DRJIT_LIBLLVM_PATH=.*does not exist"):
        _llvm.locate({_llvm.ENV_VAR: str(tmp_path / "libLLVM-19.so")})
    old = _touch(tmp_path / "libLLVM-15.so")
    with pytest.raises(_llvm.LLVMNotFoundError, match="LLVM 15, but Dr.Jit needs LLVM >= 16"):
        _llvm.locate({_llvm.ENV_VAR: str(old)})
    new = _touch(tmp_path / "libLLVM-18.so")
    assert _llvm.locate({_llvm.ENV_VAR: str(new)}).major == 18


# Run in a fresh interpreter: the library decision is made once, before drjit loads. The script
# loads `_llvm` on its own, makes it find only an LLVM 15 (the Debian case that aborts), and
# registers it as `splatbench._llvm` so that `import splatbench` uses this copy.
_NO_USABLE_LLVM = r"""
import importlib.util, os, sys
spec = importlib.util.spec_from_file_location("splatbench._llvm", sys.argv[1])
llvm = importlib.util.module_from_spec(spec)
sys.modules["splatbench._llvm"] = llvm
spec.loader.exec_module(llvm)
llvm.candidates = lambda *a, **k: [llvm.LibLLVM("/usr/lib/libLLVM-15.so.1", 15)]
import splatbench
import drjit as dr
print("env", os.environ[llvm.ENV_VAR])
print("llvm", bool(dr.has_backend(dr.JitBackend.LLVM)))
from splatbench.raster.device import get_device
try:
    get_device("cpu")
except splatbench.InputError as exc:
    print("error", exc)
"""


def test_no_usable_llvm_still_imports_and_cpu_device_says_why():
    env = {k: v for k, v in os.environ.items() if k != _llvm.ENV_VAR}
    out = subprocess.run([sys.executable, "-c", _NO_USABLE_LLVM, str(REPO / "splatbench" / "_llvm.py")],
                         env=env, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = dict(line.split(" ", 1) for line in out.stdout.splitlines())
    assert lines["env"] == _llvm.DISABLED_PATH  # no older libLLVM may load: it would abort on float min/max
    assert lines["llvm"] == "False"
    assert lines["error"].startswith("device: 'cpu' needs Dr.Jit's LLVM backend: Dr.Jit needs libLLVM >= 16")
    assert "LLVM 15 (/usr/lib/libLLVM-15.so.1)" in lines["error"] and "apt-get install" in lines["error"]
    assert "\n" not in lines["error"]


def test_packet_width_is_the_cpus_when_drjit_was_imported_first():
    """A program that imports drjit before splatbench leaves DRJIT_LIBLLVM_PATH unset
    (`configure` sets it only before Dr.Jit's import). The packet width must still be the
    CPU's: with the 4-lane fallback the reduction kept 4 gradient slots per pair on an
    AVX-512 machine (4x the per-pair buffers, a slower backward) and summed the gradients in
    another order than `splatbench train` on the same machine."""
    if not os.path.isfile(os.environ.get(_llvm.ENV_VAR, "")):
        pytest.skip("no usable libLLVM here")
    env = {k: v for k, v in os.environ.items() if k != _llvm.ENV_VAR}
    script = ("import os, drjit, splatbench\nfrom splatbench.raster.device import get_device, packet_width\n"
              "print(os.environ.get('DRJIT_LIBLLVM_PATH'), packet_width(get_device('cpu').t))")
    out = subprocess.run([sys.executable, "-c", script], env=env, cwd=REPO, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    unset, width = out.stdout.split()
    assert unset == "None"  # the case under test: drjit came first
    assert int(width) == _llvm.packet_width()  # this process's, read with the variable set
