"""Seeded area-uniform sampling of a Mitsuba scene's true surfaces: the one implementation.

`sample_surface` is used by ``splatbench.scenes`` (public API) and by
`splatbench.gaussians_from_points.from_surface`; both get the same points for the same seed
because there is only this copy. Shapes are taken in a canonical order (`shape_order_key`):
Mitsuba loads plugins in parallel, so ``mi.Scene.shapes()`` comes back in a different
order from one load to the next, and a seed must give the same points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from splatbench.errors import InputError
from splatbench.mitsuba_loader import mitsuba


@dataclass(frozen=True)
class SurfacePoints:
    """Points sampled uniformly by area on a scene's shapes.

    ``xyz`` [M, 3] float64 world positions; ``normals`` [M, 3] float64 unit shading-frame
    normals (the side the shape's normal points to); ``shape_index`` [M] int64 index into
    ``shape_ids`` (the shapes' XML ids, in `shape_order_key` order); ``albedo`` [M, 3]
    float64 linear diffuse reflectance in [0, 1] when asked for (``albedo=True``), else None.
    """

    xyz: np.ndarray
    normals: np.ndarray
    shape_index: np.ndarray
    shape_ids: list[str]
    albedo: np.ndarray | None = None


def shape_order_key(shape) -> tuple:
    """A load-order-independent sort key: XML id, plugin class, area, bounding box."""
    bbox = shape.bbox()
    corners = tuple(round(float(v), 9) for v in (*np.asarray(bbox.min).ravel(), *np.asarray(bbox.max).ravel()))
    return (shape.id(), shape.class_name(), round(_area(shape), 9), corners)


def _area(shape) -> float:
    return float(np.asarray(shape.surface_area()).reshape(-1)[0])


def _columns(value, m: int, dims: int) -> np.ndarray:
    """Dr.Jit [dims, m] or [dims, 1] (planar shapes: one constant normal) -> [m, dims] float64."""
    arr = np.asarray(value, dtype=np.float64).reshape(dims, -1)
    return np.broadcast_to(arr, (dims, m)).T.copy()


def sample_surface(mi_scene, n: int, *, seed: int = 0, include_emitters: bool = False,
                   albedo: bool = False) -> SurfacePoints:
    """``n`` points uniform by area over ``mi_scene.shapes()`` (area lights left out unless asked).

    Each shape (in `shape_order_key` order) gets a multinomial share of ``n``
    proportional to its area, then ``shape.sample_position`` with seeded uniform
    samples. Deterministic for a seed. With ``albedo=True`` each point also gets
    ``shape.bsdf().eval_diffuse_reflectance`` seen from its normal side, clipped to
    [0, 1] (0.5 where a shape has no BSDF or the value is not finite).
    """
    mi = mitsuba()
    if not (isinstance(n, int) and n >= 0):
        raise InputError(f"n: expected an int >= 0, got {n!r}")
    shapes = sorted((s for s in mi_scene.shapes() if include_emitters or not s.is_emitter()), key=shape_order_key)
    if not shapes:
        raise InputError("scene: has no shapes to sample")
    areas = np.array([_area(s) for s in shapes])
    rng = np.random.default_rng(seed)
    counts = rng.multinomial(n, areas / areas.sum())
    xyz, normals, index, rgb = [], [], [], []
    for k, (shape, m) in enumerate(zip(shapes, counts)):
        if m == 0:
            continue
        u = rng.random((2, m), dtype=np.float32)
        ps = shape.sample_position(0.0, mi.Point2f(u[0], u[1]))
        xyz.append(_columns(ps.p, m, 3))
        normals.append(_columns(ps.n, m, 3))
        index.append(np.full(m, k, dtype=np.int64))
        if albedo:
            bsdf = shape.bsdf()
            if bsdf is None:
                rgb.append(np.full((m, 3), 0.5))
                continue
            si = mi.SurfaceInteraction3f(ps, mi.Color0f())
            si.wi = mi.Vector3f(0.0, 0.0, 1.0)
            rgb.append(_columns(bsdf.eval_diffuse_reflectance(si), m, 3))
    cat = (lambda a, w: np.concatenate(a) if a else np.zeros((0, w)))
    colors = None
    if albedo:
        colors = cat(rgb, 3)
        colors[~np.isfinite(colors).all(axis=1)] = 0.5
        colors = np.clip(colors, 0.0, 1.0)
    return SurfacePoints(cat(xyz, 3), cat(normals, 3), np.concatenate(index) if index else np.zeros(0, np.int64),
                         [s.id() for s in shapes], colors)
