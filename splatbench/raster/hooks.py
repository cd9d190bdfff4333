"""Test and benchmark hooks of the render path, kept off the public signatures.

`splatbench.render` and `splatbench.rasterize` never take them; the internal entry point
`torch_bridge.rasterize_with_hooks` (used by the gradient tests and by
`splatbench.metrics.timing`) hands one `Hooks` to `pipeline.render_frame`.
"""

from __future__ import annotations

from dataclasses import dataclass

from splatbench.raster.timing import StageTimer


@dataclass(frozen=True)
class Hooks:
    """loop_ad: tests only; differentiate compositing with Dr.Jit's AD through the forward
    loop (`compositing.composite_loop_ad`) instead of the hand-written backward pass.
    timer: benchmarks only; a `StageTimer` charged per stage, forward and backward (its
    marks wait for Dr.Jit, so a timed call runs slower)."""

    loop_ad: bool = False
    timer: StageTimer | None = None


#: What the public entry points pass: no hook.
NO_HOOKS = Hooks()
