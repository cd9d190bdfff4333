"""The Dr.Jit tile rasterizer: `render` (numpy) and `rasterize` (torch, differentiable).

Ops mirror `reference/` by name: `project`, `eval_sh`, `composite`. The stages hand typed
results on: `project` -> `Projection`, `bin_gaussians` -> `Bins`, `composite` -> `Composite`;
each reads its options from one `RasterOptions`.
"""

from splatbench.raster.api import RenderResult, render
from splatbench.raster.binning import Bins, TileGrid, bin_gaussians
from splatbench.raster.compositing import composite
from splatbench.raster.options import RasterOptions
from splatbench.raster.projection import project
from splatbench.raster.sh import eval_sh
from splatbench.raster.work import WorkStats, work_stats


def __getattr__(name: str):
    """`rasterize` and `RasterInfo` need torch: import it only when they are used."""
    if name in ("rasterize", "RasterInfo"):
        from splatbench.raster import torch_bridge

        return getattr(torch_bridge, name)
    raise AttributeError(f"module 'splatbench.raster' has no attribute {name!r}")


__all__ = ["render", "RenderResult", "rasterize", "RasterInfo", "RasterOptions", "project", "eval_sh", "bin_gaussians",
           "TileGrid", "Bins", "composite", "work_stats", "WorkStats"]
