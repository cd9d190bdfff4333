"""Bounded reading of files from others: every count or size checked before anything is allocated.

A file someone gives us is data; a count in its header is a claim. These helpers check
each claim against the bytes the file actually holds (and a sane ceiling) so that
reading a hostile file costs at most a small multiple of its size in memory, and a lie
is one `InputError` line naming the file and the field::

    size = file_size(path, "points3D.bin")
    check_count(n, what="points3D.bin: number of points", min_bytes=43, available=size - 8)
    arrays = read_npz(path, what="workload")          # {key: ndarray}, no pickle
    depth = read_npy(path, what="depth map")
    rgb = read_image(path, what="images/r_0.png")     # uint8 pixels, decompression-bomb limit on
    width, height, has_alpha = image_header(path, what="images/r_0.png")  # the header alone

Readers built on these: `splatbench.ply` (PLY headers), `splatbench.data.colmap_bounds`
(COLMAP binary models), `splatbench.workloads` (npz), `splatbench.data.dataset`
(images, depth maps, point clouds). docs/robustness.md lists them and what the
fuzzing campaign ran against them.
"""

from __future__ import annotations

import io
import os
import warnings
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from splatbench.errors import InputError

#: The most elements (vertices, points, cameras, images, array entries) any file may claim.
MAX_COUNT = 2_000_000_000
#: numpy's own ceiling on a .npy header (``max_header_size``), checked here before reading it.
_MAX_NPY_HEADER = 10000
#: Deflate expands at most ~1032:1; an npz member claiming more than this per compressed byte lies.
_DEFLATE_RATIO = 1100


def file_size(path: str | os.PathLike, what: str) -> int:
    """Bytes in ``path``; a one-line `InputError` if it cannot be read."""
    try:
        return os.stat(path).st_size
    except FileNotFoundError:
        raise InputError(f"{what}: no such file {os.fspath(path)!r}") from None
    except OSError as exc:
        raise InputError(f"{what}: cannot read {os.fspath(path)!r} ({exc.strerror or exc})") from None


def check_count(count: int, *, what: str, min_bytes: int, available: int, limit: int = MAX_COUNT) -> int:
    """``count`` if ``0 <= count <= limit`` and ``count`` items of at least ``min_bytes``
    each fit in the ``available`` bytes left in the file; else one `InputError` line."""
    if count < 0 or count > limit:
        raise InputError(f"{what}: {count} is not a plausible count (0..{limit}); the file is damaged or not one")
    if count * min_bytes > available:
        raise InputError(f"{what}: claims {count} entries (at least {count * min_bytes} bytes) but only "
                         f"{max(available, 0)} bytes follow; the file is truncated or damaged")
    return count


