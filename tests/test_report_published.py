"""Beside published numbers (issue 39): an experiment file's ``[[report.published]]`` entries, each a
published difference between two cells or a published value of one cell on one scene, and the report's
section "Beside published numbers" that sets the grid's own result beside each (docs/reports.md).

The grids are of the dummy kind of `tests.kinds_for_tests`; their results are records written as the
engine writes them, with values chosen here, so the file runs in seconds and every number is
recomputed independently from the report's ``results.parquet`` (scipy's t quantile, not the project's).
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from splatbench.errors import InputError
from splatbench.experiments import expand, parse_experiment
from splatbench.experiments.grid import check_experiment, load_experiment, published_runs
from splatbench.experiments.spec import PublishedSpec
from splatbench.experiments.store import RunRecord, write_record
from splatbench.metrics.spec import MetricSpec
from splatbench.metrics.stats import Interval
from splatbench.reports import build_report, write_report
from splatbench.reports.published import TITLE, placement, published_results
from tests.assertions import one_line_error
from tests.kinds_for_tests import KIND

GRID = f"""
name = "pub"
kind = "{KIND}"
scenes = ["alpha", "beta"]
seeds = [0, 1, 2]
[axes]
x = [0.0, 1.0]
[variants.style]
plain = {{ opts.b = "p" }}
fancy = {{ opts.b = "q" }}
"""

DIFFERENCE = """
[[report.published]]
cells = [{ x = 1.0, style = "fancy" }, { x = 1.0, style = "plain" }]
value = 0.5
source = "Somebody et al. 2024, Table 3"
protocol = "graphdeco-30k, Mip-NeRF 360 at 1/4 resolution"
"""

ABSOLUTE = """
[[report.published]]
cell = { x = 0, style = "plain" }
scene = "beta"
value = 0.3
metric = "total"
source = "Other 2023, Table 1"
protocol = "their own"
"""


def spec_of(text: str):
    spec = parse_experiment(tomllib.loads(text), source="x.toml", default_name="x")
    check_experiment(spec)
    return spec


def results(root, spec, gain: float = 0.4, noise: float = 0.1, seed: int = 0) -> None:
    """Every run of the grid done: ``value`` = x (+ ``gain`` for style fancy) + seed noise; ``total`` = 2 value."""
    rng = np.random.default_rng(seed)
    for run in expand(spec):
        v = run.config["x"] + (gain if run.labels["style"] == "fancy" else 0.0) + float(rng.normal(0, noise))
        write_record(root, RunRecord(run_id=run.run_id, experiment=spec.name, kind=spec.kind, scene=run.scene,
                                     seed=run.seed, status="done", config=dict(run.config), labels=dict(run.labels),
                                     metrics={"value": v, "total": 2 * v, "a_plus_seed": run.seed, "scene_tag": "t",
                                              "positive": True},
                                     curves={}, seconds=1.0, started="2026-01-01T00:00:00+00:00",
                                     finished="2026-01-01T00:00:01+00:00", worker="h:1"))


def t95(values) -> tuple[float, float, float]:
    """(mean, low, high) of the 95 % Student's t interval of ``values``, computed here with scipy."""
    v = np.asarray(values, dtype=float)
    half = stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / math.sqrt(len(v))
    return float(v.mean()), float(v.mean() - half), float(v.mean() + half)


def per_seed(table: pd.DataFrame, scene: str, x: float, style: str, metric: str = "value") -> dict[int, float]:
    """Seed -> ``metric`` of the run of cell (x, style) at ``scene``, read from a report's run table."""
    sel = table[(table.scene == scene) & (table["axis.x"].astype(float) == x) & (table["axis.style"] == style)]
    return dict(zip(sel.seed.astype(int), sel[f"metric.{metric}"].astype(float)))


