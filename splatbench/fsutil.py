"""Filesystem helpers: put finished folders in place atomically."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path


def replace_dir(tmp: Path, out: Path, *, accept_existing: Callable[[Path], bool] = lambda path: False) -> None:
    """Rename the finished folder ``tmp`` to ``out``, replacing an older ``out``.

    The older folder is moved aside first and deleted only once the new one is in
    place. If the rename fails, a folder that another process put at ``out``
    meanwhile is kept when ``accept_existing(out)`` says it is equivalent; otherwise
    the older folder is restored and the error re-raised, so no result is lost.
    """
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
