"""The Dr.Jit tile rasterizer: `render` (numpy) and `rasterize` (torch, differentiable).

Ops mirror `reference/` by name: `project`, `eval_sh`, `composite`.
"""

from splatbench.raster.api import RenderResult, render
from splatbench.raster.compositing import composite
from splatbench.raster.options import RasterOptions
from splatbench.raster.projection import project
from splatbench.raster.sh import eval_sh
from splatbench.raster.torch_bridge import RasterInfo, rasterize

__all__ = ["render", "RenderResult", "rasterize", "RasterInfo", "RasterOptions", "project", "eval_sh", "composite"]
