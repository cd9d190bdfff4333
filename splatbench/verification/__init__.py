"""The verification core: what compare, conform, regress and stress share when they check a rasterizer.

Modules (each imports only those above it in this list, and lower layers):

    bounds      the float32 bound of a rasterizer against the float64 oracle, the boundary bands'
                part in it (`FORWARD_ATOL`, `gradient_bound`, `BAND_BUDGET`, `over_bound`) and the
                judged measurements (`ImageError`, `GradError`)
    cotangents  the seeded random cotangents of every gradient check (`Cotangents`), drawn here only
    calls       a backend's checked forward and VJP (`render`, `forward`, `vjp`), faults in one line
    judging     relative L2 errors, the gradient band per entry, a gradient against the oracle's
"""
