"""Seeded scenes for the parity and gradient tests.

`parity_scene` (the parity scenes, shared with regress's ``parity`` scene set) lives in
`splatbench.workloads`; `smooth_scene` here: a scene where no threshold is active.
"""

from __future__ import annotations

import numpy as np

from splatbench import Camera, Gaussians
from splatbench.workloads import Workload, parity_scene, random_camera_pose, random_unit_quats  # noqa: F401 - parity_scene: the tests' import


def smooth_scene(seed: int, n: int = 4, size: tuple[int, int] = (20, 16)) -> Workload:
    """A scene where no threshold of the matched rasterizer is active: Gaussians well
    inside the image, opacities in [0.2, 0.7] (no alpha clamp), moderate sizes, few
    enough that transmittance stays far above its stop threshold, positive colours.
    Rendered with ``alpha_min`` tiny, ``radius="opacity"`` and ``transmittance_min=0``
    it is the smooth function of `reference.render(mode="exact")`."""
    rng = np.random.default_rng(20_000 + seed)
    W, H = size
    fx = fy = 1.2 * W
    cx, cy = W / 2 + 0.7, H / 2 - 0.4
    z = rng.uniform(3, 5, n)
    u, v = rng.uniform(0.3 * W, 0.7 * W, n), rng.uniform(0.3 * H, 0.7 * H, n)
    cam_pts = np.stack([(u - cx) * z / fx, (v - cy) * z / fy, z], axis=1)
    sigma = rng.uniform(1.5, 3.0, n)
    log_scales = np.log(sigma * z / fx)[:, None] + 0.2 * rng.standard_normal((n, 3))
    logits = rng.uniform(-1.4, 0.8, n)  # sigmoid in [0.2, 0.69]
    sh = np.concatenate([rng.uniform(0.6, 1.2, (n, 1, 3)), 0.1 * rng.standard_normal((n, 15, 3))], 1)
    w2c = random_camera_pose(rng)
    R, t = w2c[:3, :3], w2c[:3, 3]
    gaussians = Gaussians((cam_pts - t) @ R, log_scales, random_unit_quats(rng, n), logits, sh)
    return Workload(f"smooth-{seed}", gaussians, Camera(W, H, fx, fy, cx, cy, w2c))
