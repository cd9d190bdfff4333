"""A run record keeps its run's notes (the trial's issue 3): the loader's lines (the images
folder and its reduction, undistortion, masks, the split rule) and the start's, in an optional
``notes`` field that records written before it lack; the train report's Resolution line says
from them how each capture's photos were read."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from splatbench.experiments.store import RunRecord, build_table, check_record, read_record, read_records, write_record
from splatbench.experiments.train_report import protocol_lines
from tests.test_dry_run_inputs import llff_capture

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "reports" / "sh_degree" / "runs"


def _record(**kw) -> RunRecord:
    return RunRecord(**{"run_id": "0123456789abcdef", "experiment": "e", "kind": "train", "scene": "s", "seed": 0,
                        "status": "done", "config": {"x": 1}, **kw})


def test_notes_are_optional_in_a_record_and_its_table(tmp_path):
    plain = _record()
    assert "notes" not in plain.to_dict()  # a record without notes is the earlier format, byte for byte
    write_record(tmp_path, plain)
    assert "notes" not in json.loads((tmp_path / "e" / "0123456789abcdef.json").read_text())
    noted = _record(notes=["LLFF layout: ...", "masks: masks_8/ (9 object masks) become the views' alphas"])
    write_record(tmp_path, noted)
    assert read_record(tmp_path / "e" / "0123456789abcdef.json") == noted
    with pytest.raises(ValueError, match="notes: expected a list of strings"):
        check_record({**noted.to_dict(), "notes": [1]}, "0123456789abcdef.json")
    assert "notes" not in build_table([plain]).columns
    table = build_table([plain, noted])
    assert table.columns[-3:].tolist() == ["notes", "warnings", "curves"]
    assert table.notes.tolist() == [None, json.dumps(noted.notes)]


@pytest.mark.skipif(not COMMITTED.is_dir(), reason="needs reports/sh_degree/runs")
def test_committed_records_without_notes_still_read_and_report_as_before():
    records = read_records(COMMITTED)
    older = [r for r in records.values() if r.notes == []]  # the grid's first runs, made before runs kept notes
    assert len(older) >= 48, len(older)
    for chosen in (older, list(records.values())):  # alone, and beside later records that keep notes
        lines = protocol_lines(build_table(chosen))
        resolution = next(line for line in lines if line.startswith("- **Resolution**"))
        # (records with notes add how each capture was read after its size: "fox 1/12 (89×158 px; OPENCV ...")
        assert "fox 1/12 (89×158 px" in resolution and "maryrose 1/24 (144×144 px" in resolution


def test_a_train_runs_loader_notes_reach_its_record_and_the_reports_resolution_line(tmp_path):
    from splatbench.experiments import parse_experiment, run_experiment
    import tomllib

    llff_capture(tmp_path / "cap")
    text = f"""
name = "noted"
kind = "train"
scenes = [{{ name = "cap", path = "{tmp_path / 'cap'}", downscale = 16 }}]
seeds = [0]
[base]
iterations = 4
log_every = 2
init.method = "random"
init.random_points = 200
eval.lpips_net = "none"
"""
    spec = parse_experiment(tomllib.loads(text), source="noted.toml", default_name="noted")
    summary = run_experiment(spec, workers=1, results_dir=tmp_path / "results", progress=False)
    assert summary.done == 1, summary
    (record,) = read_records(tmp_path / "results" / "noted").values()
    assert any(n.startswith("LLFF layout: poses_bounds.npy, 9 views of 512x512 originals") and
               "images_8/ read and reduced by 2 to 32x32 by area averaging" in n for n in record.notes)
    assert "masks: masks_8/ (9 object masks) become the views' alphas: the photos are composited over the run's " \
           "background (data.masks=false ignores them)" in record.notes
    assert any("every 8th image by sorted name is a test view (2 test, 7 train" in n for n in record.notes)
    lines = protocol_lines(build_table([record]))
    resolution = next(line for line in lines if line.startswith("- **Resolution**"))
    assert "cap 1/16 (32×32 px; images_8/ reduced by 2 on load; masks_8/ as alphas)" in resolution, resolution


def test_the_resolution_line_names_undistortion_from_the_loaders_note_not_its_cache_path(tmp_path, monkeypatch):
    from splatbench.data import load_dataset
    from tests.test_dry_run_inputs import blender_capture

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    notes = list(load_dataset(blender_capture(tmp_path / "cap", distortion=True), downscale=2).notes)
    assert any(str(tmp_path / "cache") in n for n in notes)  # the loader's note names this machine's cache
    record = _record(config={"iterations": 4, "scene": "cap", "data": {"path": str(tmp_path / "cap"), "downscale": 2}},
                     metrics={"image_width": 24, "image_height": 16}, notes=notes)
    resolution = next(line for line in protocol_lines(build_table([record])) if line.startswith("- **Resolution**"))
    assert "s 1/2 (24×16 px; OPENCV lens distortion undistorted by pycolmap)" in resolution, resolution
    assert str(tmp_path) not in resolution
