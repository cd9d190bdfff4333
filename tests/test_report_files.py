"""splatbench.report_files: the one writer of the verification applications' report files
(compare, conform, stress, validate) and of the shared figures."""

from __future__ import annotations

import json
import re

import pandas as pd
import pytest

from splatbench.metrics.machine import machine_info
from splatbench.report_files import (markdown_table, run_header, save_figure, write_csv, write_json, write_parquet,
                                     write_text)


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


def test_save_figure_writes_a_png_and_closes_the_figure(tmp_path):
    from splatbench.figures import pyplot

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
