"""The built-in backends, one module each (registered by name in `splatbench.backends.registry`).

    drjit_backend       "drjit": splatbench's Dr.Jit tile rasterizer (`splatbench.rasterize`)
    reference_backend   "reference", "reference-exact": the float64 NumPy oracle, and
                        `reference_render`, THE adapter from splatbench inputs to `reference.render`
    torch_backend       "torch", "torch64": an independent pure-PyTorch implementation
    gsplat_backend      "gsplat": gsplat 1.5.3 (optional extra ``.[gsplat]``)
    mitsuba_backend     "mitsuba": ray-traced Gaussians (Mitsuba's volprim ellipsoids)

Modules are imported only when their backend is asked for.
"""
