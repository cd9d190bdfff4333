"""Filesystem helpers: put finished files and folders in place atomically, with the
permissions an ordinary ``open`` / ``mkdir`` would have given them.

`atomic_write` writes one file through a fsync'd temporary ``.<name>.<pid>.<random>.tmp``
beside it, created by an ordinary ``open``: the primitive under `splatbench.report_files`
(the writer of every result, report, figure, cache and checkpoint) and under the model
files below it (PLYs, PNG images, workloads).
`tempfile.mkdtemp` creates 0700 folders whatever the umask; renamed into place as they
are, a result would be unreadable to the rest of a group, so `replace_dir` first gives
the temporary folder its umask mode (0755 under umask 022).

Folders derived from content (rendered datasets, SfM models, undistorted images, teacher
scenes, regression snapshots) are built the same way everywhere::

    if manifest_hash(out) != digest:                       # not there yet, or stale
        with building_dir(out, accept_existing=lambda p: manifest_hash(p) == digest) as tmp:
            ...                                            # fill tmp (a new sibling of out)
            write_manifest(tmp, {"hash": digest, ...})     # last: what makes it a finished folder

`building_dir` renames the finished temporary folder onto ``out`` (`replace_dir`) and
removes it whatever happens; `read_manifest` reads a folder's ``manifest.json`` back.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from splatbench.errors import InputError


def current_umask() -> int:
    """The process's umask, read without changing it (Linux: /proc/self/status)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)  # elsewhere: set and restore (not thread-safe, hence the fallback only)
    os.umask(mask)
    return mask


def umask_mode(path: str | os.PathLike) -> None:
    """Give ``path`` the mode a new file (0666) or folder (0777) gets under the umask."""
    base = 0o777 if os.path.isdir(path) else 0o666
    os.chmod(path, base & ~current_umask())


def replace_dir(tmp: Path, out: Path, *, accept_existing: Callable[[Path], bool] = lambda path: False) -> None:
    """Rename the finished folder ``tmp`` to ``out``, replacing an older ``out``.

    The older folder is moved aside first and deleted only once the new one is in
    place. If the rename fails, a folder that another process put at ``out``
    meanwhile is kept when ``accept_existing(out)`` says it is equivalent; otherwise
    the older folder is restored and the error re-raised, so no result is lost.
    """
    umask_mode(tmp)
    trash = None
    if out.exists():
        trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
        os.replace(out, trash / out.name)
    try:
        os.rename(tmp, out)
    except OSError:
        if not (out.exists() and accept_existing(out)):
            if trash is not None and not out.exists():
                os.replace(trash / out.name, out)  # put the older folder back
            raise
    finally:
        if trash is not None:
            shutil.rmtree(trash, ignore_errors=True)


@contextmanager
def building_dir(out: Path, *, accept_existing: Callable[[Path], bool] = lambda path: False) -> Iterator[Path]:
    """A new, empty temporary folder ``.<out name>.tmp-XXXX`` beside ``out`` to build ``out`` in.

    When the ``with`` block ends normally, the temporary folder replaces ``out``
    (`replace_dir`: an older ``out`` is moved aside and deleted once the new one is in
    place; one that another process finished meanwhile is kept when
    ``accept_existing(out)``). On an exception or an interrupt ``out`` is left as it
    was. The temporary folder is removed in every case.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        yield tmp
        replace_dir(tmp, out, accept_existing=accept_existing)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


#: The file that makes a folder built by content a finished one: its content hash
#: (``hash``) and what it holds; written last (`write_manifest`).
MANIFEST = "manifest.json"

_NUMBER_LIST = re.compile(r"\[\s*([-+0-9.eE]+(?:,\s*[-+0-9.eE]+)*)\s*\]")


def json_text(data: Any) -> str:
    """``data`` as JSON indented by one space, lists of numbers (matrix rows, resolutions)
    kept on one line, with a final newline."""
    text = json.dumps(data, indent=1)
    return _NUMBER_LIST.sub(lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text) + "\n"


def write_manifest(folder: str | os.PathLike, manifest: dict[str, Any]) -> None:
    """Write ``manifest`` (a JSON object) as ``folder/manifest.json`` (`json_text`)."""
    (Path(folder) / MANIFEST).write_text(json_text(manifest), encoding="utf-8")


def read_manifest(folder: str | os.PathLike) -> dict[str, Any] | None:
    """The folder's ``manifest.json`` as a dict, or None when there is none (or it is
    unreadable, or not a JSON object)."""
    try:
        data = json.loads((Path(folder) / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def manifest_hash(folder: str | os.PathLike) -> str | None:
    """The content hash (``hash``) the folder's manifest records; None without one."""
    digest = (read_manifest(folder) or {}).get("hash")
    return digest if isinstance(digest, str) else None


def atomic_write(path: str | Path, write) -> Path:
    """Call ``write(temp_path)``, fsync the temporary file, rename it onto ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = path.parent / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    try:
        write(temp)
        fd = os.open(temp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(temp, path)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)
    return path


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def read_text(path: str | os.PathLike, what: str) -> str:
    """The UTF-8 text of ``path``; a one-line `InputError` starting ``what:`` when it
    cannot be read or is not UTF-8."""
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{what}: cannot read {str(p)!r} ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{what}: {str(p)!r} is not UTF-8 text (byte {exc.start}); save it as UTF-8") from None


#: Environment variable naming the root of splatbench's caches (undistorted images, SfM
#: models, oracle renders); default ``~/.cache/splatbench``.
CACHE_ENV = "SPLATBENCH_CACHE"


def cache_root() -> Path:
    """``$SPLATBENCH_CACHE``, else ``~/.cache/splatbench``: where derived data is cached by content."""
    return Path(os.environ.get(CACHE_ENV) or Path.home() / ".cache" / "splatbench")
