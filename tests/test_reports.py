"""Reports (issue 6 §3) and the train / raster run kinds.

The report tests build a results folder by hand: the real grid of a ``train``
experiment (its run ids from `expand`) with made-up, seeded metrics and curves written
as the engine writes them (`write_record`, `write_table`), so they run in seconds.
They check that every table cell and every number of the findings can be recomputed
from the ``results.parquet`` written beside ``report.md``, and that the figures exist.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from splatbench.experiments.train_report import floats_per_gaussian
from splatbench.errors import InputError
from splatbench.experiments import RunRecord, expand, parse_experiment
from splatbench.experiments.store import write_record, write_table
from splatbench.reports import build_report, write_report
from splatbench.plotting import pareto_front
from splatbench.reports.findings import fmt_interval
from splatbench.metrics.stats import holm, paired_difference, paired_ratio
from splatbench.experiments.train_kind import REPORT as TRAIN_REPORT
from splatbench.experiments.train_kind import TRAIN
from splatbench.reports.tables import Stat

#: The train kind's table metrics, as its result declares them.
TRAIN_METRICS = tuple(TRAIN.specs[name] for name in TRAIN_REPORT.metrics)

SCENES = ["diffuse", "glossy"]
SH_VALUES = [0, 1, 3, "auto"]


def sh_spec(seeds=(0, 1, 2)):
    return parse_experiment({"name": "shfake", "kind": "train", "scenes": SCENES, "seeds": list(seeds),
                             "base": {"iterations": 100, "data": {"resolution": 32, "views": 8, "spp": 2}},
                             "axes": {"sh.degree": SH_VALUES}}, source="shfake.toml")


def fake_metrics(scene: str, degree, seed: int) -> tuple[dict, dict]:
    """Seeded numbers with a real pattern: SH helps on glossy only; auto picks 0 / 2."""
    rng = np.random.default_rng([SCENES.index(scene), SH_VALUES.index(degree), seed])
    d = {"auto": 0 if scene == "diffuse" else 2}.get(degree, degree)
    psnr = 26.0 + (1.5 * d if scene == "glossy" else 0.0) + rng.normal(0, 0.1)
    steps = [0, 50, 100]
    metrics = {"test_psnr": psnr, "test_ssim": 0.8 + 0.01 * d + rng.normal(0, 0.002),
               "num_gaussians": int(1000 + 100 * d + rng.integers(0, 20)), "train_seconds": 10.0 + 2 * d + rng.random(),
               "render_ms_per_view": 5.0 + d + rng.random(), "sh_degree": d, "peak_rss_mb": 500.0,
               "iterations": 100, "test_views": 1, "dataset_hash": "0" * 16,
               "test_lpips": 0.2 - (0.02 * d if scene == "glossy" else 0.0) + rng.normal(0, 0.005),
               "lpips_net": "alex", "lpips_scale_inputs": 1, "cpu_seconds": 15.0 + rng.random(),
               "load_before": 0.5, "load_after": 1.5, "load_other": 0.2, "cores": 2, "time_loaded": 0,
               "run_peak_rss_mb": 600.0 + 20 * d + seed}
    curves = {"step": steps, "psnr": [psnr - 6, psnr - 2, psnr], "loss": [0.3, 0.2, 0.1],
              "num_gaussians": [1000] * 3, "eval_step": [50, 100], "eval_psnr": [psnr - 1, psnr],
              "eval_ssim": [0.7, 0.8], "eval_lpips": [0.3, 0.2]}
    return metrics, curves


def done_record(spec, run, metrics: dict, curves) -> RunRecord:
    """A finished train run's record with the given metrics and curves (fixed times, one worker)."""
    return RunRecord(run_id=run.run_id, experiment=spec.name, kind="train", scene=run.scene, seed=run.seed,
                     status="done", config=dict(run.config), labels=dict(run.labels), metrics=metrics, curves=curves,
                     error=None, seconds=1.0, started="2026-01-01T00:00:00+00:00",
                     finished="2026-01-01T00:00:01+00:00", worker="h:1")


