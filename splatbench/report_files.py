"""How results, reports and caches land on disk: the one file writer of every part at the
measurement level and above (the verification applications, the benchmarks, training's
configs, results and checkpoints, the experiment store and its caches, the experiment
reports and every figure); and the one writer of a Markdown table (`markdown_table`),
which every report's tables go through.

Every file is written whole or not at all (`splatbench.fsutil.atomic_write`, the primitive
underneath: a temporary beside it, fsync'd, renamed into place with the umask's mode), so a
run stopped half-way never leaves a truncated table, a half PNG or a cut checkpoint beside
older files. Below this level, the model files (`ply`, `images`, `workloads`) call
`atomic_write` themselves; files inside a folder built by `fsutil.building_dir` are written
plainly, since that folder lands whole.

    write_text(path, text) -> Path             UTF-8 text (markdown)
    write_json(path, data, indent=1) -> Path   JSON and a final newline
    write_parquet(path, frame) -> Path         a pandas DataFrame, without its index
    write_csv(path, columns, rows) -> Path     a header line, then one line per mapping in ``rows`` (LF endings)
    write_binary(path, dump) -> Path           what ``dump(stream)`` writes to a binary stream (np.save, torch.save)
    save_figure(fig, path, **kw) -> Path       a matplotlib figure (PNG at 110 dpi, nothing clipped), closed
    run_header(command, seconds, machine)      where and how a run was made: {"command", "seconds",
                                               "written", "machine"} (machine: `MachineInfo`, load included)
    markdown_table(header, rows, align=None)   the one writer of a Markdown table (every report's tables)
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, BinaryIO

from splatbench.fsutil import atomic_write
from splatbench.metrics.machine import MachineInfo


def write_text(path: str | Path, text: str) -> Path:
    """``text`` into ``path`` (UTF-8), atomically; returns the path."""
    return atomic_write(path, lambda temp: temp.write_text(text, encoding="utf-8"))


def write_json(path: str | Path, data: Any, *, indent: int = 1) -> Path:
    """``data`` as JSON (``indent``, then a newline) into ``path``, atomically; values JSON has
    no type for (paths, numpy scalars) are written as their ``str``."""
    return write_text(path, json.dumps(data, indent=indent, default=str) + "\n")


def write_parquet(path: str | Path, frame) -> Path:
    """The pandas DataFrame ``frame`` (without its index) into ``path``, atomically."""
    return atomic_write(path, lambda temp: frame.to_parquet(temp, index=False))


def write_csv(path: str | Path, columns: Sequence[str], rows: Iterable[Mapping[str, Any]]) -> Path:
    """A CSV file: the header ``columns``, then one line per mapping in ``rows`` (its keys are
    ``columns``), atomically."""
    def write(temp: Path) -> None:
        with open(temp, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(columns), lineterminator="\n")
            writer.writeheader()
            writer.writerows(rows)

    return atomic_write(path, write)


def write_binary(path: str | Path, dump: Callable[[BinaryIO], object]) -> Path:
    """What ``dump(stream)`` writes to the binary ``stream`` (``np.save``, ``torch.save``: a
    stream, so neither appends a suffix to the temporary's name) into ``path``, atomically."""
    def write(temp: Path) -> None:
        with open(temp, "wb") as stream:
            dump(stream)

    return atomic_write(path, write)


def save_figure(fig, path: str | Path, *, dpi: int = 110) -> Path:
    """Save the matplotlib figure ``fig`` to ``path`` (format from its suffix), atomically, with
    a tight bounding box (titles and labels never clipped), then close it."""
    import matplotlib.pyplot as plt  # only where a figure exists, so matplotlib is loaded already

    path = Path(path)
    try:
        return atomic_write(path, lambda temp: fig.savefig(temp, format=path.suffix.lstrip(".") or "png", dpi=dpi,
                                                           bbox_inches="tight", pad_inches=0.1))
    finally:
        plt.close(fig)


def run_header(command: str, seconds: float, machine: MachineInfo) -> dict[str, Any]:
    """The head of a run's record: the command that reproduces it, how long it took, when
    the record was written (UTC) and the machine (CPU, versions, device, load averages)."""
    return {"command": command, "seconds": seconds,
            "written": datetime.now(timezone.utc).isoformat(timespec="seconds"), "machine": asdict(machine)}


_DELIMITERS = {"-": "---", "l": ":---", "r": "---:", "c": ":---:"}


def markdown_table(header: Sequence[object], rows: Iterable[Sequence[object]], *, align: str | None = None) -> str:
    """A GitHub-flavoured Markdown table: the header line, the delimiter line, then one line per
    row, joined by newlines (no final newline, so it drops into a list of lines).

    Every cell is ``str(cell)`` with each ``|`` escaped as ``\\|`` (an unescaped one would split the
    cell, even inside a code span) and each line break turned into a space (a row is one line).
    ``align``: one letter per column, ``-`` (none: ``---``), ``l`` (``:---``), ``r`` (``---:``) or
    ``c`` (``:---:``); None: none for every column. A row whose length is not the header's, or an
    ``align`` of another length or letter, raises ValueError (a bug of the caller, not of the data).
    """
    header = [_table_cell(h) for h in header]
    align = "-" * len(header) if align is None else align
    if len(align) != len(header) or set(align) - set(_DELIMITERS):
        raise ValueError(f"markdown_table: align {align!r} must be {len(header)} of the letters "
                         f"{''.join(_DELIMITERS)}")
    lines = [_table_line(header), "|" + "|".join(_DELIMITERS[a] for a in align) + "|"]
    for row in rows:
        cells = [_table_cell(c) for c in row]
        if len(cells) != len(header):
            raise ValueError(f"markdown_table: a row of {len(cells)} cells under {len(header)} columns: {cells}")
        lines.append(_table_line(cells))
    return "\n".join(lines)


def _table_cell(value: object) -> str:
    return " ".join(str(value).replace("|", "\\|").splitlines())


def _table_line(cells: Sequence[str]) -> str:
    return "| " + " | ".join(cells) + " |"


__all__ = ["write_text", "write_json", "write_parquet", "write_csv", "write_binary", "save_figure", "run_header",
           "markdown_table"]
