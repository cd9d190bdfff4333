"""3DGS ``.ply`` files in graphdeco-inria's layout, read and written with plyfile.

One ``vertex`` element with one float32 property per value, binary little endian --
always graphdeco's 62 properties of SH degree 3 (``GaussianModel.construct_list_of_attributes``
with ``max_sh_degree = 3``, the default of its ``--sh_degree``), so graphdeco's
``load_ply`` and common viewers open every file::

    x y z  nx ny nz  f_dc_0 f_dc_1 f_dc_2  f_rest_0 .. f_rest_44
    opacity  scale_0 scale_1 scale_2  rot_0 rot_1 rot_2 rot_3

``f_dc_c`` is ``sh[:, 0, c]``; ``f_rest`` is *channel-major* over graphdeco's 15 rest
coefficients: ``f_rest_{15·c + k-1}`` holds ``sh[:, k, c]`` for k in 1..15. A model of a
lower degree writes zeros in the bands above it and records its degree in a header
comment (``comment splatbench sh_degree D``); reading such a file gives back degree D
(the zeros dropped), so the round trip is bit-exact. ``opacity`` is the logit,
``scale_i`` the log scale, ``rot_*`` the quaternion (w, x, y, z). Normals are written
as zeros and ignored on reading. Files from other writers with fewer ``f_rest_*``
(``3·((D+1)² − 1)``, channel-major over their own ``(D+1)² − 1``) are read too; without
the comment the degree is the one the ``f_rest_*`` count gives.

Two more optional header comments say how the model should be viewed (`ViewHints`):
``comment splatbench up X Y Z`` (the world's up direction, e.g. ``0 1 0`` for the y-up
Mitsuba scenes) and ``comment splatbench background R G B`` (the RGB in [0, 1] it was
trained on). `splatbench train` writes them when it knows them; ``splatbench render``
uses them. Other readers (graphdeco's ``load_ply``, viewers) skip comments.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from splatbench.guards import SH_BASES_OF_DEGREE
from splatbench.errors import InputError
from splatbench.fsutil import atomic_write
from splatbench.safeio import check_count

_BASE_HEAD = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
_BASE_TAIL = ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
_F_REST = re.compile(r"^f_rest_(\d+)$")


#: The SH degree every written file has the properties of (graphdeco's default).
WRITE_DEGREE = 3
#: Header comment prefix recording the degree of the model a file holds.
_DEGREE_COMMENT = "splatbench sh_degree "
#: Header comment prefixes of the `ViewHints` fields.
_UP_COMMENT = "splatbench up "
_BACKGROUND_COMMENT = "splatbench background "


def property_names(sh_degree: int = WRITE_DEGREE) -> list[str]:
    """The vertex property names, in file order, for SH degree 0..3 (`write_ply` uses 3: 62 names)."""
    n_rest = 3 * (SH_BASES_OF_DEGREE[sh_degree] - 1)
    return _BASE_HEAD + [f"f_rest_{i}" for i in range(n_rest)] + _BASE_TAIL


class PlyArrays(NamedTuple):
    """The five raw parameter groups a 3DGS ``.ply`` holds (float32), in `Gaussians`' order.

    means [N, 3], log_scales [N, 3], quats [N, 4] (w, x, y, z), opacity_logits [N],
    sh [N, K, 3]. `splatbench.Gaussians.from_ply` checks them and builds the Gaussians
    (this module does not import `splatbench.gaussians`, which imports it).
    """

    means: np.ndarray
    log_scales: np.ndarray
    quats: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray


@dataclass(frozen=True)
class ViewHints:
    """How a model wants to be viewed, recorded in its header; None: not recorded.

    ``up`` [3]: the world's up direction (a unit vector). ``background`` [3]: RGB in [0, 1]
    behind the splats during training.
    """

    up: tuple[float, float, float] | None = None
    background: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.up is not None:
            object.__setattr__(self, "up", _unit_vector("up", self.up))
        if self.background is not None:
            object.__setattr__(self, "background", _rgb01("background", self.background))

    def comments(self) -> list[str]:
        """The header comment lines (without ``comment ``) that record the set fields."""
        lines = []
        for prefix, value in ((_UP_COMMENT, self.up), (_BACKGROUND_COMMENT, self.background)):
            if value is not None:
                lines.append(prefix + " ".join(repr(float(v)) for v in value))  # repr: exact round trip
        return lines


def _three_floats(field: str, value) -> tuple[float, float, float]:
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise InputError(f"{field}: expected 3 numbers, got {value!r}") from None
    if len(v) != 3 or not all(np.isfinite(v)):
        raise InputError(f"{field}: expected 3 finite numbers, got {list(value)!r}")
    return v  # type: ignore[return-value]


def _unit_vector(field: str, value) -> tuple[float, float, float]:
    v = np.asarray(_three_floats(field, value))
    norm = float(np.linalg.norm(v))
    if not norm > 0:
        raise InputError(f"{field}: expected a non-zero direction, got {v.tolist()}")
    return tuple(float(x) for x in v / norm)  # type: ignore[return-value]


def _rgb01(field: str, value) -> tuple[float, float, float]:
    v = _three_floats(field, value)
    if not all(0 <= c <= 1 for c in v):
        raise InputError(f"{field}: expected 3 values in [0, 1], got {list(v)}")
    return v


def to_vertex_array(gaussians: PlyArrays) -> np.ndarray:
    """The structured vertex array [N] (62 float32 fields) that `write_ply` stores; SH bands
    above the model's degree are zero. ``gaussians``: `PlyArrays` or a `Gaussians`."""
    names = property_names(WRITE_DEGREE)
    n, k, _ = gaussians.sh.shape
    k_full = SH_BASES_OF_DEGREE[WRITE_DEGREE]
    sh = np.zeros((n, k_full, 3), dtype=np.float32)
    sh[:, :k] = gaussians.sh
    columns = np.empty((n, len(names)), dtype=np.float32)
    columns[:, 0:3] = gaussians.means
    columns[:, 3:6] = 0.0
    columns[:, 6:9] = sh[:, 0, :]
    rest = 9 + 3 * (k_full - 1)
    # channel-major: column 15·c + (k-1) holds sh[:, k, c]
    columns[:, 9:rest] = np.transpose(sh[:, 1:, :], (0, 2, 1)).reshape(n, 3 * (k_full - 1))  # n may be 0
    columns[:, rest] = gaussians.opacity_logits
    columns[:, rest + 1:rest + 4] = gaussians.log_scales
    columns[:, rest + 4:rest + 8] = gaussians.quats
    vertex = np.empty(n, dtype=[(name, "<f4") for name in names])
    for i, name in enumerate(names):
        vertex[name] = columns[:, i]
    return vertex


