"""Every count in a COLMAP binary model checked against the file before pycolmap reads it.

pycolmap reserves memory for the counts a ``.bin`` file states (cameras, images, 2-D
points per image, points, track lengths, rigs, sensors, frames) before reading them: a
``cameras.bin`` of a few bytes claiming 10^11 cameras would ask for terabytes.
`check_colmap_binary` walks each file's records (the layouts of COLMAP's
``colmap/scene/reconstruction_io_binary.cc``, as pycolmap 4 writes them) and refuses, in
one `InputError` line naming the file and the field, any count whose records cannot fit
in the bytes left, a camera model id COLMAP does not define, or an image name that is
not UTF-8. It allocates nothing beyond the file's bytes. Text models (``.txt``) state no
counts that are allocated ahead; `check_colmap_text` checks they are UTF-8.
"""

from __future__ import annotations

import struct
from pathlib import Path

from splatbench.errors import InputError
from splatbench.safeio import check_count, file_size

#: COLMAP's camera model ids and their parameter counts (``colmap/sensor/models.h``;
#: tests/test_robustness.py checks this table against pycolmap's).
CAMERA_MODEL_PARAMS = {0: 3, 1: 4, 2: 4, 3: 5, 4: 8, 5: 8, 6: 12, 7: 5, 8: 4, 9: 5, 10: 12, 11: 16, 12: 4,
                       13: 5, 14: 3, 15: 4, 16: 6, 17: 2}


class _Cursor:
    """Reads little-endian fields from a file's bytes; a short read is a one-line error."""

    def __init__(self, data: bytes, what: str) -> None:
        self.data, self.pos, self.what = data, 0, what

    @property
    def left(self) -> int:
        return len(self.data) - self.pos

    def read(self, fmt: str, field: str) -> tuple:
        size = struct.calcsize("<" + fmt)
        if size > self.left:
            raise InputError(f"{self.what}: {field}: the file ends early (truncated or damaged)")
        values = struct.unpack_from("<" + fmt, self.data, self.pos)
        self.pos += size
        return values

    def skip(self, nbytes: int, field: str) -> None:
        if nbytes > self.left:
            raise InputError(f"{self.what}: {field}: the file ends early (truncated or damaged)")
        self.pos += nbytes

    def count(self, fmt: str, field: str, min_bytes: int) -> int:
        (n,) = self.read(fmt, field)
        return check_count(n, what=f"{self.what}: {field}", min_bytes=min_bytes, available=self.left)

    def name(self, field: str) -> None:
        end = self.data.find(b"\0", self.pos)
        if end < 0:
            raise InputError(f"{self.what}: {field}: no terminating NUL (truncated or damaged)")
        try:
            self.data[self.pos:end].decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(f"{self.what}: {field}: {self.data[self.pos:end]!r:.80} is not UTF-8 text") from None
        self.pos = end + 1


def _cameras(c: _Cursor) -> None:
    n = c.count("Q", "number of cameras", min_bytes=24 + 8 * min(CAMERA_MODEL_PARAMS.values()))
    for i in range(n):
        _, model = c.read("iiQQ", f"camera {i}")[:2]
        if model not in CAMERA_MODEL_PARAMS:
            raise InputError(f"{c.what}: camera {i}: model id {model} is not a COLMAP camera model")
        c.skip(8 * CAMERA_MODEL_PARAMS[model], f"camera {i} params")


def _images(c: _Cursor) -> None:
    n = c.count("Q", "number of images", min_bytes=4 + 56 + 4 + 1 + 8)
    for i in range(n):
        c.skip(4 + 56 + 4, f"image {i}")
        c.name(f"image {i} name")
        k = c.count("Q", f"image {i} number of 2-D points", min_bytes=24)
        c.skip(24 * k, f"image {i} 2-D points")


def _points(c: _Cursor) -> None:
    n = c.count("Q", "number of points", min_bytes=8 + 24 + 3 + 8 + 8)
    for i in range(n):
        c.skip(8 + 24 + 3 + 8, f"point {i}")
        k = c.count("Q", f"point {i} track length", min_bytes=8)
        c.skip(8 * k, f"point {i} track")


def _rigs(c: _Cursor) -> None:
    n = c.count("Q", "number of rigs", min_bytes=8)
    for i in range(n):
        _, sensors = c.read("II", f"rig {i}")
        check_count(sensors, what=f"{c.what}: rig {i} number of sensors", min_bytes=8, available=c.left)
        if sensors:
            c.skip(8, f"rig {i} reference sensor")
        for s in range(max(sensors - 1, 0)):
            (_, _, has_pose) = c.read("iIB", f"rig {i} sensor {s}")
            if has_pose:
                c.skip(56, f"rig {i} sensor {s} pose")


def _frames(c: _Cursor) -> None:
    n = c.count("Q", "number of frames", min_bytes=4 + 4 + 56 + 4)
    for i in range(n):
        c.skip(4 + 4 + 56, f"frame {i}")
        k = c.count("I", f"frame {i} number of data ids", min_bytes=16)
        c.skip(16 * k, f"frame {i} data ids")


_WALKERS = {"cameras": _cameras, "images": _images, "points3D": _points, "rigs": _rigs, "frames": _frames}


def check_colmap_text(sparse: str | Path) -> None:
    """The ``.txt`` files of the model folder ``sparse`` must be UTF-8 text (pycolmap
    hands image names to Python as UTF-8); one `InputError` line naming the file and
    the byte otherwise."""
    for part in _WALKERS:
        path = Path(sparse) / f"{part}.txt"
        if path.is_file():
            try:
                path.read_bytes().decode("utf-8")
            except UnicodeDecodeError as exc:
                raise InputError(f"{path}: not UTF-8 text (byte {exc.start}); the file is damaged") from None


def check_colmap_binary(sparse: str | Path, label: str | None = None) -> None:
    """Walk ``cameras.bin``, ``images.bin``, ``points3D.bin`` (and ``rigs.bin``,
    ``frames.bin`` when present) of the model folder ``sparse``; one `InputError` line,
    naming the file (as ``label``/NAME, default the folder) and the field, for any count
    the file cannot hold or an unknown camera model."""
    sparse = Path(sparse)
    for part, walk in _WALKERS.items():
        path = sparse / f"{part}.bin"
        if not path.is_file():
            continue
        what = f"{label or sparse}/{part}.bin"
        file_size(path, what)  # readable
        walk(_Cursor(path.read_bytes(), what))


__all__ = ["check_colmap_binary", "check_colmap_text", "CAMERA_MODEL_PARAMS"]
