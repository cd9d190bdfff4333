"""How often Mitsuba's ray-ellipsoid test misjudges hit/miss (the "Scale" caveat of the package)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from splatbench.backends.builtins.mitsuba_scene import ELLIPSOID_EXTENT, mitsuba_volprim


@dataclass(frozen=True)
class ProbeRow:
    """How often Mitsuba's ray-ellipsoid test disagrees with the exact one (``m_ray < 3``)."""

    sigma: float           # the Gaussian's (isotropic) standard deviation, world units
    distance_ratio: float  # ray origin distance / sigma
    rays: int
    wrong: float           # fraction of rays whose hit/miss differs from the exact test
    max_m_error: float     # largest |m_ray - 3| among the wrong rays (0 when none)


def intersection_probe(sigmas: Sequence[float] = (0.01, 0.1, 1.0, 10.0),
                       ratios: Sequence[float] = (10, 30, 100, 300, 1000), *, rays: int = 20000,
                       seed: int = 0) -> list[ProbeRow]:
    """Shoot ``rays`` rays at one isotropic ``ellipsoids`` primitive and check each hit/miss.

    For each sigma and distance ratio, rays start on the axis at distance
    ``ratio * sigma`` and pass the centre at a Mahalanobis distance drawn uniformly in
    [0, 6]; the exact answer is a hit when that distance is below the extent (3).
    """
    mi = mitsuba_volprim()
    out = []
    for sigma in sigmas:
        data = np.array([[0.0, 0.0, 0.0, sigma, sigma, sigma, 0.0, 0.0, 0.0, 1.0]], np.float32)
        scene = mi.load_dict({"type": "scene", "shape": {"type": "ellipsoids", "extent": ELLIPSOID_EXTENT,
                                                         "data": mi.TensorXf(data)}})
        for ratio in ratios:
            rng = np.random.default_rng(seed)
            m = rng.uniform(0.0, 6.0, rays)
            phi = rng.uniform(0.0, 2 * math.pi, rays)
            target = np.stack([np.cos(phi) * m * sigma, np.sin(phi) * m * sigma, np.zeros(rays)], axis=1)
            origin = np.array([0.0, 0.0, -ratio * sigma])
            d = target - origin
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            m_exact = np.linalg.norm(-origin[None] - (d @ -origin)[:, None] * d, axis=1) / sigma
            ray = mi.Ray3f(mi.Point3f(*[np.full(rays, c, np.float32) for c in origin]),
                           mi.Vector3f(*[np.ascontiguousarray(d[:, k], dtype=np.float32) for k in range(3)]))
            hit = np.asarray(scene.ray_intersect(ray).is_valid(), dtype=bool)
            wrong = hit != (m_exact < ELLIPSOID_EXTENT)
            out.append(ProbeRow(float(sigma), float(ratio), rays, float(wrong.mean()),
                                float(np.abs(m_exact[wrong] - ELLIPSOID_EXTENT).max()) if wrong.any() else 0.0))
    return out
