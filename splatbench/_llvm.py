"""Locate a libLLVM that Dr.Jit's LLVM backend can use, before Dr.Jit loads.

Dr.Jit 1.5 on x86 needs LLVM >= 16: with LLVM 15, float ``dr.minimum`` /
``dr.maximum`` / ``dr.clip`` abort the whole Python process ("Cannot select:
fminimum"), and LLVM 14 is rejected. Dr.Jit picks whatever ``libLLVM.so`` the
dynamic loader finds first unless ``DRJIT_LIBLLVM_PATH`` names one, so we set
that variable to the newest suitable library before ``import drjit``.

This module imports nothing from splatbench or drjit: ``make setup`` runs it as
a script (``python splatbench/_llvm.py --check``) with the system Python.
"""

from __future__ import annotations

import glob
import os
import re
import sys
from dataclasses import dataclass

MIN_MAJOR = 16
ENV_VAR = "DRJIT_LIBLLVM_PATH"
SEARCH_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)
FIX = "install LLVM >= 16, e.g. `sudo apt-get install -y libllvm19` (Debian/Ubuntu), or set DRJIT_LIBLLVM_PATH"


class LLVMNotFoundError(RuntimeError):
    """No libLLVM >= 16 is available for Dr.Jit's LLVM backend."""


@dataclass(frozen=True)
class LibLLVM:
    path: str
    major: int


_VERSION_RE = re.compile(r"libLLVM(?:-|\.so\.)(\d+)")


def _major_of(path: str) -> int | None:
    name = os.path.basename(path)
    m = _VERSION_RE.search(name)
    if m:
        return int(m.group(1))
    m = re.search(r"llvm[-@]?(\d+)", path)  # e.g. /usr/lib/llvm-19/lib/libLLVM.so
    return int(m.group(1)) if m else None


def candidates(search_dirs: tuple[str, ...] = SEARCH_DIRS) -> list[LibLLVM]:
    """All libLLVM shared libraries found on the usual paths, newest first."""
    found: dict[str, LibLLVM] = {}
    patterns = []
    for d in search_dirs:
        patterns += [f"{d}/libLLVM*.so*", f"{d}/libLLVM*.dylib", f"{d}/llvm-*/lib/libLLVM*.so*"]
    patterns += ["/usr/lib/llvm-*/lib/libLLVM*.so*"]
    for pattern in patterns:
        for path in glob.glob(pattern):
            major = _major_of(path)
            if major is None or not os.path.isfile(path):
                continue
            real = os.path.realpath(path)
            if real not in found:
                found[real] = LibLLVM(path=path, major=major)
    return sorted(found.values(), key=lambda lib: (-lib.major, len(lib.path)))


def locate(environ: dict[str, str] | None = None) -> LibLLVM:
    """The libLLVM Dr.Jit should load: the user's choice if set, else the newest >= 16.

    Raises:
        LLVMNotFoundError: with one line naming the fix, when only older ones exist.
    """
    environ = os.environ if environ is None else environ
    user = environ.get(ENV_VAR)
    if user:
        if not os.path.isfile(user):
            raise LLVMNotFoundError(f"{ENV_VAR}={user!r} does not exist; {FIX}")
        major = _major_of(user)
        if major is not None and major < MIN_MAJOR:
            raise LLVMNotFoundError(
                f"{ENV_VAR}={user!r} is LLVM {major}, but Dr.Jit needs LLVM >= {MIN_MAJOR}; {FIX}"
            )
        return LibLLVM(path=user, major=major or MIN_MAJOR)
    found = candidates()
    usable = [lib for lib in found if lib.major >= MIN_MAJOR]
    if usable:
        return usable[0]
    older = ", ".join(f"LLVM {lib.major} ({lib.path})" for lib in found) or "none"
    raise LLVMNotFoundError(
        f"Dr.Jit needs libLLVM >= {MIN_MAJOR} (older ones abort the process); found: {older}; {FIX}"
    )


#: What ``DRJIT_LIBLLVM_PATH`` is set to when no usable libLLVM exists: a path that does not exist,
#: so Dr.Jit loads no older libLLVM (which would abort on float min/max) and its LLVM backend stays off.
DISABLED_PATH = f"/nonexistent/splatbench-found-no-libLLVM-{MIN_MAJOR}-or-newer"

