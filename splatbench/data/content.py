"""What a file or dataset folder holds, as one hash: the identity of a user's data in a run id.

``content_hash(path) -> str`` ("sha256:<64 hex>") hashes a file's bytes, or for a folder every
regular file under it (relative path, size and bytes, in sorted order), so that the same data
gives the same run id in any clone, at any path, and changed data gives a new one. Left out of a
folder: hidden entries (``.git``, ``.DS_Store``) and ``sfm/`` at its top, where ``splatbench sfm``
writes the model it makes by default, so that making one does not change the data's identity.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

#: Folders at a dataset's top that splatbench writes itself (derived, not the user's data).
DERIVED_DIRS = ("sfm",)
_CHUNK = 1 << 20


def content_hash(path: str | Path) -> str:
    """``"sha256:<hex>"`` of a file's bytes, or of a folder's files (module doc). Remembered
    in this process while no file's size or modification time changes (a grid asks once per run)."""
    root = Path(path).absolute()
    files = [root] if root.is_file() else sorted(
        p for p in root.rglob("*") if p.is_file() and _kept(p.relative_to(root)))
    stamp = (str(root), tuple((str(p), st.st_size, st.st_mtime_ns) for p in files for st in [p.stat()]))
    if stamp not in _SEEN:
        digest = hashlib.sha256()
        for p in files:
            if p != root:
                digest.update(f"{p.relative_to(root).as_posix()}\0{p.stat().st_size}\0".encode())
            _feed(digest, p)
        if len(_SEEN) > 64:
            _SEEN.clear()
        _SEEN[stamp] = "sha256:" + digest.hexdigest()
    return _SEEN[stamp]


_SEEN: dict[tuple, str] = {}


def _kept(rel: Path) -> bool:
    parts = rel.parts
    return not any(part.startswith(".") for part in parts) and not (len(parts) > 1 and parts[0] in DERIVED_DIRS)


def _feed(digest, path: Path) -> None:
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)


__all__ = ["content_hash", "DERIVED_DIRS"]
