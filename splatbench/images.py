"""Image files: 8-bit PNG written atomically (temporary file, then rename)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from splatbench.fsutil import replace_file


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """[H, W, 3] or [H, W] floats in [0, 1] -> uint8 (clipped; NaN becomes 0)."""
    return (np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64)), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Write ``image`` ([H, W, 3] or [H, W], floats in [0, 1]) as PNG; returns the path."""
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".png", dir=path.parent)
    os.close(fd)
    try:
        Image.fromarray(to_uint8(image)).save(tmp, format="PNG")
        replace_file(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
