"""Installed package versions, as recorded in benchmark results and dataset cache keys."""

from __future__ import annotations

import functools
import subprocess
from importlib import metadata
from pathlib import Path

#: splatbench's own version (`splatbench.__version__`; importable below the package's facade).
SPLATBENCH_VERSION = "0.1.0"


def package_version(package: str) -> str:
    """The installed version of ``package`` (a distribution name), or ``"not installed"``."""
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"


@functools.cache
def code_version() -> str:
    """The code this process runs: ``git:<short commit>`` of the checkout splatbench is imported
    from, with ``+dirty`` when its tracked files differ from that commit; ``<version>`` (e.g.
    ``0.1.0``) when it is not a git checkout or git cannot be run. What a run records
    (`splatbench.experiments.store.RunRecord.code`), so a report can say which commit each of its
    cells ran at. Read once per process, at its first call (a worker's first run): a process keeps
    the modules it imported, so a checkout moved later does not change the code it runs."""
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                              text=True, timeout=30)
        if head.returncode != 0 or not head.stdout.strip():
            return SPLATBENCH_VERSION
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "--",
                                "splatbench"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return SPLATBENCH_VERSION
    return f"git:{head.stdout.strip()}" + ("+dirty" if dirty.returncode != 0 or dirty.stdout.strip() else "")
