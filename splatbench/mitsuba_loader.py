"""The one place that imports Mitsuba 3 and chooses its variant.

Every Mitsuba user in splatbench (dataset rendering in `splatbench.scenes.render`,
surface sampling, the ray-traced validation in `splatbench.validate.mitsuba`, the
Mitsuba backend, `Camera.to_mitsuba`) gets the module from `mitsuba`, so the variant
rule is written once:

* ``mitsuba()`` sets `MITSUBA_VARIANT` (``llvm_ad_rgb``: the JIT variant that renders
  scenes and differentiates), switching from any other variant;
* ``mitsuba(variant=None)`` keeps the variant already set (``scalar_rgb`` when none is):
  for conversions such as `Camera.to_mitsuba` that work in whatever variant the caller
  uses.

Mitsuba is imported on first call; ``splatbench/__init__`` (which runs before this module
can) has already set ``DRJIT_LIBLLVM_PATH``, so Dr.Jit loads a libLLVM >= 16.
"""

from __future__ import annotations

from types import ModuleType

from splatbench import _llvm
from splatbench.errors import InputError

#: The variant splatbench renders with (Dr.Jit LLVM backend, AD, RGB).
MITSUBA_VARIANT = "llvm_ad_rgb"
#: The variant set when the caller asks to keep the current one and none is set yet.
FALLBACK_VARIANT = "scalar_rgb"


def mitsuba(variant: str | None = MITSUBA_VARIANT) -> ModuleType:
    """The ``mitsuba`` module with its variant set (see the module docstring for the rule)."""
    import mitsuba as mi  # splatbench/__init__ (run before any splatbench module) picked libLLVM

    if variant is not None and variant.startswith("llvm_"):
        try:
            _llvm.require()
        except _llvm.LLVMNotFoundError as exc:
            raise InputError(f"Mitsuba variant {variant}: {exc}") from None
    if variant is None:
        if mi.variant() is None:
            mi.set_variant(FALLBACK_VARIANT)
    elif mi.variant() != variant:
        mi.set_variant(variant)
    return mi
