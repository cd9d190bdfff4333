"""Installed package versions, as recorded in benchmark results and dataset cache keys."""

from __future__ import annotations

from importlib import metadata


def package_version(package: str) -> str:
    """The installed version of ``package`` (a distribution name), or ``"not installed"``."""
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"
