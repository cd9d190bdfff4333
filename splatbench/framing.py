"""Cameras that frame a set of Gaussians: one view (`framing_camera`) or a rig around the up axis
(`framing_rig`), as `splatbench render`, `compare --model` and teacher scenes need them."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError

#: The up direction assumed for a PLY that records none: -y, as COLMAP captures (and so
#: graphdeco's models of them) have their world y axis pointing down.
DEFAULT_UP = (0.0, -1.0, 0.0)
#: `--up`'s axis names: +x, -x, +y, -y, +z, -z.
AXES = {f"{sign}{axis}": tuple(value if a == axis else 0.0 for a in "xyz")
         for axis in "xyz" for sign, value in (("+", 1.0), ("-", -1.0))}


def parse_up(text: str) -> tuple[float, float, float]:
    """``--up``: an axis (``+y``, ``-z``, ...) or ``X,Y,Z``; a unit vector."""
    from splatbench.ply import ViewHints

    try:
        return ViewHints(up=AXES.get(text.strip().lower()) or text.split(",")).up
    except InputError:
        raise InputError(f"--up: expected one of {', '.join(AXES)} or X,Y,Z (3 finite numbers, not all zero), "
                         f"got {text!r}") from None


#: Elevation of the framing camera when the world's up is known (it then looks down onto
#: the floor, as the scene rigs do); 0 when the up is assumed.
KNOWN_UP_ELEVATION = 20.0


def framing_camera(gaussians, width: int, height: int, fov_x_deg: float = 50.0, up=DEFAULT_UP,
                   elevation_deg: float = 0.0, azimuth_deg: float = 0.0) -> Camera:
    """A look-at camera that frames the central 98 % of the Gaussians, ``up`` [3] up in the image.

    It looks along the first world axis of +z, +y that is not within 25° of ``up`` (+z
    for a y-up or y-down world, +y for a z-up one), made perpendicular to ``up`` and turned
    by ``azimuth_deg`` about ``up``, from ``elevation_deg`` above that horizontal direction
    (down onto a floor).
    The framed radius is at least 3 standard deviations of the largest of those
    Gaussians (so one Gaussian, or several at one point, fill the view rather than
    vanish), and the near plane is 1 % of the camera's distance (so a small scene is
    not clipped by the default near plane)."""
    if len(gaussians) == 0:
        raise InputError("gaussians: 0 Gaussians, nothing to frame or render")
    up_ = np.asarray(up, dtype=np.float64)
    up_ = up_ / np.linalg.norm(up_)
    axes = (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    axis = next(a for a in axes if abs(a @ up_) < np.cos(np.radians(25)))  # one of them is: they are orthogonal
    forward = axis - (axis @ up_) * up_
    forward /= np.linalg.norm(forward)
    if azimuth_deg:
        a = np.radians(azimuth_deg)  # Rodrigues about up_ (forward is perpendicular to it)
        forward = np.cos(a) * forward + np.sin(a) * np.cross(up_, forward)
    lo, hi = np.percentile(gaussians.means, [1, 99], axis=0)
    center = (lo + hi) / 2
    sigma = float(np.percentile(np.exp(np.clip(gaussians.log_scales, -20, 20)).max(axis=1), 99))
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 3 * sigma, 1e-6)
    distance = radius / np.tan(np.radians(fov_x_deg) / 2) * 1.2
    if elevation_deg:
        e = np.radians(elevation_deg)
        forward = np.cos(e) * forward - np.sin(e) * up_
    return Camera.look_at(center - distance * forward, center, up_,
                          width, height, fov_x_deg, near=min(0.01, distance / 100))


def framing_rig(gaussians, n_views: int, width: int, height: int, *, up=DEFAULT_UP,
                elevation_deg: float = KNOWN_UP_ELEVATION, fov_x_deg: float = 50.0,
                azimuth0_deg: float = 0.0) -> Sequence[Camera]:
    """``n_views`` framing cameras (see `framing_camera`) at azimuths ``azimuth0_deg + 360 k / n_views``
    about ``up`` [3], all ``elevation_deg`` above the horizontal: a rig around a trained model."""
    if int(n_views) < 1:
        raise InputError(f"views: {n_views!r} is not a positive number of views")
    return [framing_camera(gaussians, width, height, fov_x_deg, up, elevation_deg,
                           azimuth0_deg + 360.0 * k / int(n_views)) for k in range(int(n_views))]
