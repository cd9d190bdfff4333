"""`splatbench.backends`: any 3DGS rasterizer behind one typed interface.

    Backend, BackendInfo   a rasterizer callable and its metadata (see `base`)
    as_numpy(x)            a backend's tensor or array as float64 numpy on the host
    get_backend(spec)      a built-in ("drjit", "torch", "torch64", "gsplat", "mitsuba", "reference",
                           "reference-exact"; see `builtins`), an entry point in group
                           "splatbench.backends", or "module:function"
    as_backend(fn)         wrap a plain callable (graphdeco conventions, nothing declared)
    available()            names of the built-in and installed backends
    reference_render(conventions, means, ..., camera, mode=)
                           the float64 oracle following a backend's declared conventions
                           (numpy out): the one adapter from splatbench inputs to `reference`
"""

from splatbench.backends.base import GRAPHDECO, OUTPUTS, Backend, BackendInfo, RasterFn, as_numpy
from splatbench.backends.builtins.reference_backend import reference_render
from splatbench.backends.registry import ENTRY_POINT_GROUP, as_backend, available, get_backend, register_builtin

__all__ = ["Backend", "BackendInfo", "RasterFn", "as_numpy", "GRAPHDECO", "OUTPUTS", "ENTRY_POINT_GROUP", "as_backend",
           "available", "get_backend", "reference_render", "register_builtin"]
