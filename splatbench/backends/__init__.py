"""`splatbench.backends`: any 3DGS rasterizer behind one typed interface.

    Backend, BackendInfo   a rasterizer callable and its metadata (see `base`)
    get_backend(spec)      "drjit", "torch", "gsplat", "reference", "mitsuba", an entry point
                           in group "splatbench.backends", or "module:function"
    as_backend(fn)         wrap a plain callable (graphdeco conventions, nothing declared)
    available()            names of the built-in and installed backends
"""

from splatbench.backends.base import GRAPHDECO, OUTPUTS, Backend, BackendInfo, RasterFn
from splatbench.backends.registry import ENTRY_POINT_GROUP, as_backend, available, get_backend, register_builtin

__all__ = ["Backend", "BackendInfo", "RasterFn", "GRAPHDECO", "OUTPUTS", "ENTRY_POINT_GROUP", "as_backend",
           "available", "get_backend", "register_builtin"]
