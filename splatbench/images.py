"""Image files: 8-bit PNG written atomically (temporary file, then rename)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from splatbench.fsutil import atomic_write


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """[H, W, 3] or [H, W] floats in [0, 1] -> uint8 (clipped; NaN becomes 0)."""
    return (np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64)), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Write ``image`` ([H, W, 3] or [H, W], floats in [0, 1]) as PNG, atomically
    (`splatbench.fsutil.atomic_write`); returns the path."""
    from PIL import Image

    return atomic_write(path, lambda temp: Image.fromarray(to_uint8(image)).save(temp, format="PNG"))
