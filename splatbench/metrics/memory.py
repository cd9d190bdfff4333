"""Peak resident set size of the current process, for benchmarks."""

from __future__ import annotations

import resource
import sys

_MB = 1e6


def peak_rss_mb() -> float:
    """The process's peak RSS so far in MB (10^6 bytes), from ``getrusage(RUSAGE_SELF).ru_maxrss``
    (KiB on Linux, bytes on macOS)."""
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    scale = 1 if sys.platform == "darwin" else 1024
    return maxrss * scale / _MB


def reset_peak_rss() -> bool:
    """Reset the peak RSS ("high-water mark") to the current RSS, so that a later
    `peak_rss_mb` covers only what ran since. Linux >= 4.0 (``/proc/self/clear_refs``);
    returns False where that is unavailable and the peak keeps counting from the start."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return True


def current_rss_mb() -> float:
    """The process's resident set size now, in MB (10^6 bytes)."""
    import psutil

    return psutil.Process().memory_info().rss / _MB
