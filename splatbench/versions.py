"""Installed package versions, as recorded in benchmark results and dataset cache keys."""

from __future__ import annotations

from importlib import metadata

#: splatbench's own version (`splatbench.__version__`; importable below the package's facade).
SPLATBENCH_VERSION = "0.1.0"


def package_version(package: str) -> str:
    """The installed version of ``package`` (a distribution name), or ``"not installed"``."""
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"