# --------------------------------------------------------------------------- parsing
def test_entries_parse_into_published_specs_and_change_no_run():
    spec = spec_of(GRID + DIFFERENCE + ABSOLUTE)
    diff, absolute = spec.published
    assert diff == PublishedSpec(cells=({"x": 1.0, "style": "fancy"}, {"x": 1.0, "style": "plain"}), value=0.5,
                                 source="Somebody et al. 2024, Table 3",
                                 protocol="graphdeco-30k, Mip-NeRF 360 at 1/4 resolution")
    assert diff.is_difference and diff.metric is None and diff.scene is None
    assert not absolute.is_difference and absolute.cells == ({"x": 0, "style": "plain"},)
    assert (absolute.scene, absolute.metric, absolute.value) == ("beta", "total", 0.3)
    # a [report] key changes no run: the same run ids as the file without it
    assert [r.run_id for r in expand(spec)] == [r.run_id for r in expand(spec_of(GRID))]
    # each entry's runs are the grid's runs of its cells: a difference at every scene, a value at its own
    grid = {r.run_id: r for r in expand(spec)}
    a, b = published_runs(spec, diff)
    assert [(r.scene, r.seed) for r in a] == [(s, k) for s in ("alpha", "beta") for k in (0, 1, 2)]
    assert all(r.run_id in grid and grid[r.run_id].labels == {"x": 1.0, "style": "fancy"} for r in a)
    assert all(r.run_id in grid and grid[r.run_id].labels == {"x": 1.0, "style": "plain"} for r in b)
    (only,) = published_runs(spec, absolute)
    assert [(r.scene, r.seed, r.labels["style"]) for r in only] == [("beta", k, "plain") for k in (0, 1, 2)]
    assert spec_of(GRID).published == ()


ONE_AT_A_TIME = f"""
name = "oat"
kind = "{KIND}"
scenes = ["alpha"]
seeds = [0, 1]
grid = "one-at-a-time"
[base]
x = 0.5
[axes]
x = [0.5, 2.0]
n = [3, 5]
"""


def test_a_one_at_a_time_grid_takes_its_base_and_one_value():
    spec = spec_of(ONE_AT_A_TIME + """
[[report.published]]
cells = [{ n = 5 }, {}]
value = 1.0
source = "s"
protocol = "p"
""")
    a, b = published_runs(spec, spec.published[0])
    assert {r.config["n"] for r in a} == {5} and {r.config["n"] for r in b} == {3}
    # an axis value equal to the base is the base: the two cells are the same runs
    one_line_error(lambda: spec_of(ONE_AT_A_TIME + '[[report.published]]\ncells = [{ x = 0.5 }, {}]\nvalue = 1\n'
                                                   'source = "s"\nprotocol = "p"\n'),
                   "x.toml: report.published[0].cells: both cells are the same runs")


GOOD = {"cells": [{"x": 1.0, "style": "fancy"}, {"x": 1.0, "style": "plain"}], "value": 0.5, "source": "s",
        "protocol": "p"}


@pytest.mark.parametrize("change, drop, message", [
    ({"colour": 1}, (), "report.published[0].colour: unknown key"),
    ({}, ("value",), "report.published[0].value: missing"),
    ({}, ("source",), "report.published[0].source: missing"),
    ({}, ("protocol",), "report.published[0].protocol: missing"),
    ({"source": "  "}, (), "report.published[0].source: expected where it is published"),
    ({"protocol": 3}, (), "report.published[0].protocol: expected its protocol"),
    ({"value": "0.5"}, (), "report.published[0].value: expected the published number"),
    ({"value": float("nan")}, (), "report.published[0].value: expected the published number"),
    ({"value": True}, (), "report.published[0].value: expected the published number"),
    ({"metric": 3}, (), "report.published[0].metric: expected a metric's name"),
    ({}, ("cells",), "report.published[0]: expected either cells = [A, B]"),
    ({"cell": {"x": 0.0, "style": "plain"}, "scene": "alpha"}, (), "report.published[0]: expected either cells"),
    ({"cells": [{"x": 1.0, "style": "fancy"}]}, (), "report.published[0].cells: expected two cells, A then B"),
    ({"cells": [{"x": 1.0, "style": "fancy"}] * 2}, (), "report.published[0].cells: the two cells are the same cell"),
    ({"cells": [{"x": 3.0, "style": "fancy"}, {"x": 1.0, "style": "plain"}]}, (),
     "report.published[0].cells[0].x: 3.0 is not a value of the grid's axis 'x'"),
    ({"cells": [{"x": 1.0, "style": "gold"}, {"x": 1.0, "style": "plain"}]}, (),
     "report.published[0].cells[0].style: 'gold' is not a value of the grid's variant 'style'"),
    ({"cells": [{"x": 1.0}, {"x": 1.0, "style": "plain"}]}, (),
     "report.published[0].cells[0]: names no value of 'style' (a cell of a product grid"),
    ({"cells": [{"y": 1.0, "style": "fancy"}, {"x": 1.0, "style": "plain"}]}, (),
     "report.published[0].cells[0].y: not an axis of the grid"),
    ({"scene": "alpha"}, (), "report.published[0].scene: a published difference stands beside every scene"),
])
def test_a_bad_entry_is_one_line_naming_its_key(change, drop, message):
    entry = {k: v for k, v in {**GOOD, **change}.items() if k not in drop}
    data = {**tomllib.loads(GRID), "report": {"published": [entry]}}
    one_line_error(lambda: parse_experiment(data, source="x.toml", default_name="x"), f"x.toml: {message}")