_missing: LLVMNotFoundError | None = None


def configure() -> LibLLVM | None:
    """Set ``DRJIT_LIBLLVM_PATH`` (unless the user did) before Dr.Jit is imported.

    Returns the library, or None when no libLLVM >= 16 exists: then Dr.Jit's LLVM backend is
    switched off (`DISABLED_PATH`) rather than importing splatbench failing, so a machine with
    a GPU and no suitable LLVM still renders on CUDA; `require()` raises the reason when the CPU
    backend is asked for. A ``DRJIT_LIBLLVM_PATH`` the user set that is unusable still raises.

    Raises:
        LLVMNotFoundError: the user's ``DRJIT_LIBLLVM_PATH`` is missing or older than LLVM 16.
    """
    global _missing
    try:
        lib = locate()
    except LLVMNotFoundError as exc:
        if os.environ.get(ENV_VAR):
            raise
        _missing = exc
        if "drjit" not in sys.modules:
            os.environ[ENV_VAR] = DISABLED_PATH
        return None
    _missing = None
    if "drjit" not in sys.modules:
        os.environ.setdefault(ENV_VAR, lib.path)
    return lib


def require() -> None:
    """Raise why Dr.Jit's LLVM (CPU) backend is off, if `configure()` found no usable libLLVM.

    Raises:
        LLVMNotFoundError: one line naming the fix.
    """
    if _missing is not None:
        raise _missing


#: The narrowest SIMD packet Dr.Jit's LLVM backend runs (SSE4.2 and NEON: 4 lanes; it
#: refuses to start without one).
MIN_PACKET_WIDTH = 4


def packet_width(features: str | None = None) -> int:
    """The SIMD packet width (lanes) of Dr.Jit's LLVM backend on this CPU, decided as
    Dr.Jit 1.5 decides it (drjit-core ``llvm_core.cpp``) from LLVM's host CPU features:
    16 with ``+avx512vl``, 8 with ``+avx``, else 4 (always 4 on Apple silicon).

    ``features``: LLVM's feature string; None reads it from the libLLVM in
    ``DRJIT_LIBLLVM_PATH`` (``LLVMGetHostCPUFeatures``). Where it cannot be read, returns
    `MIN_PACKET_WIDTH`: a caller that groups lanes by packet stays correct with a
    narrower width than the true one, never with a wider one.
    """
    if features is None:
        if sys.platform == "darwin" and os.uname().machine == "arm64":
            return MIN_PACKET_WIDTH
        features = _host_cpu_features()
    if "+avx512vl" in features:
        return 16
    if "+avx" in features:
        return 8
    return MIN_PACKET_WIDTH


def _host_cpu_features() -> str:
    """LLVM's host CPU feature string ("" where it cannot be read), from the libLLVM in
    ``DRJIT_LIBLLVM_PATH`` or, where that is unset, the one `locate` finds: a program that
    imports drjit before splatbench leaves the variable unset (`configure` sets it only
    before Dr.Jit's import), and the features are the CPU's, whichever libLLVM reports them."""
    import ctypes  # a late import: only the rasterizer's reduction asks, once

    path = os.environ.get(ENV_VAR, "")
    if not path:
        try:
            path = locate().path
        except LLVMNotFoundError:
            return ""
    if not os.path.isfile(path):
        return ""
    try:
        lib = ctypes.CDLL(path)
        lib.LLVMGetHostCPUFeatures.restype = ctypes.c_void_p
        lib.LLVMDisposeMessage.argtypes = [ctypes.c_void_p]
        raw = lib.LLVMGetHostCPUFeatures()
    except (OSError, AttributeError):
        return ""
    if not raw:
        return ""
    try:
        return (ctypes.cast(raw, ctypes.c_char_p).value or b"").decode("ascii", "replace")
    finally:
        lib.LLVMDisposeMessage(raw)


def _main(argv: list[str]) -> int:
    """``--check``: exit 0 and print the library when usable, else print why and exit 1."""
    try:
        lib = locate()
    except LLVMNotFoundError as exc:
        print(f"splatbench: {exc}", file=sys.stderr)
        return 1
    if "--quiet" not in argv:
        print(f"libLLVM {lib.major}: {lib.path}")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
