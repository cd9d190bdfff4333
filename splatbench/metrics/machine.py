"""Where a benchmark ran: `MachineInfo` (CPU, versions, device, load averages)."""

from __future__ import annotations

import os
import platform
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from splatbench.versions import package_version


@dataclass
class MachineInfo:
    """Where the benchmark ran."""

    cpu_count: int | None
    cpu_model: str
    platform: str
    python: str
    splatbench: str
    drjit: str
    mitsuba: str
    torch: str
    device: str                  # the device the rasterizer resolved to: "cpu" or "cuda"
    loadavg_start: list[float]   # 1, 5, 15 min load averages when the bench started (others' work)
    loadavg_end: list[float]
    started: str                 # ISO 8601, UTC



def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def load_average() -> list[float]:
    """The 1, 5 and 15 minute load averages (empty where the OS has none)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def resolve_device(device: str) -> str:
    """"cpu" or "cuda": where the rasterizer runs for ``device`` ("auto" picks CUDA when present)."""
    from splatbench.raster.device import get_device

    return "cuda" if get_device(device).name == "cuda" else "cpu"


def machine_info(device: str) -> MachineInfo:
    """The `MachineInfo` of this machine now, with ``device`` resolved (`resolve_device`)."""
    versions = [package_version(p) for p in ("splatbench", "drjit", "mitsuba", "torch")]
    return MachineInfo(os.cpu_count(), _cpu_model(), platform.platform(), platform.python_version(), *versions,
                       resolve_device(device), load_average(), load_average(),
                       datetime.now(timezone.utc).isoformat(timespec="seconds"))