@pytest.mark.parametrize("entry, message", [
    ({"cell": {"x": 0.0, "style": "plain"}, "value": 1, "source": "s", "protocol": "p"},
     "report.published[0].scene: expected the grid's scene the value is of (one of: alpha, beta), got None"),
    ({"cell": {"x": 0.0, "style": "plain"}, "scene": "lego", "value": 1, "source": "s", "protocol": "p"},
     "report.published[0].scene: expected the grid's scene the value is of (one of: alpha, beta), got 'lego'"),
    ({"cell": {"x": 0.0}, "scene": "alpha", "value": 1, "source": "s", "protocol": "p"},
     "report.published[0].cell: names no value of 'style'"),
])
def test_a_bad_absolute_entry_is_one_line(entry, message):
    data = {**tomllib.loads(GRID), "report": {"published": [entry]}}
    one_line_error(lambda: parse_experiment(data, source="x.toml", default_name="x"), f"x.toml: {message}")


def test_published_must_be_an_array_of_tables():
    data = {**tomllib.loads(GRID), "report": {"published": dict(GOOD)}}  # [report.published], not [[...]]
    one_line_error(lambda: parse_experiment(data, source="x.toml"), "x.toml: report.published: expected an array of")
    data = {**tomllib.loads(GRID), "report": {"published": [GOOD, "absgrad"]}}
    one_line_error(lambda: parse_experiment(data, source="x.toml"), "x.toml: report.published[1]: expected a table")


@pytest.mark.parametrize("metric, message", [
    ("psnr", "report.published[0].metric: 'psnr' is not a metric 'tests.kinds_for_tests:DUMMY' reports "
             "(expected one of: value, total, a_plus_seed)"),
    ("scene_tag", "report.published[0].metric: 'scene_tag' is not a metric"),  # a string: no number to stand beside
])
def test_a_metric_the_kind_does_not_report_is_refused_at_load_time(tmp_path, metric, message):
    path = tmp_path / "x.toml"
    path.write_text(GRID + DIFFERENCE + f'metric = "{metric}"\n')
    one_line_error(lambda: load_experiment(path), f"{path}: {message}")
    # a spec parsed alone (not loaded) meets the same line when its report is built
    parsed = parse_experiment(tomllib.loads(GRID + DIFFERENCE + f'metric = "{metric}"\n'), source="x.toml")
    one_line_error(lambda: published_results(parsed, parsed.run_kind, pd.DataFrame()), f"x.toml: {message}")
    path.write_text(GRID + DIFFERENCE + 'metric = "total"\n')
    assert load_experiment(path).published[0].metric == "total"


