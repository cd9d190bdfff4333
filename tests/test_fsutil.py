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


def test_building_dir_replaces_out_and_leaves_nothing_beside_it(tmp_path):
    out = make(tmp_path / "out", "old")
    with fsutil.building_dir(out) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".out.tmp-") and not any(tmp.iterdir())
        (tmp / "data.txt").write_text("new")
        fsutil.write_manifest(tmp, {"hash": "abc", "matrix": [[1.0, 0.0], [0.0, 1.0]]})
    assert (out / "data.txt").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert fsutil.manifest_hash(out) == "abc"
    assert fsutil.read_manifest(out) == {"hash": "abc", "matrix": [[1.0, 0.0], [0.0, 1.0]]}
    assert '"matrix": [\n  [1.0, 0.0],\n  [0.0, 1.0]\n ]' in (out / fsutil.MANIFEST).read_text()  # rows on one line


def test_building_dir_keeps_out_when_the_build_fails(tmp_path):
    out = make(tmp_path / "out", "old")
    with pytest.raises(KeyboardInterrupt):
        with fsutil.building_dir(out) as tmp:
            (tmp / "data.txt").write_text("half")
            raise KeyboardInterrupt
    assert (out / "data.txt").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # the temporary folder is gone


def test_a_folder_without_a_readable_manifest_has_no_hash(tmp_path):
    folder = make(tmp_path / "f", "x")
    assert fsutil.read_manifest(folder) is None and fsutil.manifest_hash(folder) is None
    (folder / fsutil.MANIFEST).write_text("[1, 2]")  # JSON, but not an object
    assert fsutil.read_manifest(folder) is None
    (folder / fsutil.MANIFEST).write_text('{"hash": 3}')  # a hash that is not a string
    assert fsutil.read_manifest(folder) == {"hash": 3} and fsutil.manifest_hash(folder) is None
