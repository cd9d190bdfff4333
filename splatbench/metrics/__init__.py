"""Measurement, below every application (docs/architecture.md): what train, bench,
experiments, reports, compare and conform measure with, so that none of them borrows
from another.

* `image`: PSNR (the one PSNR of splatbench), SSIM, LPIPS of rendered images;
* `timing`: the rasterizer's timing closures and per-stage split;
* `memory`: peak and current resident set size;
* `load`: the load of *other* processes around a timed section (the quiet-machine rule);
* `machine`: where a measurement ran (`MachineInfo`);
* `stats`: intervals over seeds, paired differences and ratios, bootstrap of a median ratio;
* `spec`: how a report shows a metric (`MetricSpec`).
"""

from splatbench.metrics.image import psnr, ssim_metric

__all__ = ["psnr", "ssim_metric"]
