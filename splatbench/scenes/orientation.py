"""Which way is up in a dataset: declared for a splatbench render, unknown for a capture.

A dataset rendered by ``splatbench scenes render`` (its folder holds a splatbench
``manifest.json``) has cameras that are all ``Camera.look_at(eye, target, rig.up, ...)``:
no roll, so every camera's x axis (image right) is perpendicular to the rig's ``up``.
`rig_up` recovers that direction from the cameras alone -- exactly, whichever rig and
whichever up (the built-in scenes are y-up) -- so datasets rendered before anything
recorded it work too. A COLMAP capture's world has no declared up (COLMAP's is arbitrary,
usually y down like its first camera): `dataset_up` gives None there, and
``splatbench render`` keeps its y-down default.

    dataset_up(folder, cameras) -> [3] unit vector or None
    rig_up(cameras) -> [3] unit vector
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from splatbench.cameras import Camera

#: Smallest ratio of the 2nd smallest to the largest eigenvalue of Σ r rᵀ (r: camera x axes)
#: for which the null direction is well defined; below it the x axes are (nearly) parallel.
_MIN_SPREAD = 1e-6


def rig_up(cameras: Sequence[Camera]) -> np.ndarray:
    """[3] the world direction that is up in every image of a rig without roll.

    The direction perpendicular to every camera's x axis (the eigenvector of the smallest
    eigenvalue of Σ r rᵀ over the x axes r), signed to agree with the cameras' mean
    image-up (-y axis). When all x axes are parallel (one view, or views along one
    azimuth) that direction is not unique and the cameras' mean image-up is returned.
    Components below 1e-12 are set to 0, so an axis comes out exact.
    """
    if not cameras:
        raise ValueError("rig_up: no cameras")
    rotations = np.stack([np.asarray(c.rotation, dtype=np.float64) for c in cameras])  # [V, 3, 3] world -> camera
    rights, image_ups = rotations[:, 0, :], -rotations[:, 1, :]
    mean_up = image_ups.mean(axis=0)
    values, vectors = np.linalg.eigh(rights.T @ rights)  # ascending
    if values[1] > _MIN_SPREAD * values[2]:
        up = vectors[:, 0] * (1.0 if vectors[:, 0] @ mean_up >= 0 else -1.0)
    else:
        up = mean_up
    up = np.where(np.abs(up) < 1e-12, 0.0, up)
    return up / np.linalg.norm(up)


def dataset_up(folder: str | Path, cameras: Sequence[Camera]) -> np.ndarray | None:
    """[3] the declared up of the dataset in ``folder`` (its ``cameras``): `rig_up` for a
    splatbench render (a splatbench ``manifest.json``), None for anything else."""
    from splatbench.scenes.render import DATASET_FORMAT, read_manifest

    manifest = read_manifest(folder)
    if manifest is None or manifest.get("format") != DATASET_FORMAT or not cameras:
        return None
    return rig_up(cameras)