def write_ply(gaussians: PlyArrays, path: str | os.PathLike, hints: ViewHints | None = None) -> None:
    """Write ``gaussians`` (`PlyArrays` or a `Gaussians`) to ``path`` atomically
    (`splatbench.fsutil.atomic_write`); the header records its SH degree and ``hints`` (`ViewHints`)."""
    from plyfile import PlyData, PlyElement

    element = PlyElement.describe(to_vertex_array(gaussians), "vertex")
    comments = [f"{_DEGREE_COMMENT}{SH_BASES_OF_DEGREE.index(gaussians.sh.shape[1])}",
                *(hints.comments() if hints is not None else [])]

    def write(temp) -> None:
        with open(temp, "wb") as stream:
            PlyData([element], text=False, byte_order="<", comments=comments).write(stream)

    atomic_write(path, write)


def read_ply_data(path: str | os.PathLike, name: str | None = None):
    """The ``plyfile.PlyData`` of a PLY file (any elements), its header's element counts
    checked against the file's size before any data is read (`check_ply_counts`); a
    malformed file is one `InputError` line naming it (``name``, default the path)."""
    from plyfile import PlyData, PlyElementParseError, PlyParseError

    path = os.fspath(path)
    name = name or path
    try:
        with open(path, "rb") as stream:
            header = PlyData._parse_header(stream)  # the header only: counts and property types
            check_ply_counts(header, available=os.fstat(stream.fileno()).st_size - stream.tell(), name=name)
            stream.seek(0)
            return PlyData.read(stream, mmap="c")  # copy-on-write map: the columns are copied below
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"{name}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{name}: is a directory, not a PLY file") from None
    except PlyElementParseError as exc:
        raise InputError(f"{name}: truncated or corrupt data ({_one_line(exc)})") from None
    except PlyParseError as exc:
        raise InputError(f"{name}: not a valid PLY file ({_one_line(exc)})") from None
    except Exception as exc:  # noqa: BLE001 - plyfile and numpy faults on a damaged file: ValueError, EOFError ...
        raise InputError(f"{name}: not a valid PLY file ({type(exc).__name__}: {_one_line(exc)})") from None


def check_ply_counts(header, *, available: int, name: str) -> None:
    """Each element's count in a parsed PLY ``header`` (``plyfile.PlyData`` without data)
    must fit in the ``available`` bytes after it: a binary row takes at least the sizes of
    its scalars and list lengths, an ASCII row two characters (a digit and a separator)
    per property. One `InputError` line otherwise, before anything is allocated."""
    from plyfile import PlyListProperty

    need = 0
    for element in header.elements:
        if header.text:
            row = 2 * len(element.properties)
        else:
            row = sum(np.dtype(p.len_dtype if isinstance(p, PlyListProperty) else p.val_dtype).itemsize
                      for p in element.properties)
        slack = 1 if header.text else 0  # the last ASCII row may end without its newline
        check_count(element.count, what=f"{name}: element {element.name!r} count", min_bytes=max(row, 1),
                    available=available - need + slack)
        need += element.count * row


