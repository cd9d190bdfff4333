"""`splatbench conform --save-images DIR`: per probe, the backend's render, the oracle's (under the declared
conventions) and their difference with a colour scale, as PNGs a user can look at."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from splatbench.backends.base import Backend
from splatbench.conform.calls import captured
from splatbench.verification.calls import Fault, forward
from splatbench.conform.oracle import conventions_of, oracle
from splatbench.conform.probes import Probe
from splatbench.plotting import pyplot
from splatbench.report_files import save_figure

UPSCALE = 16  # probe images are 12 to 32 pixels wide: each pixel drawn as a 16x16 block


def _big(image: np.ndarray) -> np.ndarray:
    return np.repeat(np.repeat(image, UPSCALE, axis=0), UPSCALE, axis=1)


def _difference_png(diff: np.ndarray, path: Path, title: str) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.2, 3.4), dpi=100)
    im = ax.imshow(diff, cmap="magma", vmin=0.0, vmax=max(float(diff.max()), 1e-12), interpolation="nearest")
    ax.set_title(title, fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.colorbar(im, ax=ax, label="max |backend - oracle| over rgb, alpha")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)


def save_images(backend: Backend, probes: tuple[Probe, ...], directory: str | Path, device: str) -> list[Path]:
    """Write PROBE_backend.png, PROBE_oracle.png (rgb) and PROBE_difference.png (colour scale) for each
    probe whose scene the backend renders; returns the paths written."""
    from splatbench.images import save_png

    out, conv = Path(directory), conventions_of(backend)
    written = []
    for probe in probes:
        s = probe.build()
        try:
            with captured():
                got = forward(backend, s, device)
        except Fault:
            continue
        ref = oracle(probe.build.__name__, s, conv)
        diff = np.abs(got[..., :4] - ref[..., :4]).max(-1)
        for label, image in (("backend", got), ("oracle", ref)):
            written.append(save_png(_big(image[..., :3]), out / f"{probe.name}_{label}.png"))
        path = out / f"{probe.name}_difference.png"
        _difference_png(diff, path, f"{probe.name}: largest {diff.max():.2e}")
        written.append(path)
    return written
