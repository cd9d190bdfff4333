"""Seeded scenes for the parity and gradient tests.

Gaussians are generated in camera space (so they land in view) and moved to the
world through a random rigid camera pose; intrinsics have off-centre principal
points and non-square images. Each seed picks one kind of scene.
"""

from __future__ import annotations

import numpy as np

from splatbench import Camera, Gaussians
from splatbench.gaussians import quat_to_rotmat
from splatbench.workloads import Workload, random_unit_quats

KINDS = ("standard", "overlap", "needles", "tiny", "large")


def random_pose(rng: np.random.Generator) -> np.ndarray:
    """A random world_to_camera [4, 4] (rotation from a random unit quaternion)."""
    M = np.eye(4)
    M[:3, :3] = quat_to_rotmat(random_unit_quats(rng, 1)[0])
    M[:3, 3] = rng.uniform(-3, 3, 3)
    return M


def parity_scene(seed: int) -> tuple[Workload, tuple[float, float, float]]:
    """(workload, background) for parity scene ``seed``; the kind cycles with the seed."""
    rng = np.random.default_rng(10_000 + seed)
    kind = KINDS[seed % len(KINDS)]
    degree = seed % 4
    W, H = int(rng.integers(24, 72)), int(rng.integers(24, 72))
    n = int(rng.choice([1, 12, 60, 200, 400])) if kind != "overlap" else 300
    fx = W * rng.uniform(0.8, 1.5)
    fy = fx * rng.uniform(0.9, 1.1)
    cx = W / 2 + rng.uniform(-0.15, 0.15) * W
    cy = H / 2 + rng.uniform(-0.15, 0.15) * H
    z = rng.uniform(2, 6, n)
    if kind == "overlap":  # heavy overlap: a dense, opaque clump at the centre
        u, v = rng.normal(cx, 0.1 * W, n), rng.normal(cy, 0.1 * H, n)
    else:  # include some Gaussians beyond the image edges
        u, v = rng.uniform(-0.1 * W, 1.1 * W, n), rng.uniform(-0.1 * H, 1.1 * H, n)
    sigma_px = {"standard": (0.3, 6.0), "overlap": (1.0, 8.0), "needles": (0.5, 4.0), "tiny": (0.05, 0.8),
                "large": (5.0, 25.0)}[kind]
    aniso = 1.5 if kind == "needles" else 0.25
    cam_pts = np.stack([(u - cx) * z / fx, (v - cy) * z / fy, z], axis=1)
    sigma = np.exp(rng.uniform(np.log(sigma_px[0]), np.log(sigma_px[1]), n))
    log_scales = np.log(sigma * z / fx)[:, None] + aniso * rng.standard_normal((n, 3))
    logits = rng.normal(2.0 if kind == "overlap" else 0.0, 1.5, n)
    k = (degree + 1) ** 2
    sh = np.concatenate([0.6 * rng.standard_normal((n, 1, 3)), 0.1 * rng.standard_normal((n, k - 1, 3))], 1)
    w2c = random_pose(rng)
    R, t = w2c[:3, :3], w2c[:3, 3]
    means = (cam_pts - t) @ R  # R^T (p - t), row-wise
    gaussians = Gaussians(means, log_scales, random_unit_quats(rng, n), logits, sh)
    camera = Camera(W, H, fx, fy, cx, cy, w2c)
    background = tuple(rng.uniform(0, 1, 3)) if seed % 2 else (0.0, 0.0, 0.0)
    return Workload(f"parity-{seed}-{kind}-d{degree}", gaussians, camera), background


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
    w2c = random_pose(rng)
    R, t = w2c[:3, :3], w2c[:3, 3]
    gaussians = Gaussians((cam_pts - t) @ R, log_scales, random_unit_quats(rng, n), logits, sh)
    return Workload(f"smooth-{seed}", gaussians, Camera(W, H, fx, fy, cx, cy, w2c))
