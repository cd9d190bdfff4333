"""Cross-renderer validation of the splat rasterizer.

Submodules, imported on demand:

* `splatbench.validate.mitsuba` -- the rasterizer against Gaussians ray-traced by
  Mitsuba's ``volprim_rf_basic`` (``splatbench validate mitsuba``; docs/validation.md).

(The boundary checks on arrays that every public function uses live in
`splatbench.guards`.)
"""
