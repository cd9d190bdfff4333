"""Checks the finding of reports/conform_public/metal-gauss/report.md: metal-gauss 0.2.1's torch_ref
with its "too wide" cull switched off (`max_radius_frac`, torch_ref.py:140-141), through the same
adapter, under conform. A what-if.

    PYTHONPATH=.:out/conform_public/site-metal-gauss python tools/verify_metal_gauss.py [FRAC]

FRAC replaces the package's default max_radius_frac=1.0 (1e9 by default: no Gaussian is culled for
its size).
"""

from __future__ import annotations

import functools
import sys

import metal_gauss.torch_ref as torch_ref

import examples.adapters.metal_gauss as adapter
from splatbench.backends import Backend
from splatbench.conform import conform


def main(argv: list[str]) -> None:
    frac = float(argv[0]) if argv else 1e9
    torch_ref.render = functools.partial(torch_ref.render, max_radius_frac=frac)  # metal_gauss.api calls this
    rep = conform(Backend(adapter.render, adapter.render.backend_info), device="cpu")
    print(f"max_radius_frac={frac:g}")
    for status in ("pass", "explained", "warn", "fail", "skip"):
        names = [r.name for r in rep.results if r.status == status]
        print(f"  {status} ({len(names)}): {' '.join(names)}")
    print("  diagnosis:", "; ".join(f"{d.axis}: {d.found} (explains {', '.join(d.explains)})"
                                    for d in rep.diagnosis) or "none")
    print("  defects:", "; ".join(d.probe for d in rep.defects) or "none")
    for d in rep.defects:
        print(f"    {d.probe} (+{len(d.follows)} follow): {d.cause}")
    for r in rep.results:
        if r.status == "warn":
            print(f"  warn {r.name}: {r.detail}")


if __name__ == "__main__":
    main(sys.argv[1:])