def _npy_header(stream, what: str) -> tuple[tuple[int, ...], np.dtype, int]:
    """(shape, dtype, data bytes) of the ``.npy`` header at ``stream``'s position, checked."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(stream)
        if version not in ((1, 0), (2, 0), (3, 0)):
            raise ValueError(f"unsupported .npy version {version}")
        # the header's length, bounded before numpy reads it (numpy reads first, then checks)
        size_field = stream.read(2 if version == (1, 0) else 4)
        length = int.from_bytes(size_field, "little")
        if len(size_field) < (2 if version == (1, 0) else 4) or length > _MAX_NPY_HEADER:
            raise ValueError(f"header length {length} (at most {_MAX_NPY_HEADER})")
        head = io.BytesIO(fmt.magic(*version) + size_field + stream.read(length))
        fmt.read_magic(head)
        read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, _, dtype = read_header(head)
    except Exception as exc:  # noqa: BLE001 - numpy parses the header dict with ast: SyntaxError, TokenError ...
        raise InputError(f"{what}: not a valid .npy array ({type(exc).__name__}: {_short(exc)})") from None
    if dtype.hasobject:
        raise InputError(f"{what}: holds Python objects (dtype {dtype}); only numeric arrays are read (no pickle)")
    count = 1
    for n in shape:
        count *= n
    if count > MAX_COUNT:
        raise InputError(f"{what}: shape {list(shape)} claims {count} elements (at most {MAX_COUNT})")
    return tuple(shape), dtype, count * dtype.itemsize


def read_npy(path: str | os.PathLike, *, what: str) -> np.ndarray:
    """The array in a ``.npy`` file, its header checked against the file's size (`npy_shape`; no pickle)."""
    npy_shape(path, what=what)
    with open(path, "rb") as stream:
        try:
            return np.load(stream, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - a damaged array is data, any failure one line
            raise InputError(f"{what}: cannot read the array ({type(exc).__name__}: {_short(exc)})") from None


def npy_shape(path: str | os.PathLike, *, what: str) -> tuple[tuple[int, ...], np.dtype]:
    """``(shape, dtype)`` of a ``.npy`` file from its header, checked against the file's size
    as `read_npy` checks it; no data is read (a dry run's check)."""
    size = file_size(path, what)
    with open(path, "rb") as stream:
        shape, dtype, nbytes = _npy_header(stream, what)
        if nbytes > size - stream.tell():
            raise InputError(f"{what}: header claims {nbytes} bytes of data, the file holds {size - stream.tell()}; "
                             f"truncated or damaged")
    return shape, dtype


def read_npz(path: str | os.PathLike, *, what: str) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file, by key (``"means"`` for ``means.npy``).

    Each member's header is checked before its data is read: the shape times the item
    size must equal the member's size, and a compressed member may not claim more than
    deflate can produce from its compressed bytes. No pickle (object arrays are refused).
    """
    size = file_size(path, what)
    out: dict[str, np.ndarray] = {}
    try:
        with zipfile.ZipFile(path) as archive:
            infos = archive.infolist()
            check_count(len(infos), what=f"{what}: number of arrays", min_bytes=1, available=size, limit=10_000)
            for info in infos:
                key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
                where = f"{what}: array {key!r}"
                if key in out:
                    raise InputError(f"{where}: stored twice in the archive")
                if info.compress_type == zipfile.ZIP_STORED:
                    bound = info.compress_size
                elif info.compress_type == zipfile.ZIP_DEFLATED:
                    bound = info.compress_size * _DEFLATE_RATIO + 1024
                else:
                    raise InputError(f"{where}: unsupported compression {info.compress_type}")
                if info.file_size > bound or info.compress_size > size:
                    raise InputError(f"{where}: claims {info.file_size} bytes from {info.compress_size} stored; "
                                     f"damaged or a zip bomb")
                with archive.open(info) as member:
                    _, _, nbytes = _npy_header(member, where)
                    if nbytes != info.file_size - member.tell():
                        raise InputError(f"{where}: header claims {nbytes} bytes of data, the member holds "
                                         f"{info.file_size - member.tell()}; truncated or damaged")
                out[key] = np.load(io.BytesIO(archive.read(info)), allow_pickle=False)  # at most file_size bytes
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"{what}: no such file {os.fspath(path)!r}") from None
    except Exception as exc:  # noqa: BLE001 - zipfile, zlib, struct and numpy faults all mean a damaged archive
        raise InputError(f"{what}: not a readable npz ({type(exc).__name__}: {_short(exc)})") from None
    return out


def read_image(path: str | os.PathLike, *, what: str, mode: str | None = None) -> np.ndarray:
    """The pixels of an image file as a uint8 array (``mode``: ``"RGB"``, ``"RGBA"``, or
    None: as stored), refused in one line if its header claims more than Pillow's
    ``Image.MAX_IMAGE_PIXELS`` (about 89 million; a decompression bomb: refused at the limit,
    not only at twice it, where Pillow itself stops) or it cannot be decoded."""
    arr, _ = read_image_with_alpha(path, what=what, mode=mode)
    return arr


def read_image_with_alpha(path: str | os.PathLike, *, what: str, mode: str | None = None
                          ) -> tuple[np.ndarray, bool]:
    """`read_image`, and whether the stored image has an alpha channel (``mode=None``
    then decodes RGBA for images with alpha, RGB otherwise)."""
    def decode(im) -> tuple[np.ndarray, bool]:
        has_alpha = _has_alpha(im)
        return np.asarray(im.convert(mode or ("RGBA" if has_alpha else "RGB"))), has_alpha

    # from memory: BytesIO.read(n) returns what is there, where a file's read(n) first
    # allocates n bytes (Pillow reads a PNG's trailing IDAT by its stated length, up to 2 GiB)
    return _with_image(path, what, decode, in_memory=True)


def image_header(path: str | os.PathLike, *, what: str) -> tuple[int, int, bool]:
    """``(width, height, has alpha)`` of an image file from its header alone (no pixel is
    decoded), refused in one line as `read_image_with_alpha` refuses it (a decompression
    bomb, a file Pillow cannot identify): what a dry run checks (`splatbench.data.check_dataset`)."""
    return _with_image(path, what, lambda im: (int(im.width), int(im.height), _has_alpha(im)), in_memory=False)


def _has_alpha(im) -> bool:
    return im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info)


def _with_image(path: str | os.PathLike, what: str, use, *, in_memory: bool):
    """``use(image)`` of the Pillow image opened from ``path`` (its bytes read into memory
    first when ``in_memory``), every failure one `InputError` line naming ``what``."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)  # refuse at the limit, not 2x
            with Image.open(io.BytesIO(Path(path).read_bytes()) if in_memory else Path(path)) as im:
                return use(im)
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"{what}: no such image {os.fspath(path)!r}") from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as exc:
        raise InputError(f"{what}: refused as a decompression bomb ({_short(exc)})") from None
    except Exception as exc:  # noqa: BLE001 - Pillow's decoders raise OSError, ValueError, SyntaxError, struct.error ...
        if isinstance(exc, Image.UnidentifiedImageError):  # its message names the in-memory buffer, not the file
            raise InputError(f"{what}: not an image Pillow can decode (empty, damaged, or not a PNG/JPEG/...): "
                             f"replace it with the image file") from None
        raise InputError(f"{what}: cannot read the image ({type(exc).__name__}: {_short(exc)}); replace it with an "
                         f"intact copy") from None


def _short(exc: BaseException) -> str:
    return (" ".join(str(exc).split()) or type(exc).__name__)[:200]


__all__ = ["MAX_COUNT", "file_size", "check_count",
           "read_npy", "npy_shape", "read_npz", "read_image", "read_image_with_alpha", "image_header"]