# --------------------------------------------------------------------------- the section
def test_rows_are_the_paired_difference_and_the_cells_mean_computed_from_the_table(tmp_path):
    spec = spec_of(GRID + DIFFERENCE + ABSOLUTE)
    results(tmp_path / "results", spec)
    report = build_report(spec, tmp_path / "results")
    text = write_report(report, tmp_path / "report").read_text()
    table = pd.read_parquet(tmp_path / "report" / "results.parquet")
    diff, absolute = published_results(spec, report.kind, table)
    # a difference: one row per scene of the grid, fancy − plain at x = 1 paired seed by seed
    assert [r.scene for r in diff.rows] == ["alpha", "beta"] and diff.metric.name == "value"  # the headline
    assert diff.labels == ("x=1, style=fancy", "x=1, style=plain")
    for row in diff.rows:
        a, b = per_seed(table, row.scene, 1.0, "fancy"), per_seed(table, row.scene, 1.0, "plain")
        mean, low, high = t95([a[s] - b[s] for s in (0, 1, 2)])
        assert (row.interval.estimate, row.interval.low, row.interval.high) == pytest.approx((mean, low, high))
        assert row.interval.n == 3 and row.text == f"{mean:+.4g} [95 % CI {low:+.4g}, {high:+.4g}]"
        expected = "inside" if float(f"{low:.4g}") <= 0.5 <= float(f"{high:.4g}") else \
            "above" if 0.5 > float(f"{high:.4g}") else "below"
        assert row.verdict == expected
        assert (f"| {row.scene} | {row.text} | 3 of 3 | +0.5 | the published value lies {expected} this interval |"
                in text)
    # an absolute value: its scene only, the cell's own mean over seeds of the metric it names
    (row,) = absolute.rows
    mean, low, high = t95(list(per_seed(table, "beta", 0.0, "plain", "total").values()))
    assert row.scene == "beta" and absolute.metric.name == "total"
    assert (row.interval.estimate, row.interval.low, row.interval.high) == pytest.approx((mean, low, high))
    assert f"| beta | {mean:.4g} [95 % CI {low:.4g}, {high:.4g}] | 3 of 3 | 0.3 |" in text
    # the section: a title per entry, its source, and the sentence that says what differs
    assert f"## {TITLE}" in text
    assert "### `x=1, style=fancy` − `x=1, style=plain`, value" in text
    assert "Published: +0.5 (Somebody et al. 2024, Table 3)." in text
    assert "### `x=0, style=plain` on beta, total" in text
    assert ("**Not a replication**: this grid's number is at its own settings (its runs name no protocol) on its own "
            "scenes (alpha, beta), one row each, 3 seeds (the header gives its settings); the published one's "
            "protocol: graphdeco-30k, Mip-NeRF 360 at 1/4 resolution;") in text
    assert "on its scene beta, 3 seeds (the header gives its settings); the published one's protocol: their own;" \
        in text


@pytest.mark.parametrize("where, verdict", [("estimate", "inside"), ("high", "above"), ("low", "below")])
def test_the_verdict_says_where_the_published_value_lies(tmp_path, where, verdict):
    spec = spec_of(GRID)
    results(tmp_path / "results", spec, noise=0.2)
    table = pd.read_parquet(write_report(build_report(spec, tmp_path / "results"), tmp_path / "r").parent
                            / "results.parquet")
    a, b = per_seed(table, "alpha", 1.0, "fancy"), per_seed(table, "alpha", 1.0, "plain")
    mean, low, high = t95([a[s] - b[s] for s in (0, 1, 2)])
    assert high - low > 0.2  # noise 0.2 over 3 seeds: a wide interval, so the three values below differ
    value = {"estimate": mean, "high": high + 0.1, "low": low - 0.1}[where]
    published = spec_of(GRID + DIFFERENCE.replace("value = 0.5", f"value = {value!r}"))
    text = write_report(build_report(published, tmp_path / "results"), tmp_path / "p").read_text()
    section = text.split(f"## {TITLE}")[1]
    row = next(line for line in section.splitlines() if line.startswith("| alpha | "))
    assert row.endswith(f"| the published value lies {verdict} this interval |"), row


PSNR = MetricSpec("test_psnr", "test PSNR (dB)", ".2f", unit="dB")


@pytest.mark.parametrize("iv, value, verdict", [
    (Interval(0.2, 0.1104, 0.3, 3, "paired t"), 0.11, "inside"),   # the bound written +0.11 holds 0.11
    (Interval(0.2, 0.1151, 0.3, 3, "paired t"), 0.11, "below"),    # written +0.12
    (Interval(0.2, 0.1, 0.2951, 3, "paired t"), 0.30, "inside"),   # written +0.30
    (Interval(0.2, 0.1, 0.2949, 3, "paired t"), 0.30, "above"),    # written +0.29
    (Interval(0.2, math.nan, math.nan, 1, "paired t"), 0.2, "no interval"),   # one seed
    (Interval(0.2, 0.1999, 0.2001, 3, "paired t"), 0.2, "no interval"),      # seeds did not vary it (±0.00)
    (Interval(math.nan, math.nan, math.nan, 0, "paired t"), 0.2, "no result"),
])
def test_placement_judges_the_bounds_as_written(iv, value, verdict):
    assert placement(iv, value, PSNR) == verdict


