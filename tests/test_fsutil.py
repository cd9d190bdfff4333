"""replace_dir never loses a result: the older folder survives a failed rename."""

from __future__ import annotations

import os

import pytest

from splatbench import fsutil


def make(folder, text):
    folder.mkdir()
    (folder / "data.txt").write_text(text)
    return folder


def test_replaces_an_older_folder(tmp_path):
    out = make(tmp_path / "out", "old")
    fsutil.replace_dir(make(tmp_path / "tmp", "new"), out)
    assert (out / "data.txt").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no leftovers


def test_failed_rename_restores_the_older_folder(tmp_path, monkeypatch):
    out = make(tmp_path / "out", "old")
    tmp = make(tmp_path / "tmp", "new")

    def fail(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(fsutil.os, "rename", fail)
    with pytest.raises(OSError, match="disk full"):
        fsutil.replace_dir(tmp, out)
    assert (out / "data.txt").read_text() == "old"


def test_an_equivalent_folder_put_there_meanwhile_is_kept(tmp_path, monkeypatch):
    out = tmp_path / "out"
    tmp = make(tmp_path / "tmp", "ours")

    def race(src, dst):  # another process finishes the same folder first
        make(out, "theirs")
        raise OSError("directory not empty")

    monkeypatch.setattr(fsutil.os, "rename", race)
    fsutil.replace_dir(tmp, out, accept_existing=lambda path: (path / "data.txt").exists())
    assert (out / "data.txt").read_text() == "theirs"
    with pytest.raises(OSError):
        os.rmdir(out)  # still there, not emptied
