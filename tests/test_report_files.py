"""splatbench.report_files: the one file writer of every part at the measurement level and
above (results, reports, caches, checkpoints, figures) and the one Markdown table writer."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pandas as pd
import pytest

from splatbench.metrics.machine import machine_info
from splatbench.report_files import (markdown_table, run_header, save_figure, write_binary, write_csv, write_json,
                                     write_parquet, write_text)


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def test_each_kind_of_file_round_trips(tmp_path):
    out = tmp_path / "deep" / "folder"  # parents are made
    assert write_text(out / "r.md", "# é\n").read_text(encoding="utf-8") == "# é\n"
    path = write_json(out / "r.json", {"a": [1, 2], "where": tmp_path}, indent=2)
    assert path.read_text(encoding="utf-8").endswith("}\n")
    assert json.loads(path.read_text(encoding="utf-8")) == {"a": [1, 2], "where": str(tmp_path)}
    frame = pd.DataFrame({"x": [1.5, 2.5], "name": ["a", "b"]})
    pd.testing.assert_frame_equal(pd.read_parquet(write_parquet(out / "t.parquet", frame)), frame)
    csv = write_csv(out / "t.csv", ["x", "name"], ({"x": x, "name": n} for x, n in [(1, "a"), (2, "b,c")]))
    assert csv.read_bytes() == b'x,name\n1,a\n2,"b,c"\n'  # LF line endings (POSIX text)
    assert _leftovers(out) == []


def test_a_write_that_fails_leaves_the_older_file(tmp_path):
    """Atomic: rows that raise half-way leave the previous file whole, and no temporary."""
    path = write_csv(tmp_path / "t.csv", ["x"], [{"x": 1}])

    def rows():
        yield {"x": 2}
        raise RuntimeError("stopped half-way")

    with pytest.raises(RuntimeError, match="half-way"):
        write_csv(path, ["x"], rows())
    assert path.read_bytes() == b"x\n1\n"
    assert _leftovers(tmp_path) == []


def test_write_binary_hands_a_stream_and_keeps_the_name(tmp_path):
    import numpy as np

    path = write_binary(tmp_path / "a.npy", lambda stream: np.save(stream, np.arange(3)))
    assert path == tmp_path / "a.npy" and np.load(path).tolist() == [0, 1, 2]  # no ".npy" added to any name

    def half(stream):
        stream.write(b"half a file")
        raise KeyboardInterrupt  # a run stopped mid-write

    with pytest.raises(KeyboardInterrupt):
        write_binary(path, half)
    assert np.load(path).tolist() == [0, 1, 2] and _leftovers(tmp_path) == []


PACKAGE = Path(__file__).resolve().parents[1] / "splatbench"
#: The modules below the measurement level that write their own files through the primitive
#: `fsutil.atomic_write` (they may not import `report_files`, a level above them).
PRIMITIVE_USERS = {"fsutil.py", "report_files.py", "images.py", "ply.py", "workloads.py"}
#: Calls that write a file whole by themselves only in `report_files`.
WRITER_CALLS = {"savefig", "to_parquet", "to_csv", "mkstemp", "NamedTemporaryFile"}
#: Plain ``Path.write_text`` / ``write_bytes`` where the file need not land atomically, and why.
PLAIN_WRITES = {
    "fsutil.py": "write_manifest: the last file of a folder built by building_dir, which lands whole",
    "scenes/render.py": "files inside the dataset folder building_dir builds",
    "regress/files.py": "the manifest inside the snapshot folder building_dir builds",
    "experiments/claims.py": "a claim's temporary, hard-linked onto its name only once written (a lock, no result)",
    "report_files.py": "write_text's own temporary, which atomic_write renames into place",
}


def _calls(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else None
            yield node.lineno, name, isinstance(f, ast.Attribute)


def test_every_result_report_and_cache_file_goes_through_the_one_writer():
    """No module above the model level writes a file but through `report_files` (atomic): no
    bare ``savefig`` (a half PNG), ``to_parquet``, ``mkstemp`` or ``atomic_write`` of its own."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = path.relative_to(PACKAGE).as_posix()
        for line, name, attribute in _calls(ast.parse(path.read_text(encoding="utf-8"))):
            if name == "atomic_write" and module not in PRIMITIVE_USERS:
                found.append(f"{module}:{line}: atomic_write (use splatbench.report_files)")
            elif name in WRITER_CALLS and module != "report_files.py":
                found.append(f"{module}:{line}: {name} (use splatbench.report_files)")
            elif attribute and name in ("write_text", "write_bytes") and module not in PLAIN_WRITES:
                found.append(f"{module}:{line}: Path.{name} (use splatbench.report_files.write_text)")
    assert found == []
    # the exceptions still occur: the lists only shrink
    for module in PLAIN_WRITES:
        names = {name for _, name, attribute in _calls(ast.parse((PACKAGE / module).read_text(encoding="utf-8")))
                 if attribute}
        assert names & {"write_text", "write_bytes"}, f"{module} no longer writes plainly: drop it from PLAIN_WRITES"


def test_save_figure_writes_a_png_and_closes_the_figure(tmp_path):
    from splatbench.plotting import pyplot

    plt = pyplot()
    fig, ax = plt.subplots()
    ax.set_title("a title")
    path = save_figure(fig, tmp_path / "f.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert fig.number not in plt.get_fignums()
    assert _leftovers(tmp_path) == []


def test_run_header_names_the_command_time_and_machine():
    header = run_header("splatbench compare --backend drjit", 12.5, machine_info("cpu"))
    assert list(header) == ["command", "seconds", "written", "machine"]
    assert header["command"] == "splatbench compare --backend drjit" and header["seconds"] == 12.5
    assert header["written"].endswith("+00:00")  # UTC
    assert {"cpu_count", "cpu_model", "device", "loadavg_start", "loadavg_end"} <= set(header["machine"])
    json.dumps(header)  # JSON-ready


def test_markdown_table_aligns_and_escapes():
    text = markdown_table(["name", "value"], [["a", 1.5], ["b", None]], align="-r")
    assert text == "| name | value |\n|---|---:|\n| a | 1.5 |\n| b | None |"  # no final newline
    assert markdown_table(["x"], [], align="c") == "| x |\n|:---:|"
    assert markdown_table(["x", "y"], [], align="lr").splitlines()[1] == "|:---|---:|"


def test_a_pipe_or_line_break_in_a_cell_stays_in_its_cell():
    # A bare `|` would split the cell (GitHub splits even inside a code span); a line break would end the row.
    text = markdown_table(["run", "error"], [["`a|b`", "x | y\nsecond line"]])
    rows = text.splitlines()
    assert len(rows) == 3 and rows[2] == "| `a\\|b` | x \\| y second line |"
    # every row has as many unescaped separators as the header
    assert {len(re.findall(r"(?<!\\)\|", row)) for row in rows} == {3}


def test_markdown_table_refuses_a_ragged_row_or_a_bad_alignment():
    with pytest.raises(ValueError, match="a row of 1 cells under 2 columns"):
        markdown_table(["a", "b"], [["only one"]])
    with pytest.raises(ValueError, match="align"):
        markdown_table(["a", "b"], [], align="r")
    with pytest.raises(ValueError, match="align"):
        markdown_table(["a"], [], align="x")