def read_ply(path: str | os.PathLike) -> PlyArrays:
    """The arrays of a graphdeco-inria 3DGS ``.ply``; one-line `InputError` naming the file if
    malformed. `splatbench.Gaussians.from_ply` is the public entry point (it checks the values)."""
    path = os.fspath(path)
    name = path
    ply = read_ply_data(path)

    elements = [e.name for e in ply.elements]
    if "vertex" not in elements:
        raise InputError(f"{name}: missing element 'vertex' (found {elements})")
    vertex = ply["vertex"]
    data = vertex.data
    fields = list(data.dtype.names or ())

    rest_ids = sorted(int(m.group(1)) for f in fields if (m := _F_REST.match(f)))
    n_rest = (max(rest_ids) + 1) if rest_ids else 0
    valid = [3 * (k - 1) for k in SH_BASES_OF_DEGREE]
    if n_rest not in valid:
        if n_rest > valid[-1]:
            raise InputError(f"{name}: {n_rest} f_rest_* properties; expected one of {valid} (SH degree 0..3)")
        n_rest = min(v for v in valid if v > n_rest)  # the nearest complete degree: report what is missing
    k = n_rest // 3 + 1
    wanted = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(n_rest)] + _BASE_TAIL
    missing = [f for f in wanted if f not in fields]
    if missing:
        raise InputError(f"{name}: missing vertex properties {missing}")
    for f in wanted:
        kind = data.dtype[f].kind
        if kind not in "fiu" or data.dtype[f].subdtype is not None:
            raise InputError(f"{name}: vertex property {f!r} has type {data.dtype[f]}, expected float32")

    def cols(names: list[str]) -> np.ndarray:
        return np.stack([np.asarray(data[f], dtype=np.float32) for f in names], axis=-1)

    n = len(data)
    sh = np.empty((n, k, 3), dtype=np.float32)
    sh[:, 0, :] = cols(["f_dc_0", "f_dc_1", "f_dc_2"])
    if k > 1:
        rest = cols([f"f_rest_{i}" for i in range(n_rest)]).reshape(n, 3, k - 1)
        sh[:, 1:, :] = np.transpose(rest, (0, 2, 1))
    degree = _recorded_degree(ply.comments)
    k_recorded = SH_BASES_OF_DEGREE[degree] if degree is not None else k
    if k_recorded < k and not (sh[:, k_recorded:] != 0).any():  # != 0: a NaN counts, without a warning
        sh = np.ascontiguousarray(sh[:, :k_recorded])  # the written model's degree; the rest is padding
    return PlyArrays(
        means=cols(["x", "y", "z"]),
        log_scales=cols(["scale_0", "scale_1", "scale_2"]),
        quats=cols(["rot_0", "rot_1", "rot_2", "rot_3"]),
        opacity_logits=np.asarray(data["opacity"], dtype=np.float32),
        sh=sh,
    )


def read_view_hints(path: str | os.PathLike) -> ViewHints:
    """The `ViewHints` a PLY's header comments record (fields absent: None); reads the
    header only. A malformed hint is one `InputError` line naming the file and the comment."""
    path = os.fspath(path)
    comments = []
    try:
        with open(path, "rb") as stream:
            for _ in range(100_000):  # a header is a few hundred lines; stop on a file that is not one
                line = stream.readline()
                if not line or line.strip() == b"end_header":
                    break
                if line.startswith(b"comment "):
                    comments.append(line[len(b"comment "):].decode("ascii", "replace").strip())
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    found: dict[str, tuple[float, float, float]] = {}
    for line in comments:
        for field, prefix in (("up", _UP_COMMENT), ("background", _BACKGROUND_COMMENT)):
            if line.startswith(prefix):
                try:
                    found[field] = getattr(ViewHints(**{field: line[len(prefix):].split()}), field)
                except InputError as exc:
                    raise InputError(f"{path}: header comment {line!r}: {exc}") from None
    return ViewHints(**found)


def _recorded_degree(comments: list[str]) -> int | None:
    """The degree a ``comment splatbench sh_degree D`` header line records, if any."""
    for line in comments:
        if line.startswith(_DEGREE_COMMENT) and line[len(_DEGREE_COMMENT):].strip() in ("0", "1", "2", "3"):
            return int(line[len(_DEGREE_COMMENT):])
    return None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__
