"""The benchmarks' result files: one CSV row per result, and a JSON record of the
machine, the settings and the results (shared by `bench raster` and `bench train`)."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any


def write_csv_rows(rows: Iterable[dict[str, Any]], columns: Sequence[str], path: Path) -> Path:
    """Write ``rows`` under the header ``columns`` (keys not in ``columns`` are left out)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow(row)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(buf.getvalue())
    return path


def write_results_json(results: Sequence[Any], machine: Any, settings: Any, path: Path) -> Path:
    """``{"machine": ..., "settings": ..., "results": [...]}`` of dataclasses, indented."""
    payload = {"machine": asdict(machine), "settings": asdict(settings), "results": [asdict(r) for r in results]}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(payload, indent=2) + "\n")
    return path
