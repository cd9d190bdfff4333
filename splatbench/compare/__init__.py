"""`splatbench compare`: any rasterizers side by side against the float64 oracle.

A verification application beside `splatbench.conform`, `splatbench.stress` and
`splatbench.validate`; it calls rasterizers through the plugin interface
(`splatbench.backends`). Modules:

    run       run_compare(backends, workloads, settings) -> CompareResult (what is measured)
    measure   oracle images, image errors, the gradient oracle, interleaved timing (the float32 bound,
              the cotangents, a backend's VJP and the gradient judgement: `splatbench.verification`)
    timing    the typed timing of one backend (Timing)
    report    results.parquet, run.json (a typed CompareRecord), report.md and the figures (write_compare,
              rewrite_report)
    cli       the command line

The package imports none of them here, so ``splatbench compare --help`` loads nothing heavy.
"""
