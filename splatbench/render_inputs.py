"""The inputs of one render (`RenderInput`: Gaussians, a camera, a background) and the
building blocks of hand-made ones: Gaussians placed by where they land on screen and how
large they look there. (A Mitsuba scene that datasets are rendered from is `splatbench.scenes`.)

The verification applications each build their own scenes from these: conform's probe
scenes (`splatbench.conform.probe_scenes`), stress's degenerate cases (`splatbench.stress.cases`)
and validate's sweeps (`splatbench.validate.mitsuba.cases`); the synthetic workloads' random
rotations are `splatbench.workloads.random_unit_quats`. What they hand a rasterizer is a
`RenderInput` (regress's scenes and stress's cases add their name or category to it).

    RenderInput(means, log_scales, quats, opacity_logits, sh, camera, background=None, sh_degree=None)
    camera_points(camera, u, v, depth) -> [..., 3]  camera-space points seen at pixel position (u, v)
    to_world(camera, cam_pts [..., 3]) -> [..., 3]  camera space -> world (float64)
    point_at(camera, u, v, depth) -> [..., 3]       the world points seen at (u, v) at camera depth
    world_sigma(camera, sigma_px, depth)            the world standard deviation spanning sigma_px pixels
    logit(opacity)                                  the stored opacity (a logit) of an opacity in (0, 1)
    sh_dc(colours [N, 3]) -> [N, 1, 3]              SH whose degree-0 colour is ``colours``

Pixel positions follow docs/conventions.md: pixel (i, j) is sampled at (j + 0.5, i + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from splatbench.cameras import Camera
from splatbench.conventions import SH_C0
from splatbench.gaussians import GROUPS


@dataclass(frozen=True)
class RenderInput:
    """The inputs of one render, as the verification applications hand them to a rasterizer.

    means [N, 3], log_scales [N, 3], quats [N, 4] (w, x, y, z), opacity_logits [N],
    sh [N, K, 3]: the five parameter groups as given (not checked or converted, unlike
    `splatbench.Gaussians`: a stress case holds NaNs on purpose); ``camera``; the
    ``background`` (None = black) and the SH degree evaluated (None = every band in ``sh``).
    """

    means: np.ndarray
    log_scales: np.ndarray
    quats: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray
    camera: Camera
    background: tuple[float, float, float] | None = None
    sh_degree: int | None = None

    @property
    def n(self) -> int:
        """The number of Gaussians N."""
        return int(self.means.shape[0])

    def params(self) -> dict[str, np.ndarray]:
        """The five groups by name, in `GROUPS` order (a rasterizer's argument order)."""
        return {k: getattr(self, k) for k in GROUPS}


def camera_points(camera: Camera, u, v, depth) -> np.ndarray:
    """Camera-space points [..., 3] that project to pixel position (``u``, ``v``) at camera z
    ``depth`` (scalars or arrays of one shape, broadcast)."""
    u, v, z = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (u, v, depth)))
    return np.stack([(u - camera.cx) * z / camera.fx, (v - camera.cy) * z / camera.fy, z], axis=-1)


def to_world(camera: Camera, cam_pts) -> np.ndarray:
    """Camera-space points [..., 3] in world coordinates (float64): R^T (p - t)."""
    return (np.asarray(cam_pts, dtype=np.float64) - camera.translation) @ camera.rotation


def point_at(camera: Camera, u, v, depth) -> np.ndarray:
    """The world points [..., 3] seen at pixel position (``u``, ``v``) at camera z ``depth``."""
    return to_world(camera, camera_points(camera, u, v, depth))


def world_sigma(camera: Camera, sigma_px, depth):
    """The world standard deviation whose footprint spans ``sigma_px`` pixels at camera z
    ``depth`` (before eps2d; along x, through fx)."""
    return sigma_px * depth / camera.fx


def logit(opacity) -> np.ndarray:
    """log(o / (1 - o)): the stored opacity whose sigmoid is ``opacity`` (in (0, 1))."""
    o = np.asarray(opacity, dtype=np.float64)
    return np.log(o / (1.0 - o))


def sh_dc(colours) -> np.ndarray:
    """SH [N, 1, 3] whose degree-0 colour is ``colours`` [N, 3]: (colour - 0.5) / SH_C0."""
    return ((np.asarray(colours, dtype=np.float64) - 0.5) / SH_C0)[:, None, :]
