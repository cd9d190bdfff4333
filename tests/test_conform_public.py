"""reports/conform_public/ (issue 20 item 6): every package that tools/conform_public.py checks has
its committed conform.json and report.md, and the README's table is what those JSON files give (a
hand edit or a table left behind after a rerun fails here). Rerunning conform on the packages
themselves is `make conform-public`, not part of the test suite: it installs them from PyPI."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("conform_public", ROOT / "tools" / "conform_public.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def test_every_package_is_reported_with_its_pinned_install():
    tool = _tool()
    for p in tool.PACKAGES:
        folder = tool.REPORTS / p.name
        assert (folder / "report.md").is_file(), f"no report.md for {p.name}"
        report = json.loads((folder / "conform.json").read_text())
        assert report["install"] == tool.install_command(p), f"{p.name}: conform.json is from other pins"
        assert all("==" in r for r in p.requirements), f"{p.name}: unpinned requirement"
        if p.requirements:  # the version conform reports is the pinned one
            pinned = dict(r.split("==") for r in p.requirements)
            assert report["version"] == pinned[p.name], (p.name, report["version"])


def test_readme_table_is_the_committed_json():
    tool = _tool()
    text = (tool.REPORTS / "README.md").read_text()
    between = text.split(tool.BEGIN, 1)[1].split(tool.END, 1)[0].strip()
    assert between == tool.table(), "reports/conform_public/README.md table is stale: run make conform-public"
