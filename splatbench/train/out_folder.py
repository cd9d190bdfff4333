"""`claim_out`: the `splatbench train` output folder, never silently shared by two runs.

    claim_out("runs/d64", resume=None, force=False)   # InputError if runs/d64 holds a run
    claim_out("runs/d64", resume=None, force=True)    # clears that run's files first

A folder *holds a run* when it has one of the files `splatbench.train.train` writes
there: ``result.json``, ``point_cloud.ply`` or ``checkpoints/``. Training into it would
replace the PLY, result.json and config.toml, leave the old run's ``point_cloud.png``
(written by ``splatbench render``) beside the new model, and mix two runs' checkpoints
(an existing ``iteration_<step>.ply`` is even kept as the new run's checkpoint). So the
CLI refuses unless the run is a ``--resume`` of one of the folder's own checkpoints, or
``--force`` is given: then only the files the trainer (and ``render`` of its PLY) write
are removed -- `RUN_FILES` and the checkpoint files in ``checkpoints/`` -- never anything
else. The Python API (`train`) does not call this: the experiment runner and the tests
rerun into their own work folders on purpose.
"""

from __future__ import annotations

import re
from pathlib import Path

from splatbench.errors import InputError

#: A run's files at the top of its folder (point_cloud.png: `splatbench render` of its PLY).
RUN_FILES = ("result.json", "config.toml", "point_cloud.ply", "point_cloud.png")
#: The checkpoints folder and the files the trainer writes in it (`checkpoint_path`, `.pt` beside
#: it, and the temporary a killed write leaves: `fsutil.atomic_write`'s
#: ``.iteration_<step>.<ply|pt>.<pid>.<hex>.tmp``, or an older version's ``.tmp-*.pt``).
CHECKPOINTS = "checkpoints"
_CHECKPOINT_FILE = re.compile(r"(iteration_\d+\.(ply|pt)|\.iteration_\d+\.(ply|pt)\.\d+\.[0-9a-f]+\.tmp|\.tmp-.*\.pt)")


def run_markers(out: str | Path) -> list[str]:
    """The names in ``out`` that show it holds a run (empty: it holds none)."""
    out = Path(out)
    return [name for name in ("result.json", "point_cloud.ply") if (out / name).is_file()] + \
        ([f"{CHECKPOINTS}/"] if (out / CHECKPOINTS).is_dir() else [])


def claim_out(out: str | Path, *, resume: str | Path | None = None, force: bool = False) -> list[Path]:
    """Check that ``out`` may receive a new training run; with ``force``, clear an earlier
    run's files from it first. Returns the paths removed. A ``resume`` from a checkpoint in
    ``out/checkpoints`` continues that run and is always allowed (nothing is removed).

    Raises `InputError` (one line: the folder, what it holds, the fix) when ``out`` holds a
    run and neither applies."""
    out = Path(out)
    if resume is not None and _inside(Path(resume), out / CHECKPOINTS):
        return []
    markers = run_markers(out)
    if not markers:
        return []
    if not force:
        hint = (f"pass --resume {out / CHECKPOINTS}/iteration_<step>.pt to continue it, "
                if "result.json" not in markers else "")
        raise InputError(f"{out}: already holds a training run ({', '.join(markers)}); {hint}pass --force to "
                         f"replace it (removes that run's files), or choose another --out")
    removed = [out / name for name in RUN_FILES if (out / name).is_file()]
    checkpoints = out / CHECKPOINTS
    if checkpoints.is_dir():
        removed += [p for p in sorted(checkpoints.iterdir()) if p.is_file() and _CHECKPOINT_FILE.fullmatch(p.name)]
    for path in removed:
        path.unlink()
    if checkpoints.is_dir() and not any(checkpoints.iterdir()):
        checkpoints.rmdir()
    return removed


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
    except (ValueError, OSError):
        return False
    return True


__all__ = ["claim_out", "run_markers", "RUN_FILES", "CHECKPOINTS"]
