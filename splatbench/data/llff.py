"""LLFF's capture layout: ``poses_bounds.npy`` beside ``images/`` and ``images_N/``, and object masks.

``poses_bounds.npy`` (LLFF's ``imgs2poses.py``; the eight LLFF scenes of NeRF and 3DGS
papers, NeRD's captures) holds N x 17 float rows, one per image in the order of the
image names sorted: a 3 x 5 matrix in row-major order, then the near and far depth
bounds of the view::

    [ r00 r01 r02 tx h ]     columns 0..2: camera-to-world rotation, axes [down, right, back]
    [ r10 r11 r12 ty w ]     column 3: the camera centre in the world
    [ r20 r21 r22 tz f ]     column 4: height, width, focal (pixels) of the ORIGINAL images

so the project's camera (OpenCV axes x right, y down, z forward, ``docs/conventions.md``)
has camera-to-world columns ``[right, down, forward] = [c1, c0, -c2]``; its principal
point is the image centre, ``fx = fy = f`` scaled to the images read (LLFF stores no
distortion and one focal; the rotation is snapped to the nearest rotation, as a float32
file holds it to ~1e-7). `camera_from_row` and `row_from_camera` are the two directions; the world frame is kept as stored (no recentring, no rescaling by the
bounds, unlike NeRF's ``load_llff_data``), so a capture converted to another layout
loads to the same cameras.

`read_poses_bounds` checks the file as data from others (one `InputError` line naming
the file and the fix): no pickle, its header against its size, a 2-D numeric array of
17 columns, one row per image, every value finite, sizes whole and positive, focal
positive, ``0 < near < far``, rotations orthonormal; every message names the file's
full path and prints numbers as plain numbers. `folders` lists the capture's
``images_N/`` folders by factor. Masks are every layout's (`splatbench.data.masks`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from splatbench.cameras import Camera
from splatbench.data.masks import folders
from splatbench.errors import InputError
from splatbench.safeio import read_npy

POSES_FILE = "poses_bounds.npy"
#: Image files LLFF's loader reads (``load_llff.py``: names ending in JPG, jpg, png), any case here.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
#: LLFF's [down, right, back] camera-to-world columns -> OpenCV's [right, down, forward]:
#: ``c2w_opencv = c2w_llff @ _TO_OPENCV`` (a rotation: det +1; its own inverse's transpose)
_TO_OPENCV = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def camera_from_row(row: np.ndarray, where: str) -> tuple[Camera, float, float]:
    """``(camera at the original size, near, far)`` of one checked poses_bounds row [17]."""
    pose = np.asarray(row[:15], np.float64).reshape(3, 5)
    h, w, f = pose[:, 4]
    c2w = np.eye(4)
    c2w[:3, :3] = pose[:, :3] @ _TO_OPENCV
    c2w[:3, 3] = pose[:, 3]
    w2c = np.eye(4)
    w2c[:3, :3] = c2w[:3, :3].T
    w2c[:3, 3] = -c2w[:3, :3].T @ c2w[:3, 3]
    if np.abs(pose[:, :3]).max() > 1 + 1e-5:  # no entry of a rotation exceeds 1 (and 1e308 would overflow RᵀR)
        raise InputError(f"{where}: the rotation (columns 0..2 of the 3x5 pose) has an entry "
                         f"{np.abs(pose[:, :3]).max():.6g} > 1: not a rotation")
    try:
        Camera(int(w), int(h), float(f), float(f), w / 2, h / 2, w2c)  # checked as stored: a rotation?
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    # then the nearest rotation (SVD): rows stored in float32 are orthonormal to ~1e-7 only, and every
    # other layout holds a rotation exactly (COLMAP as a quaternion), so a converted capture loads the same
    u, _, vt = np.linalg.svd(c2w[:3, :3])
    rot = u @ vt
    w2c[:3, :3] = rot.T
    w2c[:3, 3] = -rot.T @ c2w[:3, 3]
    return Camera(int(w), int(h), float(f), float(f), w / 2, h / 2, w2c), float(row[15]), float(row[16])


def row_from_camera(camera: Camera, near: float, far: float) -> np.ndarray:
    """The poses_bounds row [17] float64 of ``camera`` (square pixels, principal point at
    the centre, no distortion: what LLFF can hold; `InputError` otherwise)."""
    if camera.fx != camera.fy:
        raise InputError(f"fx, fy: LLFF's [h, w, f] holds one focal, the camera has fx={float(camera.fx):g} "
                         f"fy={float(camera.fy):g}")
    if (camera.cx, camera.cy) != (camera.width / 2, camera.height / 2):
        raise InputError(f"cx, cy: LLFF's [h, w, f] puts the principal point at the image centre "
                         f"({camera.width / 2:g}, {camera.height / 2:g}), the camera has ({float(camera.cx):g}, "
                         f"{float(camera.cy):g})")
    if not 0 < near < far or not np.isfinite(far):
        raise InputError(f"near, far: expected 0 < near < far, finite, got {float(near):g}, {float(far):g}")
    c2w = camera.camera_to_world
    pose = np.zeros((3, 5))
    pose[:, :3] = c2w[:3, :3] @ _TO_OPENCV.T
    pose[:, 3] = c2w[:3, 3]
    pose[:, 4] = [camera.height, camera.width, camera.fx]
    return np.concatenate([pose.reshape(-1), [near, far]])


_VALID = ("a valid one is LLFF's N x 17 float array (one row per image), written by imgs2poses.py or by "
          "np.save(path, rows.astype(np.float64))")


def read_poses_bounds(path: Path, images: int, folder: str) -> np.ndarray:
    """The rows [images, 17] float64 of ``path``, checked (module doc); ``folder``: where
    the ``images`` images were listed, for the messages."""
    what = str(path)
    try:
        data = read_npy(path, what=what)  # no pickle, header against the file's size
    except InputError as exc:  # empty, text, truncated, pickled: say what the file should be
        raise InputError(f"{exc}; {_VALID}") from None
    if data.dtype.kind not in "fiu":  # bool, complex, strings, structured records are not poses
        raise InputError(f"{what}: dtype {data.dtype}, expected float rows of 17 numbers; {_VALID}")
    if data.ndim != 2 or data.shape[1] != 17:
        raise InputError(f"{what}: shape {list(data.shape)}, expected [N, 17] (a 3x5 pose of [rotation | centre "
                         f"| h, w, f] and near, far per image); is it LLFF's poses_bounds.npy? {_VALID}")
    if data.shape[0] != images:
        raise InputError(f"{what}: {data.shape[0]} rows for {images} images in {folder}/ (one row per image, in "
                         f"the order of their sorted names); the file belongs to another capture or images are "
                         f"missing or extra")
    rows = data.astype(np.float64)
    bad = ~np.isfinite(rows)
    if bad.any():
        i, j = (int(k) for k in np.argwhere(bad)[0])
        raise InputError(f"{what}: row {i} column {j} is {float(rows[i, j])} ({int(bad.any(axis=1).sum())} rows hold "
                         f"NaN or infinite values); every pose and bound must be finite")
    hw = rows[:, [4, 9]]
    wrong = (hw < 1) | (hw != np.round(hw)) | (hw > 1 << 20)
    if wrong.any():
        i = int(np.argwhere(wrong.any(axis=1))[0, 0])
        raise InputError(f"{what}: row {i}: height, width {float(rows[i, 4]):g}, {float(rows[i, 9]):g}: expected "
                         f"whole numbers of pixels (columns 4 and 9: the original images' size)")
    if not (rows[:, 14] > 0).all():
        i = int(np.argwhere(rows[:, 14] <= 0)[0, 0])
        raise InputError(f"{what}: row {i}: focal {float(rows[i, 14]):g}: expected a positive focal length in "
                         f"pixels (column 14)")
    if not ((rows[:, 15] > 0) & (rows[:, 15] < rows[:, 16])).all():
        i = int(np.argwhere(~((rows[:, 15] > 0) & (rows[:, 15] < rows[:, 16])))[0, 0])
        raise InputError(f"{what}: row {i}: near, far {float(rows[i, 15]):g}, {float(rows[i, 16]):g}: expected "
                         f"0 < near < far (columns 15 and 16: the view's depth bounds)")
    return rows


def image_files(folder: Path) -> list[str]:
    """The image file names of ``folder``, sorted (LLFF's order)."""
    return sorted(p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())


__all__ = ["POSES_FILE", "IMAGE_SUFFIXES", "camera_from_row", "row_from_camera", "read_poses_bounds", "folders",
           "image_files"]