def test_no_entry_no_section_and_missing_runs_give_no_verdict(tmp_path):
    spec = spec_of(GRID)
    results(tmp_path / "results", spec)
    text = write_report(build_report(spec, tmp_path / "results"), tmp_path / "plain").read_text()
    # no entry: one line saying none is declared, no section (and no verdict)
    assert f"## {TITLE}" not in text and "Not a replication" not in text
    assert f"\n**{TITLE}**: none declared (the experiment file has no `[[report.published]]`)" in text
    # an entry whose runs have no result yet: the section all the same, no verdict
    published = spec_of(GRID + DIFFERENCE)
    text = write_report(build_report(published, tmp_path / "empty"), tmp_path / "none").read_text()
    assert f"## {TITLE}" in text
    assert "| alpha | – | 0 of 3 | +0.5 | no finished run yet: no verdict |" in text


def test_the_shipped_densification_entry_is_gsplats_absgrad_difference():
    """experiments/densification.toml stands beside gsplat's feature ablation (docs/source/tests/eval.rst,
    PROTOCOL.md): absgrad 29.11 against default 29.00 dB at 30K on 7 Mip-NeRF 360 scenes; its [check] reruns
    those two cells at graphdeco-30k (the check's row beside it)."""
    from pathlib import Path

    data = tomllib.loads((Path(__file__).resolve().parents[1] / "experiments" / "densification.toml").read_text())
    data["scenes"] = ["thin"]  # its captures' folders are not in every clone; the entry does not depend on them
    data.pop("extra")  # its extra cells name the captures (and [report] matched names them)
    data["report"].pop("matched")
    check = data.pop("check")  # its scene is a capture; the check's cells are the entry's, reversed
    assert check["protocol"] == "graphdeco-30k"
    assert [check["cells"][1], check["cells"][0]] == data["report"]["published"][0]["cells"]
    spec = parse_experiment(data, source="densification.toml", default_name="densification")
    (entry,) = spec.published
    assert entry.cells == ({"densify": "absgrad"}, {"densify": "default"}) and entry.metric is None
    assert entry.value == pytest.approx(29.11 - 29.00) and "eval.rst" in entry.source
    assert "30,000 steps" in entry.protocol and "7 Mip-NeRF 360 scenes" in entry.protocol
    with pytest.raises(InputError):  # its cells are the grid's: a cell it does not have would not parse
        parse_experiment({**data, "report": {**data["report"], "published": [
            {**data["report"]["published"][0], "cells": [{"densify": "absgrad2"}, {"densify": "default"}]}]}},
            source="densification.toml")


TRAIN_GRID = """
name = "trainpub"
kind = "train"
scenes = ["diffuse", "glossy"]
seeds = [0, 1, 2]
[base]
protocol = "graphdeco-7k"
eval.every = 700
data.resolution = 32
data.views = 8
data.spp = 2
[variants.densify]
default = { strategy.name = "default" }
absgrad = { strategy.name = "absgrad" }
[[report.published]]
cells = [{ densify = "absgrad" }, { densify = "default" }]
value = 0.11
source = "gsplat docs/source/tests/eval.rst"
protocol = "gsplat at 30,000 steps, 7 Mip-NeRF 360 scenes"
"""


