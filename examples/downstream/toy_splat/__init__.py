"""toy_splat: a small dense 3DGS rasterizer (every Gaussian at every pixel), written from
splatbench's docs/conventions.md, to show how a project regression-tests its gradients."""

from toy_splat.rasterizer import render

__all__ = ["render"]