@pytest.fixture(scope="module")
def sh_results(tmp_path_factory):
    """A results folder for `sh_spec`: every run done but one failed and one missing."""
    root = tmp_path_factory.mktemp("results")
    spec = sh_spec()
    runs = expand(spec)
    records = []
    for i, run in enumerate(runs):
        if i == 5:
            continue  # never ran
        metrics, curves = fake_metrics(run.scene, run.labels["sh.degree"], run.seed)
        status = "failed" if i == 7 else "done"
        rec = RunRecord(run_id=run.run_id, experiment=spec.name, kind="train", scene=run.scene, seed=run.seed,
                        status=status, config=dict(run.config), labels=dict(run.labels),
                        metrics=metrics if status == "done" else {}, curves=curves if status == "done" else None,
                        error="RuntimeError: boom" if status == "failed" else None, seconds=12.5,
                        started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:13+00:00", worker="h:1")
        write_record(root, rec)
        records.append(rec)
    write_table(root / spec.name, records)
    return spec, root, runs


@pytest.fixture(scope="module")
def sh_report(sh_results, tmp_path_factory):
    spec, root, runs = sh_results
    out = tmp_path_factory.mktemp("reports") / spec.name
    report = build_report(spec, root)
    path = write_report(report, out)
    return report, path, runs


def recompute(table: pd.DataFrame) -> dict:
    """(scene, label) -> metric -> Stat, straight from the parquet (labels as the report writes them)."""
    done = table[table.status == "done"]
    out = {}
    for (scene, label), group in done.groupby(["scene", "axis.sh.degree"]):
        label = json.loads(label) if isinstance(label, str) else label
        out[(scene, str(label))] = {m.name: Stat(float(group[f"metric.{m.name}"].mean()),
                                                 float(group[f"metric.{m.name}"].std(ddof=1)), len(group))
                                    for m in TRAIN_METRICS}
    return out


def test_report_files(sh_report):
    report, path, runs = sh_report
    folder = path.parent
    assert path.name == "report.md" and path.is_file()
    figures = sorted(p.name for p in (folder / "figures").glob("*.png"))
    assert figures == ["curves_sh_degree.png", "gaussians_vs_error.png", "time_vs_error.png"]
    for name in figures:
        assert (folder / "figures" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = path.read_text()
    for name in figures:
        assert f"](figures/{name})" in text
    assert f"{len(runs)} runs of kind `train` ({len(runs) - 2} done, 1 failed, 1 not run)" in text
    assert "## Failed runs" in text and "RuntimeError: boom" in text


def test_report_tables_match_parquet(sh_report):
    report, path, runs = sh_report
    table = pd.read_parquet(path.parent / "results.parquet")
    assert len(table) == len(runs) - 1 and set(table.run_id) <= {r.run_id for r in runs}
    expected = recompute(table)
    text = path.read_text()
    rows = [line for line in text.splitlines() if line.startswith("| diffuse") or line.startswith("| glossy")]
    assert len(rows) == len(SCENES) * len(SH_VALUES)
    specs = TRAIN_METRICS
    for line in rows:
        cells = [c.strip() for c in line.strip("|").split("|")]
        scene, label, count = cells[0], cells[1].strip("`"), int(cells[2])
        stats = expected[(scene, label)]
        assert count == stats["test_psnr"].n
        for spec, cell in zip(specs, cells[3:]):
            st = stats[spec.name] if spec.interval else dataclasses.replace(stats[spec.name], std=math.nan)
            assert cell == st.text(spec.fmt), (scene, label, spec.name)


def per_seed(table: pd.DataFrame, scene: str, label: str, metric: str) -> dict[int, float]:
    """Seed -> metric of the done run of (scene, SH degree label), straight from the parquet."""
    done = table[(table.status == "done") & (table.scene == scene)]
    sel = done[done["axis.sh.degree"].map(lambda v: str(json.loads(v) if isinstance(v, str) else v)) == label]
    return {int(s): float(v) for s, v in zip(sel.seed, sel[f"metric.{metric}"])}


def test_findings_numbers_match_parquet(sh_report):
    report, path, _ = sh_report
    table = pd.read_parquet(path.parent / "results.parquet")
    expected = recompute(table)
    text = path.read_text()
    claims = report.findings["sh.degree"].claims
    kinds = {c.kind for c in claims}
    # glossy's SH 3 leads SH 2 by 1.5 dB at ~x1.08 the Gaussians (1300 against 1200 made): "no single
    # best at comparable size" (docs/reports.md, "Best"), with its size claim; diffuse: no lead at all
    assert kinds == {"no best", "size", "vs", "count", "auto", "model size", "holm"}
    specs = {m.name: m for m in TRAIN_METRICS}
    effects = {c.metric: c.min_effect for c in TRAIN_REPORT.rules.comparisons}
    for c in claims:
        if c.kind in ("best", "no best"):
            # the leader by mean against the runner-up, paired over seeds
            ranked = sorted(((v[c.metric].mean, lab) for (s, lab), v in expected.items() if s == c.scene),
                            reverse=True)
            assert (c.label, c.reference) == (ranked[0][1], ranked[1][1])
            iv = paired_difference(per_seed(table, c.scene, c.reference, c.metric),
                                   per_seed(table, c.scene, c.label, c.metric))
            lead = iv.excludes(0.0) and iv.estimate >= effects[c.metric]
            assert lead == (c.significant and c.practical)
            # the SH degrees differ, so does each Gaussian's size (14 floats at degree 0, 59 at 3): the model's
            # size is its bytes, Gaussians × floats_per_gaussian(degree) × 4 (docs/reports.md, "Best")
            def model_bytes(label):
                g, d = (per_seed(table, c.scene, label, m) for m in ("num_gaussians", "sh_degree"))
                return {k: g[k] * floats_per_gaussian(int(d[k])) * 4 for k in g}

            size = paired_ratio(model_bytes(c.reference), model_bytes(c.label))
            larger = lead and float(f"{size.estimate:.3f}") >= 1.0 + effects["num_gaussians"]
            assert (c.kind == "best") == (lead and not larger)
            assert ("at comparable size" in c.text) == larger
            if larger:  # the size claim beside it: the paired geometric-mean ratio of the counts
                s = next(x for x in claims if x.kind == "size" and x.scene == c.scene)
                assert (s.label, s.reference) == (c.label, c.reference)
                assert (s.value, s.low, s.high) == pytest.approx((size.estimate, size.low, size.high))
                assert s.metric == "bytes" and f"at {s.text} the bytes (×" in c.text
            if c.kind == "best":
                assert c.value == pytest.approx(ranked[0][0], abs=1e-12)
        elif c.kind == "vs":
            # paired over the seeds both rows have (one run missing, one failed: fewer pairs there)
            a = per_seed(table, c.scene, c.reference, c.metric)
            b = per_seed(table, c.scene, c.label, c.metric)
            iv = (paired_difference if c.how == "diff" else paired_ratio)(a, b)
            assert (c.value, c.low, c.high, c.n) == pytest.approx((iv.estimate, iv.low, iv.high, iv.n), nan_ok=True)
            null = 0.0 if c.how == "diff" else 1.0
            assert c.significant == iv.excludes(null)  # seeded noise: every interval has a spread
            assert c.text == fmt_interval(iv, c.how, specs[c.metric], null, effects[c.metric])
            # an effect is ruled out only where the whole interval lies within ± the minimum effect (recomputed
            # here from the bounds; a ratio's bound r as the relative change max(r, 1 / r) - 1)
            m = effects[c.metric]
            size = (lambda r: max(r, 1 / r) - 1) if c.how == "ratio" else abs
            within = m is not None and max(size(iv.low), size(iv.high)) < m
            assert ("no practical difference" in c.text) == within
            assert ("no significant difference" in c.text) == (iv.defined and not c.significant and not within)
            assert ("inconclusive" in c.text) == (m is not None and not within and not c.practical)
            assert c.practical == (c.significant and (m is None or size(iv.estimate) >= m))
        elif c.kind == "count":
            # every printed interval: the paired comparisons against the reference, and the leader's
            # lead over the runner-up with its size against it (one "no best" and one "size" per scene)
            leads = sum(1 for x in claims if x.kind in ("best", "no best", "size") and x.reference
                        and math.isfinite(x.low))  # seeded noise: every interval has a spread
            # 5 compared metrics: test PSNR, SSIM, LPIPS, train time, Gaussians
            assert sum(1 for x in claims if x.kind == "vs") == 3 * len(SCENES) * 5 and leads >= len(SCENES)
            assert c.value == 3 * len(SCENES) * 5 + leads
            assert f"This table makes {int(c.value)} comparisons" in text
        elif c.kind == "holm":
            # Holm over the test PSNR comparisons against the reference, each p-value scipy's paired t test
            # straight from the parquet (seeded noise: every interval has a spread, so all 3 x 2 are in it)
            family = [x for x in claims if x.kind == "vs" and x.metric == c.metric]
            p = []
            for x in family:
                a, b = (per_seed(table, x.scene, label, x.metric) for label in (x.reference, x.label))
                seeds = sorted(set(a) & set(b))
                p.append(stats.ttest_rel([b[k] for k in seeds], [a[k] for k in seeds]).pvalue)
            kept = holm(p)
            assert (c.n, c.value) == (len(family), sum(kept))
            for x, q, k in zip(family, p, kept):
                said = "p < 0.001" if q < 0.001 else f"p = {q:.3f}"
                assert (f"{x.scene} `{x.label}` ({said})" in c.text) == k
        elif c.kind == "model size":
            # parameters: Gaussians x (3 + 3 + 4 + 1 + 3 (d + 1)²) at the degree each run ended at, paired ratio
            def params(label):
                g, d = (per_seed(table, c.scene, label, m) for m in ("num_gaussians", "sh_degree"))
                return {k: g[k] * (11 + 3 * (int(d[k]) + 1) ** 2) for k in g}

            iv = paired_ratio(params(c.reference), params(c.label))
            assert (c.value, c.n) == pytest.approx((iv.estimate, iv.n)) and c.text == f"×{iv.estimate:.3f}"
        elif c.kind == "auto":
            done = table[(table.status == "done") & (table.scene == c.scene)]
            auto = done[done["axis.sh.degree"] == json.dumps("auto")]
            assert c.value == pytest.approx(auto["metric.sh_degree"].mean())
        assert c.text in text
    # The pattern the numbers were made with is what the findings say.
    best = {c.scene: c.label for c in claims if c.kind == "best"}
    assert best == {}  # on diffuse SH changes nothing; on glossy SH 3 leads with 8 % more Gaussians
    assert "diffuse: no single best (" in text and "glossy: no single best at comparable size (`3`" in text
    auto = {c.scene: c.text for c in claims if c.kind == "auto"}
    assert auto == {"diffuse": "0", "glossy": "2"}
    gain = next(c for c in claims if c.kind == "vs" and c.scene == "glossy" and c.label == "3"
                and c.metric == "test_psnr")
    # +4.5 dB made, seed noise 0.1 dB: a significant gain over 3 paired seeds
    assert 4.0 < gain.value < 5.0 and gain.n == 3 and gain.significant and 4.0 < gain.low < gain.high < 5.0
    assert re.search(r"`3`: test PSNR \S+ dB \[95 % CI [^]]+\](, (no significant difference|no practical difference|inconclusive)[^/]*)? / " + re.escape(gain.text),
                     text)
    assert "95 % Student's t interval over seeds" in text


def test_train_report_names_its_lpips_and_leaves_loaded_times_out(tmp_path):
    """A train grid where one run was timed under others' load: kept in the table (its
    `timed under load` column) and in the quality comparisons, left out of the time ones;
    the report says which LPIPS its column is. A table of the grids run before LPIPS and
    load were recorded (no such columns) reports without them."""
    spec = sh_spec()
    runs = expand(spec)
    loaded_run = next(r for r in runs if r.scene == "glossy" and r.labels["sh.degree"] == 3 and r.seed == 2)
    old = ("test_lpips", "lpips_net", "lpips_scale_inputs", "cpu_seconds", "load_before", "load_after",
           "load_other", "cores", "time_loaded")
    for name, drop in (("new", ()), ("old", old)):
        records = []
        for run in runs:
            metrics, curves = fake_metrics(run.scene, run.labels["sh.degree"], run.seed)
            metrics["time_loaded"] = int(run is loaded_run)
            metrics = {k: v for k, v in metrics.items() if k not in drop}
            records.append(done_record(spec, run, metrics, curves))
            write_record(tmp_path / name, records[-1])
        write_table(tmp_path / name / spec.name, records)
        report = build_report(spec, tmp_path / name)
        text = write_report(report, tmp_path / "out" / name).read_text()
        vs = {(c.metric, c.n) for c in report.findings["sh.degree"].claims
              if c.kind == "vs" and c.scene == "glossy" and c.label == "3"}
        if name == "new":
            assert "| LPIPS |" in text and "| timed under load (fraction of runs) |" in text
            assert "The `LPIPS` column is LPIPS v0.1, AlexNet backbone, inputs scaled to [-1, 1]" in text
            # seed 2's times are out (2 pairs), its PSNR and LPIPS in (3 pairs)
            assert vs == {("test_psnr", 3), ("test_ssim", 3), ("test_lpips", 3), ("train_seconds", 2),
                          ("num_gaussians", 3)}
            assert "1 run(s) timed while other processes loaded the machine are left out of the render / train time comparisons" in text
            assert (f"Load: 1 of {len(runs)} runs timed while other processes loaded the machine (`metric.time_loaded`: "
                    f"their times are left out of the time comparisons, their quality kept); others' estimated load "
                    f"0.20–0.20 on 2 cores.") in text
        else:
            assert "| LPIPS |" not in text and "The `LPIPS` column" not in text and "LPIPS not recorded" in text
            assert "timed under load" not in text and "Load:" not in text
            # without a load record, times are shown but said to be no evidence
            assert "did not record the machine's load" in text
            assert vs == {("test_psnr", 3), ("test_ssim", 3), ("train_seconds", 3), ("num_gaussians", 3)}


def test_one_seed_report_says_no_interval(sh_results, tmp_path):
    """With one seed the report is written, every comparison says it has no interval,
    and nothing is called significant."""
    spec, root, _ = sh_results
    one = sh_spec(seeds=(0,))
    report = build_report(one, root)
    text = write_report(report, tmp_path / "one").read_text()
    vs = [c for c in report.findings["sh.degree"].claims if c.kind == "vs"]
    assert vs and all(c.n == 1 and not c.significant and "(1 seed: no interval)" in c.text for c in vs)
    assert "but none has an interval (one seed per cell" in text and "±" not in text


def test_one_at_a_time_rows_and_generic_kind(tmp_path):
    """Dummy kind (no kind-specific metrics): one-at-a-time rows are the base and each
    value alone; every numeric metric gets a column; a cell equal to the base is the base."""
    from splatbench.experiments.runner import run_experiment

    spec = parse_experiment({"name": "oat", "kind": "tests.kinds_for_tests:DUMMY", "scenes": ["alpha"], "seeds": [0, 1],
                             "grid": "one-at-a-time", "base": {"x": 1.0},
                             "axes": {"x": [1.0, 2.0], "n": [5]}}, source="oat.toml")
    run_experiment(spec, workers=1, results_dir=tmp_path, progress=False)
    report = build_report(spec, tmp_path)
    path = write_report(report, tmp_path / "report")
    x_table = next(t for t in report.axes if t.axis == "x")
    assert [r.label for r in x_table.rows] == ["1 (base)", "2"]
    n_table = next(t for t in report.axes if t.axis == "n")
    assert [r.label for r in n_table.rows] == ["3 (base)", "5"]
    assert all(len(r.run_ids) == 2 for r in n_table.rows)
    assert {m.name for m in report.metrics} == {"value", "total", "a_plus_seed"}
    table = pd.read_parquet(path.parent / "results.parquet")
    base = table[(table["axis.x"] == 1.0) & (table["axis.n"] == 3)]
    assert x_table.stat("alpha", "1 (base)", "value").mean == pytest.approx(base["metric.value"].mean())
    assert "## x" in path.read_text() and "## n" in path.read_text()


def test_pareto_front():
    # time, quality: (1, 1) and (2, 3) and (4, 4) are optimal; (3, 2) is beaten by (2, 3).
    assert pareto_front([2, 1, 3, 4, float("nan")], [3, 1, 2, 4, 9]) == [1, 0, 3]
    assert pareto_front([1, 1], [2, 2]) == [0, 1]  # equal points dominate neither


# Cell -> (final Gaussians, test PSNR) of `test_gaussians_pareto_figure_names_the_front`:
# absgrad beats default on both (fewer and better); mcmc beats budget (as many, better).
DENSIFY_CELLS = {"none": (20_000, 24.0), "default": (35_000, 26.0), "absgrad": (30_000, 26.5),
                 "mcmc": (40_000, 27.0), "budget": (40_000, 26.8)}


def test_gaussians_pareto_figure_names_the_front(tmp_path):
    """Issue 23: a train grid whose results have a Gaussian count gets the figure of test
    PSNR against the final number of Gaussians (means over 3 seeds, 95 % intervals), and
    report.md names the cells on its front, fewest Gaussians first: here none -> absgrad ->
    mcmc (default and budget are dominated). Results without a Gaussian count get no such
    figure; the time figure is drawn either way."""
    spec = parse_experiment({"name": "densfake", "kind": "train", "scenes": ["diffuse"], "seeds": [0, 1, 2],
                             "base": {"iterations": 100, "data": {"resolution": 32, "views": 8, "spp": 2}},
                             "variants": {"densify": {k: {"strategy": k} for k in DENSIFY_CELLS}}},
                            source="densfake.toml")
    runs = expand(spec)
    for name, drop in (("with", False), ("without", True)):
        records = []
        for run in runs:
            count, psnr = DENSIFY_CELLS[run.labels["densify"]]
            metrics, curves = fake_metrics("diffuse", 0, run.seed)
            # seed noise well inside the gaps between cells (0.2 dB, 2,000 Gaussians)
            metrics.update(test_psnr=psnr + 0.01 * (run.seed - 1), num_gaussians=count + 10 * run.seed)
            if drop:
                del metrics["num_gaussians"]
            records.append(done_record(spec, run, metrics, curves))
            write_record(tmp_path / name, records[-1])
        write_table(tmp_path / name / spec.name, records)
        report = build_report(spec, tmp_path / name)
        path = write_report(report, tmp_path / "out" / name)
        text = path.read_text()
        figure = path.parent / "figures" / "gaussians_vs_error.png"
        assert (path.parent / "figures" / "time_vs_error.png").is_file()
        if drop:
            assert not figure.exists() and "gaussians_vs_error" not in text and "gaussians_vs_error" not in report.fronts
            continue
        assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert report.fronts["gaussians_vs_error"] == {"diffuse": ["densify=none", "densify=absgrad", "densify=mcmc"]}
        assert "## Gaussians against test PSNR (dB)" in text and "](figures/gaussians_vs_error.png)" in text
        assert ("- Pareto front on diffuse, fewest Gaussians first: `densify=none` → `densify=absgrad` → "
                "`densify=mcmc`") in text
        assert "no other cell is both smaller (fewer Gaussians) and better" in text


def test_figure_labels_leave_out_the_axes_shared_prefix(tmp_path):
    """The Pareto figures label points without the axes' shared dotted prefix
    (``refine_stop=25%``); the report's text still names each front cell in full."""
    from splatbench.reports.tables import cell_labels, shared_prefix

    assert shared_prefix(["strategy.refine_stop", "strategy.reset_every"]) == "strategy."
    assert shared_prefix(["a.b.c", "a.b.d"]) == "a.b." and shared_prefix(["a.x", "b.y"]) == ""
    assert shared_prefix(["sh_degree"]) == "" and shared_prefix(["strategy.cap_max"]) == "strategy."
    spec = parse_experiment({"name": "oatfake", "kind": "train", "scenes": ["diffuse"], "seeds": [0, 1],
                             "grid": "one-at-a-time",
                             "base": {"iterations": 100, "data": {"resolution": 32, "views": 8, "spp": 2},
                                      "strategy": {"refine_stop": "50%", "grad_threshold": 2e-4}},
                             "axes": {"strategy.refine_stop": ["25%", "50%"],
                                      "strategy.grad_threshold": [2e-4, 4e-4]}}, source="oatfake.toml")
    runs = expand(spec)
    # more Gaussians, better PSNR, cell by cell: every cell is on the front
    cells = {"base": (30_000, 26.0), "refine_stop=25%": (20_000, 25.0), "grad_threshold=0.0004": (25_000, 25.5)}
    records = []
    for run in runs:
        short = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in run.labels.items()
                          if v != {"strategy.refine_stop": "50%",
                                   "strategy.grad_threshold": 2e-4}[k]) or "base"
        count, psnr = cells[short]
        metrics, curves = fake_metrics("diffuse", 0, run.seed)
        metrics.update(test_psnr=psnr + 0.01 * run.seed, num_gaussians=count + run.seed)
        records.append(done_record(spec, run, metrics, curves))
        write_record(tmp_path, records[-1])
    write_table(tmp_path / spec.name, records)
    report = build_report(spec, tmp_path)
    assert set(cell_labels(spec, report.table, short=True)) == set(cells)
    text = write_report(report, tmp_path / "out").read_text()
    front = ["strategy.refine_stop=25%", "strategy.grad_threshold=0.0004", "base"]
    assert report.fronts["gaussians_vs_error"] == {"diffuse": front}
    assert "fewest Gaussians first: " + " → ".join(f"`{c}`" for c in front) in text


# --------------------------------------------------------------------------- kinds
def test_train_kind_config_errors_and_defaults():
    from splatbench.experiments.kinds import get_kind
    from splatbench.experiments.grid import make_run_id

    kind = get_kind("train")
    base = {"scene": "diffuse", "seed": 0}
    with pytest.raises(InputError, match=r"^iteration: unknown key \(did you mean 'iterations'\?\)$"):
        kind.validate({**base, "iteration": 5})
    with pytest.raises(InputError, match=r"^dataset: set by the train kind"):
        kind.validate({**base, "dataset": "/tmp/x"})
    with pytest.raises(InputError, match=r"^data\.spp: expected an int >= 1, got 0$"):
        kind.validate({**base, "data": {"spp": 0}})
    with pytest.raises(InputError, match=r"^data\.width: unknown key"):
        kind.validate({**base, "data": {"width": 3}})
    resolved = kind.resolve({**base, "iterations": 10})
    assert "dataset" not in resolved and "out" not in resolved
    assert resolved["data"] == {"resolution": 256, "views": 32, "spp": 64,  # the diffuse rig's
                                "layout": "auto", "test_every": 8, "masks": True}  # DataConfig's defaults
    assert resolved["strategy"]["grad_threshold"] == 2e-4  # the strategy's own defaults
    explicit = kind.resolve({**base, "iterations": 10, "loss": {"ssim_lambda": 0.2}, "data": {"resolution": 256},
                             "strategy": {"refine_every": 100}})
    assert make_run_id("train", explicit) == make_run_id("train", resolved)
    assert kind.resolve({**base, "iterations": 10, "loss": {"ssim_lambda": 1}})["loss"]["ssim_lambda"] == 1.0
    assert {"diffuse", "glossy", "textured"} <= kind.scenes()


def test_train_kind_keeps_run_fractions():
    """A step field written as a fraction of the run stays that string in the resolved
    config (the run scales it once, as written; a resolved step count would be scaled
    again under schedule = "scaled"); every strategy field is in it, so a changed one
    (revised_opacity) is a new run and one written at its default is the same run."""
    from splatbench.experiments.grid import make_run_id
    from splatbench.experiments.train_kind import TRAIN
    from splatbench.train.config import TrainConfig

    base = {"scene": "diffuse", "seed": 0, "iterations": 2000}
    resolved = TRAIN.resolve({**base, "strategy": {"refine_stop": "75%", "reset_every": 0}})
    assert resolved["strategy"]["refine_stop"] == "75%" and resolved["strategy"]["reset_every"] == 0
    cfg = TrainConfig.from_dict({k: v for k, v in resolved.items() if k not in ("scene", "data")})
    assert cfg.make_strategy().refine_stop == 1500   # 75 % of 2000, not scaled again
    plain = TRAIN.resolve(base)
    assert plain["strategy"]["revised_opacity"] is False
    assert make_run_id("train", plain) == make_run_id("train", TRAIN.resolve(
        {**base, "strategy": {"revised_opacity": False}}))
    revised = TRAIN.resolve({**base, "strategy": {"revised_opacity": True}})
    assert revised["strategy"]["revised_opacity"] is True
    assert make_run_id("train", revised) != make_run_id("train", plain)


def test_train_kind_test_spp(tmp_path, monkeypatch):
    """data.test_spp: validated at the boundary; at its default (data.spp) the run and its
    dataset folder are the ones made before the field existed; otherwise the test views
    of the run's dataset are rendered with it."""
    from splatbench.experiments.grid import make_run_id
    from splatbench.experiments.train_kind import TRAIN, dataset_folder
    from splatbench.scenes import read_manifest

    base = {"scene": "diffuse", "seed": 0, "iterations": 10}
    with pytest.raises(InputError, match=r"^data\.test_spp: expected an int >= 1, got 0$"):
        TRAIN.validate({**base, "data": {"test_spp": 0}})
    with pytest.raises(InputError, match=r"^data\.test_spp: expected an int >= 1, got 'many'$"):
        TRAIN.validate({**base, "data": {"test_spp": "many"}})
    monkeypatch.setenv("SPLATBENCH_DATASETS", str(tmp_path / "data"))
    plain = TRAIN.resolve({**base, "data": {"spp": 2}})
    same = TRAIN.resolve({**base, "data": {"spp": 2, "test_spp": 2}})
    assert plain["data"] == same["data"] == {"resolution": 256, "views": 32, "spp": 2,
                                             "layout": "auto", "test_every": 8, "masks": True}
    assert make_run_id("train", plain) == make_run_id("train", same)
    assert dataset_folder("diffuse", plain["data"]).name == "diffuse-256-v32-s2"
    clean = TRAIN.resolve({**base, "data": {"resolution": 16, "views": 8, "spp": 2, "test_spp": 16}})
    assert clean["data"]["test_spp"] == 16 and make_run_id("train", clean) != make_run_id("train", plain)
    folder = dataset_folder("diffuse", clean["data"])
    assert folder.name == "diffuse-16-v8-s2-t16"
    TRAIN.prepare([clean])
    assert read_manifest(folder)["settings"]["test_spp"] == 16


def test_raster_kind_config_errors():
    from splatbench.experiments.kinds import get_kind

    kind = get_kind("raster")
    base = {"scene": "synthetic-100-32", "seed": 0}
    kind.validate(base)
    with pytest.raises(InputError, match=r"^scene: unknown workload 'synth-1'"):
        kind.validate({**base, "scene": "synth-1"})
    with pytest.raises(InputError, match=r"^tile_size: expected a power of two"):
        kind.validate({**base, "tile_size": 12})
    with pytest.raises(InputError, match=r"^sh.degree: expected an int in 0\.\.3, got 4$"):
        kind.validate({**base, "sh_degree": 4})
    with pytest.raises(InputError, match=r"^tile_siz: unknown key \(did you mean 'tile_size'\?\)$"):
        kind.validate({**base, "tile_siz": 8})
    # numbers normalised: an int where RasterOptions declares a float is that float (one run id)
    one = kind.resolve({**base, "eps2d": 1})
    assert one["eps2d"] == 1.0 and isinstance(one["eps2d"], float) and one == kind.resolve({**base, "eps2d": 1.0})


def test_raster_kind_run(tmp_path, monkeypatch):
    """Tiny runs: paired timings with a bootstrap interval, the load recorded, work done,
    parity with the matched reference, and the error against the exact mixture."""
    from splatbench.experiments.kinds import metric_values
    from splatbench.experiments.raster_kind import RASTER

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    base = RASTER.resolve({"scene": "synthetic-300-32", "seed": 1, "error_scale": 0.5})
    assert base["repeats"] == 7
    out = RASTER.run(base, tmp_path, None)
    m = metric_values(out)
    assert m["fwd_ms"] > 0 and m["fwd_bwd_ms"] > 0 and m["n"] == 300 and m["timed_pairs"] == 7
    assert all(len(out.curves[k]) == 7 for k in ("fwd_runs_ms", "default_fwd_bwd_runs_ms"))
    # the median of the 7 per-pair ratios, inside its bootstrap interval (the ends are pair ratios)
    ratios = [a / b for a, b in zip(out.curves["fwd_bwd_runs_ms"], out.curves["default_fwd_bwd_runs_ms"])]
    assert m["fwd_bwd_rel"] == pytest.approx(sorted(ratios)[3], rel=1e-3)
    assert m["fwd_bwd_rel_low"] <= m["fwd_bwd_rel"] <= m["fwd_bwd_rel_high"]
    assert m["loaded"] in (0, 1) and m["load_before"] >= 0 and m["cores"] >= 1
    assert m["loaded"] == int(m["load_other"] > m["cores"] / 2)
    # work: compositing skips the 4x4 blocks outside the support, so it performs at most the
    # pairs x 16² of whole tiles, and at least the useful evaluations (inside the support)
    assert m["pairs"] > 0 and 0 < m["useful_evaluations"] <= m["evaluations"] <= m["pairs"] * 16 ** 2
    assert (m["error_width"], m["error_height"]) == (16, 16)
    assert m["parity_max_abs"] < 1e-4            # float32 against float64 with the same options
    assert list((tmp_path / "cache" / "reference").glob("*exact*.npy"))  # the exact model is cached
    # the defaults cut faint tails: farther from the exact mixture than from their own reference
    assert m["exact_max_abs"] > 10 * m["parity_max_abs"]
    tiles = metric_values(RASTER.run({**base, "tile_size": 4}, tmp_path, None))
    assert tiles["exact_max_abs"] == pytest.approx(m["exact_max_abs"], abs=1e-6)  # tiles never change the image
    assert tiles["evaluations"] == tiles["pairs"] * 4 ** 2
    # a lower alpha_min keeps more of each Gaussian: closer to the exact model, not "error"
    closer = metric_values(RASTER.run({**base, "alpha_min": 1e-4}, tmp_path, None))
    assert closer["exact_mean_abs"] < m["exact_mean_abs"] and closer["exact_psnr"] > m["exact_psnr"]
    coarse = metric_values(RASTER.run({**base, "sh_degree": 0}, tmp_path, None))
    assert coarse["parity_max_abs"] < 1e-4 and math.isfinite(coarse["exact_psnr"])
    assert coarse["exact_psnr"] < m["exact_psnr"]   # dropping view dependence moves away from the model
    with pytest.raises(InputError, match=r"^repeats: expected at least 7 timed pairs"):
        RASTER.validate({"scene": "synthetic-300-32", "seed": 0, "repeats": 3})


def test_train_kind_run(tmp_path, monkeypatch):
    """A 3-step run on a 32-pixel dataset: the metrics and curves the reports read."""
    from splatbench.experiments.kinds import metric_values
    from splatbench.experiments.train_kind import CURVE_KEYS, TRAIN, dataset_folder

    monkeypatch.setenv("SPLATBENCH_DATASETS", str(tmp_path / "data"))
    config = TRAIN.resolve({"scene": "diffuse", "seed": 0, "iterations": 3, "log_every": 1, "sh": {"degree": 0},
                            "strategy": "none", "data": {"resolution": 32, "views": 8, "spp": 2}})
    prepared = TRAIN.prepare([config])
    assert prepared.datasets == tmp_path / "data"  # the user's setting, read in the runner
    assert (dataset_folder("diffuse", config["data"]) / "manifest.json").is_file()
    monkeypatch.delenv("SPLATBENCH_DATASETS")  # a worker finds the datasets by what prepare returned
    output = TRAIN.run(config, tmp_path / "work", prepared)
    metrics = metric_values(output)
    assert isinstance(output, TRAIN.result) and list(metrics) == list(TRAIN.specs)
    assert metrics["iterations"] == 3 and metrics["test_views"] == 1
    # the curves, and each test view's final PSNR (their mean: the test PSNR)
    assert set(output.curves) == {*CURVE_KEYS, "test_view_psnr"} and output.curves["step"] == [0, 1, 2]
    assert abs(np.mean(output.curves["test_view_psnr"]) - output.test_psnr) < 1e-6
    assert (tmp_path / "work" / "point_cloud.ply").is_file()


def test_a_train_result_becomes_the_kinds_record_field_by_field():
    """`TrainRun.of`: a `TrainResult`'s metrics by name, its load and strategy counts flattened,
    the LPIPS convention and the load mark as 0 / 1, the dataset's hash, its warnings (never its
    notes) and its curves; every value a scalar column (`metric_values`)."""
    from splatbench.experiments.kinds import check_output, metric_values
    from splatbench.experiments.train_kind import TrainRun
    from splatbench.strategies.base import TopologyCounts
    from splatbench.train.result import EvalPoint, HistoryPoint, TrainResult

    result = TrainResult(
        test_psnr=25.5, test_ssim=0.81, test_lpips=0.2, num_gaussians=1234, train_seconds=12.5, iterations=30,
        sh_degree=1, sh_degree_reason="fixed", ply_path="x.ply", render_ms_per_view=3.5, peak_rss_mb=900.0,
        test_views=4, history=[HistoryPoint(0, 0.5, 12.0, 1000), HistoryPoint(29, 0.1, 24.0, 1234)],
        evaluations=[EvalPoint(30, 25.5, 0.81, 0.2)], notes=["a note"], warnings=["warning: a warning"],
        lpips_net="alex", lpips_scale_inputs=False, cpu_seconds=20.0,
        load={"load_before": 0.5, "load_after": 1.5, "own_cpu": 1.0, "own_before": 0.2, "load_other": 1.5,
              "cores": 2, "loaded": True},
        topology=TopologyCounts(refinements=3, opacity_resets=1, cloned=10, split=5, pruned=2, pruned_size=1),
        init={"method": "surface", "points": 1000, "asked": "auto", "jitter": 0.5}, device="cpu",
        background=[0.4706, 1.0, 0.0], background_source="alpha", train_views=28, image_size=[89, 158],
        test_view_psnr=[26.0, 24.5, 25.5, 26.0])
    record = TrainRun.of(result, "abc")
    metrics = metric_values(record)
    assert list(metrics) == list(TRAIN.specs)
    assert metrics == {
        "test_psnr": 25.5, "test_ssim": 0.81, "num_gaussians": 1234, "train_seconds": 12.5,
        "render_ms_per_view": 3.5, "sh_degree": 1, "peak_rss_mb": 900.0, "iterations": 30, "test_views": 4,
        "dataset_hash": "abc", "test_lpips": 0.2, "lpips_net": "alex", "lpips_scale_inputs": 0, "cpu_seconds": 20.0,
        "load_before": 0.5, "load_after": 1.5, "load_other": 1.5, "cores": 2, "time_loaded": 1, "refinements": 3,
        "opacity_resets": 1, "cloned": 10, "split": 5, "pruned": 2, "pruned_size": 1, "relocated": 0, "added": 0,
        "init_method": "surface", "init_points": 1000,  # what init = auto resolved to, and its start
        "run_peak_rss_mb": None,  # the peak was not reset as the run started: no per-run peak
        "device": "cpu",  # where the rasterizer ran (what device = auto resolved to)
        "background": "0.4706, 1, 0", "background_source": "alpha",  # what background = auto resolved to, and why
        "train_views": 28, "image_width": 89, "image_height": 158,  # the views and the size it trained at
        "worst_view_psnr": 24.5,  # the lowest test view's PSNR (each view's in the curves)
        "resumed_step": None}  # run straight through (not continued from a killed attempt's checkpoint)
    # reset (the kind's run does it on Linux): the process's peak is the run's own
    assert metric_values(TrainRun.of(result, "abc", own_peak=True))["run_peak_rss_mb"] == 900.0
    assert record.warnings == ("warning: a warning",)
    assert record.curves["step"] == [0, 29] and record.curves["eval_psnr"] == [25.5]
    assert record.curves["test_view_psnr"] == [26.0, 24.5, 25.5, 26.0]
    assert check_output(record, TRAIN) == record
    # a result from before the strategy's counts were recorded: None in those columns
    older = metric_values(TrainRun.of(dataclasses.replace(result, topology=None, init={}, background=[],
                                                          background_source="", train_views=0, image_size=[],
                                                          test_view_psnr=[]),
                                     None))
    assert older["refinements"] is None and older["dataset_hash"] is None and older["init_method"] is None
    assert older["background"] is None and older["background_source"] is None
    assert older["train_views"] is None and older["image_width"] is None and older["image_height"] is None
    assert older["worst_view_psnr"] is None
    with pytest.raises(TypeError, match="returned dict, not TrainRun"):
        check_output({"test_psnr": 1.0}, TRAIN)


def test_raster_report_leaves_loaded_runs_out_of_findings(tmp_path):
    """A raster grid with made-up metrics: one run timed under load is kept in the table
    (its `loaded` column) but left out of every finding, and the defaults' self-ratio
    (the noise floor) is stated."""
    spec = parse_experiment({"name": "rfake", "kind": "raster", "scenes": ["synthetic-300-32"], "seeds": [0, 1, 2],
                             "grid": "one-at-a-time", "axes": {"alpha_min": [0.002], "tile_size": [8]}},
                            source="rfake.toml")
    runs = expand(spec)
    records = []
    for i, run in enumerate(runs):
        alpha = run.config["alpha_min"]
        rel = 1.0 + 0.01 * (run.seed - 1) if alpha > 0.003 and run.config["tile_size"] == 16 else 0.8 + 0.01 * run.seed
        loaded = int(run.labels.get("tile_size") == 8 and run.seed == 2)
        metrics = {"fwd_ms": 10.0, "fwd_bwd_ms": 30.0 * rel, "fwd_bwd_rel": rel, "fwd_bwd_rel_low": rel - 0.05,
                   "fwd_bwd_rel_high": rel + 0.05, "exact_psnr": 40.0 + (5.0 if alpha < 0.003 else 0.0) + run.seed,
                   "exact_max_abs": 0.01, "parity_max_abs": 1e-6, "pairs": 1000, "evaluations": 256000,
                   "loaded": loaded}
        records.append(RunRecord(run_id=run.run_id, experiment=spec.name, kind="raster", scene=run.scene,
                                 seed=run.seed, status="done", config=dict(run.config), labels=dict(run.labels),
                                 metrics=metrics, curves=None, error=None, seconds=1.0,
                                 started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:01+00:00",
                                 worker="h:1"))
        write_record(tmp_path, records[-1])
    write_table(tmp_path / spec.name, records)
    report = build_report(spec, tmp_path)
    text = write_report(report, tmp_path / "report").read_text()
    tile = report.findings["tile_size"].claims
    vs = [c for c in tile if c.kind == "vs" and c.label == "8"]
    assert vs and all(c.n == 2 for c in vs)             # seed 2 of tile 8 was loaded: 2 pairs left
    rel = next(c for c in vs if c.metric == "fwd_bwd_rel")
    assert rel.value == pytest.approx(0.805) and rel.significant          # 0.80, 0.81: below 1
    psnr = next(c for c in report.findings["alpha_min"].claims if c.kind == "vs" and c.metric == "exact_psnr")
    assert psnr.value == pytest.approx(5.0) and psnr.n == 3               # exact differences of 5 dB per seed
    base = next(c for c in tile if c.kind == "self")
    assert base.value == pytest.approx(1.0) and not base.significant      # 0.99, 1.00, 1.01 holds 1
    assert "1 run(s) timed while the load average exceeded half the cores are left out" in text
    row = next(line for line in text.splitlines() if line.startswith("| synthetic-300-32 | `8` |"))
    assert row.rstrip(" |").endswith("0.33")                              # the loaded column: 1 of 3 runs
    # every run loaded: no finding is drawn, and the report says why
    for rec in records:
        write_record(tmp_path, dataclasses.replace(rec, metrics={**rec.metrics, "loaded": 1}))
    loaded = build_report(spec, tmp_path)
    assert {"alpha_min", "tile_size"} <= set(loaded.findings)
    assert all(f.claims == [] and f"No findings: all {len(records)} done run(s)" in f.markdown()
               for name, f in loaded.findings.items() if name != "parity")


def test_product_grid_rows_average_each_seed_first(tmp_path):
    """In a product grid a row pools the other axis's values: the interval is over seeds
    (each seed's runs averaged first), not over runs, so n is the number of seeds."""
    from splatbench.experiments.runner import run_experiment
    from splatbench.metrics.stats import t_interval

    spec = parse_experiment({"name": "prod", "kind": "tests.kinds_for_tests:DUMMY", "scenes": ["alpha"], "seeds": [0, 1, 2],
                             "axes": {"x": [1.0, 2.0], "n": [3, 5]}}, source="prod.toml")
    run_experiment(spec, workers=1, results_dir=tmp_path, progress=False)
    report = build_report(spec, tmp_path)
    table = report.table
    x_table = next(t for t in report.axes if t.axis == "x")
    done = table[table["axis.x"] == 2.0]
    assert len(done) == 6                                   # 2 values of n x 3 seeds
    per_seed = done.groupby("seed")["metric.value"].mean()
    st = x_table.stat("alpha", "2", "value")
    iv = t_interval(list(per_seed))
    assert st.n == 3 and st.mean == pytest.approx(iv.estimate) and st.half_width == pytest.approx(iv.half_width)
    # the findings pair the same per-seed means; the generic kind compares its first metric,
    # a_plus_seed = a + seed, which x never changes: a difference of exactly 0 in every
    # pair, whose degenerate interval [0, 0] is no evidence: the seeds did not vary it
    vs = next(c for c in report.findings["x"].claims if c.kind == "vs")
    assert vs.metric == "a_plus_seed" and vs.n == 3
    assert (vs.value, vs.low, vs.high) == (0.0, 0.0, 0.0) and not vs.significant
    assert "(seeds did not vary the result: no interval)" in vs.text and "±" not in vs.text


def test_a_new_kind_declares_its_report_in_one_place():
    """A kind's metrics (its result's fields) and findings rules come from its own `KindReport`
    (passed to its `RunKind`), its extra findings and notes from the hooks it declares there:
    the reports are handed the kind, name none, and the kind imports no report code."""
    from dataclasses import dataclass

    from splatbench.experiments.kind_report import Comparison, FindingRules, KindReport
    from splatbench.experiments.kinds import RunKind, RunResult, metric
    from splatbench.reports.findings import rules_for
    from splatbench.reports.tables import metric_specs

    @dataclass(frozen=True)
    class ToyConfig:
        rate: float = 0.1

    @dataclass(frozen=True, kw_only=True)
    class Toy(RunResult):
        loss: float = metric("loss", ".3f", "", "lower", "what the toy minimises")
        other: float = metric(meaning="anything else")

    def note(axis_table, runs, scenes):
        return ["- a toy note"], []

    declared = KindReport(metrics=("loss",), rules=FindingRules("loss", (Comparison("loss", "diff"),)),
                          axis_notes=(note,))
    toy = RunKind(name="toy-report-kind", validate=lambda config: None, config=ToyConfig, result=Toy,
                  run=lambda config, workdir, prepared: Toy(loss=0.0, other=1.0), report=declared)
    loss = toy.specs["loss"]
    assert (loss.label, loss.fmt, loss.better, loss.meaning) == ("loss", ".3f", "lower", "what the toy minimises")
    table = pd.DataFrame({"metric.loss": [0.5], "metric.other": [1.0]})
    assert metric_specs(toy, table) == (loss,)      # its own metrics only
    assert rules_for(toy, (loss,)) == declared.rules
    bare = RunKind(name="toy-bare-kind", validate=lambda config: None, config=ToyConfig, result=Toy,
                   run=lambda config, workdir, prepared: Toy(loss=0.0, other=1.0))
    assert [m.name for m in metric_specs(bare, table)] == ["loss", "other"]  # undeclared: every one
    assert declared.axis_notes == (note,)
    with pytest.raises(TypeError, match="KindReport names metrics its kind's result does not have: lost"):
        RunKind(name="toy-wrong-kind", validate=lambda config: None, config=ToyConfig, result=Toy, run=toy.run,
                report=KindReport(metrics=("lost",)))


def test_a_cell_whose_runs_all_failed_reports_a_dash(tmp_path):
    # reports/initialization: every `far` run of init=sfm failed; the report must still be
    # written, with "–" for that cell and the runs under "Failed runs"
    spec = sh_spec()
    runs = expand(spec)
    dead = runs[0].labels["sh.degree"]
    records = []
    for run in runs:
        failed = run.labels["sh.degree"] == dead and run.scene == runs[0].scene
        metrics, curves = fake_metrics(run.scene, run.labels["sh.degree"], run.seed)
        rec = RunRecord(run_id=run.run_id, experiment=spec.name, kind="train", scene=run.scene, seed=run.seed,
                        status="failed" if failed else "done", config=dict(run.config), labels=dict(run.labels),
                        metrics={} if failed else metrics, curves=None if failed else curves,
                        error="RuntimeError: boom" if failed else None, seconds=1.0,
                        started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:01+00:00", worker="h:1")
        write_record(tmp_path, rec)
        records.append(rec)
    write_table(tmp_path / spec.name, records)
    text = write_report(build_report(spec, tmp_path), tmp_path / "out" / spec.name).read_text()
    row = next(line for line in text.splitlines() if line.startswith(f"| {runs[0].scene} | `{dead}` |"))
    assert "| 0 | – |" in row and "## Failed runs" in text


def test_report_rebuild_rewrites_a_committed_report_from_its_own_parquet(tmp_path):
    """`splatbench report --rebuild` needs no results folder: a committed report that covers its grid
    (raster_speed_vs_error: the training reports are stale until rerun under issue 29's
    initialisation) rebuilt from its parquet is the committed text; another grid's parquet is
    refused in one line."""
    import shutil
    from pathlib import Path

    from click.testing import CliRunner

    from splatbench.cli import main

    root = Path(__file__).resolve().parents[1]
    name = "raster_speed_vs_error"
    assert not (root / "reports" / name / "STALE.md").exists()
    shutil.copytree(root / "reports" / name, tmp_path / "r")
    (tmp_path / "r" / "report.md").write_text("old")
    res = CliRunner().invoke(main, ["report", str(root / "experiments" / f"{name}.toml"), "--rebuild",
                                    "--out", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output
    rebuilt = (tmp_path / "r" / "report.md").read_text()
    # the command line names the --out it was rebuilt with (the user's options are kept); the rest is the text
    assert f"Generated by `splatbench report experiments/{name}.toml --out {tmp_path / 'r'}`" in rebuilt

    def unnamed(text: str) -> str:
        return re.sub(r"Generated by `splatbench report [^`]*`", "Generated by", text)

    assert unnamed(rebuilt) == unnamed((root / "reports" / name / "report.md").read_text())
    res = CliRunner().invoke(main, ["report", str(root / "experiments" / "loss_weighting.toml"), "--rebuild",
                                    "--out", str(tmp_path / "r")])
    assert res.exit_code == 2 and "does not hold the runs the grid makes now" in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_raster_kind_run_ids_ignore_pixel_block_at_the_value_earlier_runs_had():
    """pixel_block came after runs were recorded with 4 x 4 blocks: at 4 it is left out of
    the run id (those runs keep their ids), any other value makes a run of its own."""
    from splatbench.experiments.grid import make_run_id
    from splatbench.experiments.raster_kind import identity, resolve

    before = {k: v for k, v in resolve({"scene": "garden"}).items() if k != "pixel_block"}
    assert make_run_id("raster", identity(resolve({"scene": "garden"}))) == make_run_id("raster", before)
    two = identity(resolve({"scene": "garden", "pixel_block": 2}))
    assert two["pixel_block"] == 2 and make_run_id("raster", two) != make_run_id("raster", before)
