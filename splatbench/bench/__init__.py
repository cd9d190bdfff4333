"""Benchmarks, kept apart from tests (`splatbench bench ...`).

``raster``: run time, per-stage split, throughput and peak memory of the Dr.Jit
rasterizer on the standard synthetic workloads and real captures. See
docs/benchmarks.md. What it measures with (timing, memory, load, machine facts) is
`splatbench.metrics`. Importing this package is cheap: the heavy modules load on use.
"""