def test_a_train_grid_stands_its_test_psnr_beside_the_published_difference(tmp_path):
    """The train kind: the headline is test PSNR in dB, and the sentence names the protocol its runs recorded."""
    from tests.test_check import record  # a finished train run's record, as the engine writes it

    spec = spec_of(TRAIN_GRID)
    for run in expand(spec):  # absgrad +0.30 dB over default on glossy, nothing on diffuse; seed s adds 0.01 s² dB
        gain = 0.3 if run.labels["densify"] == "absgrad" and run.scene == "glossy" else 0.0
        write_record(tmp_path / "results",
                     record(spec, run, 26.0 + gain + 0.01 * run.seed ** 2 * (run.labels["densify"] == "absgrad")))
    text = write_report(build_report(spec, tmp_path / "results"), tmp_path / "report").read_text()
    assert "### `densify=absgrad` − `densify=default`, test PSNR (dB)" in text
    assert "Published: +0.11 dB (gsplat docs/source/tests/eval.rst)." in text
    # absgrad − default per seed: diffuse 0, 0.01, 0.04; glossy 0.30, 0.31, 0.34 (t interval from scipy)
    for scene, diffs in (("diffuse", [0.0, 0.01, 0.04]), ("glossy", [0.30, 0.31, 0.34])):
        mean, low, high = t95(diffs)
        verdict = "inside" if round(low, 2) <= 0.11 <= round(high, 2) else "above" if 0.11 > round(high, 2) else "below"
        assert (f"| {scene} | {mean:+.2f} dB [95 % CI {low:+.2f}, {high:+.2f}] | 3 of 3 | +0.11 dB | the published "
                f"value lies {verdict} this interval |") in text
    assert "glossy | +0.32 dB" in text and "lies below this interval" in text  # the glossy row: 0.11 below it
    assert ("this grid's number is at protocol `graphdeco-7k` on its own scenes (diffuse, glossy), one row each, "
            "3 seeds") in text and "the published one's protocol: gsplat at 30,000 steps, 7 Mip-NeRF 360 scenes;" in text


CHECK = """
[check]
protocol = "long"
scene = "alpha"
cells = [{ x = 1.0, style = "plain" }, { x = 1.0, style = "fancy" }]
"""


def test_a_difference_of_the_checks_cells_gets_the_checks_row(tmp_path):
    """densification.toml: gsplat's absgrad − default is published at 30K and the file's [check] reruns
    default against absgrad at graphdeco-30k: the check's runs stand beside it too, a row of their own
    (last), oriented as the published difference (the check lists the reference first: plain, fancy)."""
    from splatbench.experiments.grid import check_cells
    from splatbench.reports.check import check_table

    spec = spec_of(GRID + CHECK + DIFFERENCE)
    results(tmp_path / "results", spec)
    rng = np.random.default_rng(7)
    check_values: dict[str, dict[int, float]] = {"plain": {}, "fancy": {}}
    for cell in check_cells(spec):  # the check's runs: fancy 0.9 above plain (seed noise 0.1)
        for run in cell:
            style = run.labels["style"]
            v = 5.0 + (0.9 if style == "fancy" else 0.0) + float(rng.normal(0, 0.1))
            check_values[style][run.seed] = v
            write_record(tmp_path / "results", RunRecord(
                run_id=run.run_id, experiment=spec.name, kind=spec.kind, scene=run.scene, seed=run.seed,
                status="done", config=dict(run.config), labels=dict(run.labels),
                metrics={"value": v, "total": 2 * v, "a_plus_seed": run.seed, "scene_tag": "t", "positive": True},
                curves={}, seconds=1.0, started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:01+00:00",
                worker="h:1"))
    report = build_report(spec, tmp_path / "results")
    table = pd.read_parquet(write_report(report, tmp_path / "report").parent / "results.parquet")
    (diff,) = published_results(spec, report.kind, table, check_table(spec, tmp_path / "results"))
    assert [r.scene for r in diff.rows] == ["alpha", "beta", "alpha, the check at long (`long`)"]
    assert diff.check_protocol == "long"
    mean, low, high = t95([check_values["fancy"][s] - check_values["plain"][s] for s in (0, 1, 2)])
    row = diff.rows[-1]
    assert mean > 0.5  # fancy − plain, as published: a sign slip would give about −0.9
    assert (row.interval.estimate, row.interval.low, row.interval.high) == pytest.approx((mean, low, high))
    # without the check's table the row is there, with no result; a published difference of other cells
    # gets no check row
    (bare,) = published_results(spec, report.kind, table)
    assert bare.rows[-1].verdict == "no result"
    other = spec_of(GRID + CHECK + DIFFERENCE.replace('{ x = 1.0, style = "plain" }]', '{ x = 0.0, style = "fancy" }]'))
    (unrelated,) = published_results(other, report.kind, table, check_table(other, tmp_path / "results"))
    assert [r.scene for r in unrelated.rows] == ["alpha", "beta"] and unrelated.check_protocol == ""
