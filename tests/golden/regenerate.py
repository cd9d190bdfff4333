"""Regenerate the golden gradient files: `make golden` (never run by the tests).

Each file holds the outputs and the random-cotangent gradients of one fixed scene.
Regenerate only after an intended change of the maths, and say why in the commit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.gradcheck import Cotangents, fast_vjp
from tests.scenes import parity_scene

GOLDEN_DIR = Path(__file__).parent
GOLDEN_SEEDS = (0, 7, 13)


def golden_path(seed: int) -> Path:
    return GOLDEN_DIR / f"scene{seed}.npz"


def compute(seed: int):
    workload, background = parity_scene(seed)
    c = workload.camera
    return fast_vjp(workload, Cotangents.standard_normal(500 + seed, c.height, c.width), background=background)


def main() -> None:
    for seed in GOLDEN_SEEDS:
        vjp = compute(seed)
        np.savez_compressed(golden_path(seed), rgb=vjp.rgb, alpha=vjp.alpha, depth=vjp.depth,
                            **{f"grad_{k}": g for k, g in vjp.grads.items()})
        print(f"wrote {golden_path(seed)}")


if __name__ == "__main__":
    main()
