"""Measurements of images: LPIPS (`splatbench.metrics.lpips`)."""

from splatbench.metrics.lpips import lpips

__all__ = ["lpips"]
