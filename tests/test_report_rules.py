"""The rules that decide how a report labels a difference (issue 29, items 4-6): the minimum
effect ("no practical difference"), "best" only with a significant and practical lead, no
interval printed from seeds that varied nothing, loaded times out of the Pareto fronts,
settled curves, the confounds a setting brings along, and the protocol in the header.

Each test builds a results folder by hand (the real grid of a small train experiment, with
made-up metrics and curves), as tests/test_reports.py does, so they run in seconds.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from splatbench.errors import InputError
from splatbench.experiments import RunRecord, expand, parse_experiment
from splatbench.experiments.store import write_record, write_table
from splatbench.metrics.spec import clip
from splatbench.metrics.stats import Interval, holm, paired_difference, paired_ratio, t_interval, t_p_value
from splatbench.reports import build_report, write_report
from splatbench.reports.findings import fmt_interval, judge, reading
from splatbench.reports.settling import cell_settling, last_quarter_slope, settling_finding
from splatbench.experiments.train_kind import REPORT as TRAIN_REPORT
from splatbench.experiments.train_kind import LPIPS_MIN_EFFECT, MIN_EFFECT, TRAIN
from splatbench.experiments.train_report import floats_per_gaussian
from splatbench.metrics.spec import MetricSpec

PSNR = MetricSpec("test_psnr", "test PSNR (dB)", ".2f", "dB", "higher")


def spec_of(extra: dict | None = None):
    return parse_experiment({"name": "rules", "kind": "train", "scenes": ["glossy"], "seeds": [0, 1, 2],
                             "base": {"iterations": 2000, "data": {"resolution": 32, "views": 8, "spp": 2}},
                             "axes": {"sh.degree": [0, 3]}, **(extra or {})}, source="rules.toml")


def metrics_of(psnr: float, seconds: float = 10.0, loaded: int = 0, **more) -> dict:
    return {"test_psnr": psnr, "test_ssim": 0.8, "num_gaussians": 1000, "train_seconds": seconds,
            "render_ms_per_view": 5.0, "sh_degree": 0, "peak_rss_mb": 500.0, "iterations": 2000, "test_views": 1,
            "dataset_hash": "0" * 16, "test_lpips": 0.2, "lpips_net": "alex", "lpips_scale_inputs": 1,
            "cpu_seconds": 15.0, "load_before": 0.5, "load_after": 1.5, "load_other": 0.2, "cores": 2,
            "time_loaded": loaded, **more}


def flat_curves(final: float, rise: float = 0.0, train_rise: float = 0.0) -> dict:
    """Test evaluations at 500..2000 ending at ``final``, rising by ``rise`` over the last 500
    steps (the last quarter); the training-view PSNR rising by ``train_rise`` over it."""
    steps = list(range(0, 2000, 100)) + [1999]
    return {"eval_step": [500, 1000, 1500, 2000], "eval_psnr": [final - 2.0, final - 1.0, final - rise, final],
            "step": steps, "psnr": [final + 1.0 + train_rise * max(0.0, (s - 1500) / 500.0) for s in steps],
            "loss": [0.1] * len(steps), "num_gaussians": [1000] * len(steps)}


def results(tmp_path, spec, make, keep=lambda run: True) -> tuple:
    """Write a results folder of the runs ``keep`` selects (the rest not run); ``make(run) -> (metrics,
    curves)``; the report built from it."""
    records = []
    for run in expand(spec):
        if not keep(run):
            continue
        metrics, curves = make(run)
        rec = RunRecord(run_id=run.run_id, experiment=spec.name, kind="train", scene=run.scene, seed=run.seed,
                        status="done", config=dict(run.config), labels=dict(run.labels), metrics=metrics,
                        curves=curves, error=None, seconds=1.0, started="2026-01-01T00:00:00+00:00",
                        finished="2026-01-01T00:00:01+00:00", worker="h:1")
        write_record(tmp_path / "res", rec)
        records.append(rec)
    write_table(tmp_path / "res" / spec.name, records)
    report = build_report(spec, tmp_path / "res")
    text = write_report(report, tmp_path / "out").read_text()
    return report, text


# --------------------------------------------------------------------------- minimum effect
def test_a_small_significant_difference_is_no_practical_difference():
    # +0.05 dB known to +-0.01: significant, below the 0.1 dB minimum effect
    tight = Interval(0.05, 0.04, 0.06, 3, "paired t")
    assert judge(tight, "diff", 0.0, PSNR, 0.1) == (True, False)
    text = fmt_interval(tight, "diff", PSNR, 0.0, 0.1)
    assert text.endswith("no practical difference (interval within ±0.1 dB)")
    # the same interval with a 0.01 dB minimum effect, and a 0.5 dB difference, are both practical
    assert judge(tight, "diff", 0.0, PSNR, 0.01) == (True, True)
    assert judge(Interval(0.5, 0.4, 0.6, 3, "paired t"), "diff", 0.0, PSNR, 0.1) == (True, True)
    # judged as printed: +0.0951 is written +0.10, never "below the 0.1 dB minimum effect"
    assert judge(Interval(0.0951, 0.06, 0.13, 3, "paired t"), "diff", 0.0, PSNR, 0.1) == (True, True)
    # ratios: ×1.03 is below 5 %, ×0.90 (1 / 0.90 = ×1.11) is not
    gaussians = MetricSpec("num_gaussians", "Gaussians", ".0f")
    assert judge(Interval(1.03, 1.02, 1.04, 3, "t"), "ratio", 1.0, gaussians, 0.05) == (True, False)
    assert judge(Interval(0.90, 0.89, 0.91, 3, "t"), "ratio", 1.0, gaussians, 0.05) == (True, True)


@pytest.mark.parametrize("iv, how, effect, said, written", [
    # significant, below the minimum effect, the whole interval within it: the only "no practical difference"
    (Interval(0.05, 0.04, 0.06, 3, "t"), "diff", 0.1, "no practical difference", ", no practical difference (interval within ±0.1 dB)"),
    # not significant and within: an effect ruled out all the same
    (Interval(0.01, -0.05, 0.07, 3, "t"), "diff", 0.1, "no practical difference", ", no practical difference (interval within ±0.1 dB)"),
    # significant, below it, but the interval reaches beyond it: nothing is ruled out
    (Interval(0.05, 0.01, 0.15, 3, "t"), "diff", 0.1, "inconclusive",
     ", inconclusive (below the 0.1 dB minimum effect, but its interval reaches beyond it)"),
    # a bound printed -0.10 reaches the minimum effect (judged as written)
    (Interval(-0.02, -0.0951, 0.05, 3, "t"), "diff", 0.1, "inconclusive",
     ", no significant difference, inconclusive (its interval reaches beyond the 0.1 dB minimum effect)"),
    # quick_protocol's Gaussians x1.048 [x1.042, x1.054] under 5 %: read "no practical difference" before
    (Interval(1.048, 1.042, 1.054, 3, "t"), "ratio", 0.05, "inconclusive",
     ", inconclusive (below the 5 % minimum effect, but its interval reaches beyond it)"),
    # x0.955 is 1 / 0.955 = x1.047 either side: within 5 %
    (Interval(0.99, 0.955, 1.03, 3, "t"), "ratio", 0.05, "no practical difference", ", no practical difference (interval within ±5 %)"),
    (Interval(0.5, 0.4, 0.6, 3, "t"), "diff", 0.1, "difference", "]"),
    (Interval(0.05, -0.3, 0.4, 3, "t"), "diff", None, "no significant difference", ", no significant difference"),
])
def test_only_an_interval_within_the_minimum_effect_rules_an_effect_out(iv, how, effect, said, written):
    spec = PSNR if how == "diff" else MetricSpec("num_gaussians", "Gaussians", ".0f")
    null = 1.0 if how == "ratio" else 0.0
    assert reading(iv, how, null, spec, effect) == said
    text = fmt_interval(iv, how, spec, null, effect)
    assert text.endswith(written), text
    assert ("no practical difference" in text) is (said == "no practical difference")
    assert judge(iv, how, null, spec, effect)[1] is (said == "difference")


def test_an_interval_is_cut_at_the_metrics_range_in_the_table_and_the_findings(tmp_path):
    """An SSIM near 1 over three seeds: mean ± half-width reaches past 1; the cell prints the interval cut
    there (`splatbench.metrics.spec.clip`), and an LPIPS "mean" interval is cut at 0 the same way."""
    ssim = {0: 0.999, 1: 0.990, 2: 0.9995}

    def make(run):
        psnr = 30.0 + 0.1 * run.seed
        return metrics_of(psnr, test_ssim=ssim[run.seed]), flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    iv = t_interval(list(ssim.values()))
    assert iv.high > 1.0  # the t interval crosses the bound: what the report must not print
    cell = f"{iv.estimate:.4f} [{iv.low:.4f}, 1.0000]"
    rows = [line for line in text.splitlines() if line.startswith("| glossy | `")]
    assert len(rows) == 2 and all(f"| {cell} |" in row for row in rows), rows
    assert "cut at the bound" in text  # the conventions line says so
    lpips = TRAIN.specs["test_lpips"]
    assert fmt_interval(Interval(0.02, -0.01, 0.05, 3, "t"), "mean", lpips, None) == "0.0200 [95 % CI 0.0000, 0.0500]"
    # a difference of a bounded metric is cut at what a difference can be (SSIM: ±2), a ratio at 0
    assert clip(-2.5, 0.1, "diff", TRAIN.specs["test_ssim"]) == (-2.0, 0.1)
    assert clip(-0.1, 1.2, "ratio", TRAIN.specs["num_gaussians"]) == (0.0, 1.2)
    assert clip(-5.0, 5.0, "diff", PSNR) == (-5.0, 5.0)  # unbounded: as given


def _lead(delta: float):
    """SH 3 ahead of SH 0 by ``delta`` dB on every seed, plus a little seeded noise."""
    def make(run):
        rng = np.random.default_rng(run.seed)
        psnr = 30.0 + rng.normal(0, 0.5) + (delta + rng.normal(0, 0.004) if run.labels["sh.degree"] == 3 else 0.0)
        return metrics_of(psnr), flat_curves(psnr)
    return make


def test_best_needs_a_significant_and_practical_lead(tmp_path):
    report, text = results(tmp_path, spec_of(), _lead(0.05))
    claims = report.findings["sh.degree"].claims
    assert not [c for c in claims if c.kind == "best"]
    lead = next(c for c in claims if c.kind == "no best")
    assert lead.significant and not lead.practical and lead.label == "3"
    assert "glossy: no single best (`3`" in text and "no practical difference" in text
    vs = next(c for c in claims if c.kind == "vs" and c.metric == "test_psnr")
    assert vs.significant and not vs.practical and "no practical difference (interval within ±0.1 dB)" in vs.text

    # the experiment file's own minimum effect: 0.01 dB makes the same lead a best
    report, text = results(tmp_path / "b", spec_of({"report": {"min_effect": {"test_psnr": 0.01}}}), _lead(0.05))
    best = [c for c in report.findings["sh.degree"].claims if c.kind == "best"]
    assert [(c.scene, c.label, c.reference) for c in best] == [("glossy", "3", "0")]
    vs = next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_psnr")
    assert "lies wholly beyond the 0.01 dB minimum effect" in text and vs.practical
    assert "no practical difference" not in vs.text

    # a 0.5 dB lead is named best under the default minimum effect
    report, _ = results(tmp_path / "c", spec_of(), _lead(0.5))
    assert [c.label for c in report.findings["sh.degree"].claims if c.kind == "best"] == ["3"]


def _lpips_lead(delta: float, net: str, scaled: bool):
    """SH 3 below SH 0 in LPIPS by ``delta`` on every seed (to within 5e-5), recorded as LPIPS ``net`` with
    ``scaled`` inputs; PSNR seeded noise only."""
    def make(run):
        rng = np.random.default_rng(run.seed)
        psnr, lp = 30.0 + rng.normal(0, 0.5), 0.2 + rng.normal(0, 0.01)
        lp -= delta + rng.normal(0, 5e-5) if run.labels["sh.degree"] == 3 else 0.0
        return (metrics_of(psnr, test_lpips=lp, lpips_net=net, lpips_scale_inputs=int(scaled)), flat_curves(psnr))
    return make


def test_lpips_is_judged_on_the_scale_of_the_net_its_runs_used(tmp_path):
    """LPIPS's minimum effect is the runs' convention's (`LPIPS_MIN_EFFECT`, docs/reports.md "Minimum effects":
    AlexNet scaled 0.004, VGG unscaled 0.005; tools/lpips_scale.py measured the scale): one difference between
    the two is practical in AlexNet runs and no practical difference in VGG runs; a convention without a
    measured scale is judged by its interval alone; an experiment file's own minimum effect wins."""
    alex, vgg = LPIPS_MIN_EFFECT[("alex", True)], LPIPS_MIN_EFFECT[("vgg", False)]
    delta = (alex + vgg) / 2  # between the two; the paired interval (3 seeds, SD 7e-5) is +-3e-4 around it

    def lpips_vs(report):
        return next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_lpips")

    assert MIN_EFFECT["test_lpips"] == alex  # the default convention's
    report, _ = results(tmp_path / "alex", spec_of(), _lpips_lead(delta, "alex", True))
    vs = lpips_vs(report)
    assert vs.significant and vs.practical and "no practical difference" not in vs.text, vs.text
    report, text = results(tmp_path / "vgg", spec_of(), _lpips_lead(delta, "vgg", False))
    vs = lpips_vs(report)
    assert vs.significant and not vs.practical
    assert vs.text.endswith(f"no practical difference (interval within ±{vgg:g})"), vs.text
    assert "VGG-16 backbone" in text  # the Metrics section names the convention the threshold is on
    # AlexNet fed [0, 1] unscaled: no measured scale, no minimum effect: significant is a difference
    report, _ = results(tmp_path / "unscaled", spec_of(), _lpips_lead(delta / 10, "alex", False))
    vs = lpips_vs(report)
    assert vs.significant and vs.practical and "minimum effect" not in vs.text, vs.text
    # the experiment file's own minimum effect over the runs' net's
    report, _ = results(tmp_path / "own", spec_of({"report": {"min_effect": {"test_lpips": 0.01}}}),
                        _lpips_lead(delta, "vgg", False))
    assert lpips_vs(report).text.endswith("no practical difference (interval within ±0.01)")


def test_a_minimum_effect_for_a_metric_the_findings_do_not_compare_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"report\.min_effect\.test_views: not a metric"):
        results(tmp_path, spec_of({"report": {"min_effect": {"test_views": 1}}}), _lead(0.5))
    with pytest.raises(InputError, match=r"report\.min_effect\.test_psnr: expected a number >= 0"):
        spec_of({"report": {"min_effect": {"test_psnr": -1}}})
    with pytest.raises(InputError, match=r"report\.minimum"):
        spec_of({"report": {"minimum": 1}})


# --------------------------------------------------------------------------- no spread
def test_the_comparison_count_counts_only_comparisons_with_an_interval(tmp_path):
    """Review of sh_degree, item 19: "This table makes 49 comparisons, each with its own 95 % interval"
    counted the one-seed and no-spread ones too. Here SSIM, LPIPS, train time and the Gaussians are
    one number on every seed (`metrics_of`): their four comparisons print "no interval"; the test PSNR
    comparison and the leader's lead over the runner-up have one: 2 counted, 4 named as without."""
    def make(run):
        rng = np.random.default_rng(run.seed)
        psnr = 30.0 + rng.normal(0, 0.5) + (0.5 + rng.normal(0, 0.05) if run.labels["sh.degree"] == 3 else 0.0)
        return metrics_of(psnr), flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    count = next(c for c in report.findings["sh.degree"].claims if c.kind == "count")
    assert count.value == 2
    assert ("This table makes 2 comparisons with a 95 % interval (Student's t over seeds; no correction for "
            "multiple comparisons, so about 1 in 20 intervals misses by chance); 4 more have none") in text


def test_seeds_that_vary_nothing_print_no_interval(tmp_path):
    """Every seed gives the same PSNR (what init = surface did to biker): the table says
    "(no spread)", a 0.02 dB difference is not called significant, and no ±0.00 is printed."""
    def make(run):
        psnr = 41.2613 + (0.02 if run.labels["sh.degree"] == 3 else 0.0)
        return metrics_of(psnr), flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    assert "± 0.00 " not in text and "±0.00" not in text and "± 0.00|" not in text.replace(" |", "|")
    assert "41.26 (no spread)" in text and "41.28 (no spread)" in text
    vs = next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_psnr")
    assert vs.text == "+0.02 dB (seeds did not vary the result: no interval)" and not vs.significant
    assert not [c for c in report.findings["sh.degree"].claims if c.kind == "best"]


def test_seeds_that_vary_less_than_the_precision_shown_say_so(tmp_path):
    """The seeds vary the difference, but by less than the 0.01 dB the report writes (SH 3
    leads by 0.020, 0.021 and 0.022 dB): still no interval and no significance, but the text
    must not claim the seeds did not vary it (sh_degree_spp128 had said so of a ±0.004 dB
    interval); it gives the half-width instead."""
    def make(run):
        psnr = 41.2613 + (0.02 + 0.001 * run.seed if run.labels["sh.degree"] == 3 else 0.0)
        return metrics_of(psnr), flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    vs = next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_psnr")
    assert "did not vary" not in vs.text and not vs.significant
    # 3 seeds: mean 0.021, s = 0.001, t(0.975, 2) = 4.303: half-width 0.0025
    assert vs.text == "+0.02 dB (seeds varied it by less than the precision shown, ±0.002 dB: no interval)"


# --------------------------------------------------------------------------- loaded times
def test_a_loaded_runs_time_never_enters_the_pareto_front(tmp_path):
    """SH 0 is fastest, but every one of its runs was timed under load: the time front is SH 3
    alone, and the report names what it left out; the Gaussians front keeps SH 0."""
    def make(run):
        zero = run.labels["sh.degree"] == 0
        psnr = 30.0 + (0.0 if zero else 1.0) + 0.01 * run.seed
        return metrics_of(psnr, seconds=5.0 if zero else 20.0, loaded=int(zero)), flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    assert report.fronts["time_vs_error"] == {"glossy": ["sh.degree=3"]}
    assert "Left out of this figure and its front: 3 run(s) timed while other processes loaded the machine " \
           "(glossy `sh.degree=0`)" in text
    assert report.fronts["gaussians_vs_error"]["glossy"][0] == "sh.degree=3"  # 1000 each: the better one
    time_vs = [c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "train_seconds"]
    assert time_vs == []  # no pair of trusted times: no time comparison at all


# --------------------------------------------------------------------------- settling
def test_last_quarter_slope_is_per_thousand_steps():
    s = last_quarter_slope([500, 1000, 1500, 2000], [20.0, 21.0, 21.5, 21.7])
    assert (s.start, s.end) == (1500, 2000) and s.slope == pytest.approx(0.4)  # 0.2 dB over 500 steps
    # one point in the last quarter: the last two are used
    s = last_quarter_slope([1000, 2000], [20.0, 20.3])
    assert (s.start, s.end) == (1000, 2000) and s.slope == pytest.approx(0.3)
    assert last_quarter_slope([2000], [20.0]) is None


def _settle_table(rises: dict[str, float], train_rises: dict[str, float] | None = None) -> pd.DataFrame:
    import json

    rows = []
    for cell, rise in rises.items():
        for seed in range(3):
            curves = flat_curves(30.0 + seed * 0.1, rise + 0.005 * seed, (train_rises or {}).get(cell, rise))
            rows.append({"run_id": f"{cell}{seed}", "status": "done", "scene": "s", "seed": seed, "axis.x": cell,
                         "curves": json.dumps(curves)})
    return pd.DataFrame(rows)


def test_a_rising_last_quarter_is_not_settled_and_a_flat_one_is():
    # 0.10 dB over the last 500 steps is 0.2 dB / 1,000 steps: above the 0.1 threshold
    f = settling_finding(_settle_table({"a": 0.01, "b": 0.10}), TRAIN)
    by = {c.label: c for c in f.claims}
    assert by["x=a"].settled and not by["x=b"].settled
    assert "**Not settled**: 1 of 2 cells" in f.markdown() and "s `x=b` (+0.21)" in f.markdown()
    f = settling_finding(_settle_table({"a": 0.01, "b": -0.01}), TRAIN)
    assert all(c.settled for c in f.claims) and "Settled: every cell" in f.markdown()
    # a falling curve is not settled either
    assert not settling_finding(_settle_table({"a": -0.2}), TRAIN).claims[0].settled
    # the experiment file's minimum effect moves the threshold: 0.5 dB / 1,000 steps settles b
    loose = settling_finding(_settle_table({"a": 0.01, "b": 0.10}), TRAIN, {"test_psnr": 0.5})
    assert all(c.settled for c in loose.claims)


def test_a_cell_evaluated_once_is_said_to_be_unknown_not_left_out():
    # a new user's 200-step grid evaluated the test views only at its end: before, the report
    # said nothing about settling at all
    import json

    table = _settle_table({"a": 0.01})
    one_point = {"eval_step": [2000], "eval_psnr": [30.0]}
    extra = pd.DataFrame([{"run_id": f"b{seed}", "status": "done", "scene": "s", "seed": seed, "axis.x": "b",
                           "curves": json.dumps(one_point)} for seed in range(3)])
    f = settling_finding(pd.concat([table, extra], ignore_index=True), TRAIN)
    assert "**Cannot tell whether s `x=b` settled**" in f.markdown() and len(f.claims) == 1
    assert "Settled: every cell with a slope's test curve" in f.markdown()  # not "every cell": b has none
    only = settling_finding(extra, TRAIN)
    assert "**Cannot tell whether any cell settled**" in only.markdown() and not only.claims


def test_the_train_test_gap_is_over_the_slopes_window():
    # _settle_table: the training view flat 1 dB above the end (train rise 0), the test points 1,500 / 2,000
    # at end − r / end with r = 0.005 s: the test mean is end − r / 2, so the gap is 1 + r / 2, 1.0025 on
    # average over seeds 0..2
    f = settling_finding(_settle_table({"a": 0.0}), TRAIN)
    cell = cell_settling(_settle_table({"a": 0.0}), TRAIN_REPORT.settling, 0.1)
    assert cell.gap == pytest.approx(1.0025, abs=1e-9)
    assert "- Train–test gap over the same window" in f.markdown() and "s `x=a` +1.00 dB." in f.markdown()
    # what it averages, said in the line: the training-view points logged at 1,500..1,900 and 1,999 (one
    # sampled training view each) and the test evaluations at 1,500 and 2,000
    assert cell.gap_counts == ((6, 2),)
    assert ("the mean of 6 logged training-view PSNRs minus the mean of 2 test evaluations there" in f.markdown()
            and "**Each training-view PSNR is one sampled training view**" in f.markdown())
    # a table without a training curve has no gap, and no line
    table = _settle_table({"a": 0.0})
    table["curves"] = [json.dumps({k: v for k, v in json.loads(c).items() if k != "psnr"}) for c in table.curves]
    assert cell_settling(table, TRAIN_REPORT.settling, 0.1).gap is None
    assert "Train–test gap" not in settling_finding(table, TRAIN).markdown()


def test_a_flat_test_curve_beside_a_rising_train_curve_is_overfitting():
    f = settling_finding(_settle_table({"default": 0.0, "mcmc": 0.0}, {"default": 1.0, "mcmc": 0.0}), TRAIN)
    assert "**Overfitting**" in f.markdown() and "`x=default`" in f.markdown().split("**Overfitting**")[1]
    assert "`x=mcmc`" not in f.markdown().split("**Overfitting**")[1]


def test_past_its_peak_is_judged_on_the_fall_as_written():
    """Review of sh_degree, item 4: fox `0` fell 0.1049 dB from its peak, printed "0.10 dB above its
    last value" and called past its peak against the 0.1 dB minimum effect; the documented rule judges
    at the precision written (a printed 0.10 is not more than 0.1). 0.106 prints 0.11: past its peak."""
    from splatbench.reports.settling import CellSettling

    def cell(fall: float) -> CellSettling:
        return CellSettling(0.0, None, 5600, 7000, {0: 0.0}, 0.1, best=32.0 + fall, best_step=5600, last=32.0)

    assert not cell(0.1049).past_peak and cell(0.1049).settled and cell(0.1049).why_not() == ""
    assert cell(0.106).past_peak and "0.11 dB above its last value" in cell(0.106).why_not()


def _reset_results(tmp_path):
    """A flat test curve and a training-view curve flat 1 dB above it but for an opacity reset at
    iteration 1,600 (schedule absolute, refining until 1,700: its one reset): the point logged at 1,600 is 26 dB low,
    the one at 1,700 5 dB low (sh_degree's fox at its reset: 28-31 and 4-6 dB), both inside the last
    quarter (1,500-2,000)."""
    spec = spec_of({"base": {"iterations": 2000, "schedule": "absolute",
                             "data": {"resolution": 32, "views": 8, "spp": 2},
                             "strategy": {"reset_every": 1600, "refine_stop": 1700}}})

    def make(run):
        curves = flat_curves(30.0 + 0.01 * run.seed)
        dips = {1600: 26.0, 1700: 5.0}
        curves["psnr"] = [v - dips.get(s, 0.0) for s, v in zip(curves["step"], curves["psnr"])]
        return metrics_of(30.0 + 0.01 * run.seed, sh_degree=0), curves

    return results(tmp_path, spec, make)


def test_training_view_points_just_after_an_opacity_reset_are_left_out_of_overfitting_and_the_gap(tmp_path):
    """Review of sh_degree, item 3: the dip at the reset made the training slope over the last quarter
    rise (from 4 dB below at its start to flat), "overfitting" beside a flat test curve, and pulled the
    gap below zero ((4 · 1 − 25 − 4) / 6 = −4.17 dB). Without the points logged ≤ 100 steps after the
    reset the training curve is flat 1 dB above the test curve: no overfitting, a gap of +1.00 dB; the
    text names the window used and the reset in it."""
    from splatbench.experiments.configs import run_config
    from splatbench.experiments.train_config import opacity_reset_steps

    report, text = _reset_results(tmp_path)
    runs = report.table
    assert opacity_reset_steps(run_config(runs.iloc[0])) == (1600,)
    settling = report.findings["settling"].markdown()
    assert "**Overfitting**" not in settling
    assert "glossy `sh.degree=0` +1.00 dB" in settling and "glossy `sh.degree=3` +1.00 dB" in settling
    assert "steps 1,500–2,000: its test evaluations from step 1,500 on" in settling
    assert ("**An opacity reset in the window** (step 1,600)" in settling
            and "logged 100 steps or fewer after it (steps 1,600, 1,700) are left out" in settling)


def test_an_unsettled_difference_is_marked_in_the_axis_finding(tmp_path):
    def make(run):
        three = run.labels["sh.degree"] == 3
        psnr = 30.0 + (1.0 + 0.02 * run.seed ** 2 if three else 0.0) + 0.01 * run.seed
        return metrics_of(psnr), flat_curves(psnr, rise=0.5 if three else 0.0)

    report, text = results(tmp_path, spec_of(), make)
    vs = next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_psnr")
    assert vs.significant and vs.practical and vs.settled is False
    assert "**Not settled** (glossy: `3` +1.00 dB / 1,000 steps over the last quarter)" in text
    # the paired difference at every evaluation: d = 1 + 0.02 s² (mean 1.033) at 500, 1,000 and 2,000; at
    # 1,500 the sh 3 curve sits `rise` = 0.5 dB below its end while sh 0's is flat: 0.533
    assert ("Paired difference at each evaluation (mean over seeds; glossy, steps 500 / 1,000 / 1,500 / 2,000: "
            "+1.03, +1.03, +0.53, +1.03 dB)") in text
    best = next(c for c in report.findings["sh.degree"].claims if c.kind == "best")
    assert best.settled is False and "**not settled**" in best.text

    report, _ = results(tmp_path / "b", spec_of(), lambda run: (metrics_of(30.0 + run.seed * 0.01 + (
        1.0 + 0.02 * run.seed ** 2 if run.labels["sh.degree"] == 3 else 0.0)), flat_curves(30.0)))
    vs = next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_psnr")
    assert vs.settled is True


def test_a_cell_drifting_apart_late_is_not_settled():
    """Both cells flat by the threshold, but the difference moved by more than a quarter of
    its size over the last quarter."""
    from splatbench.reports.settling import difference_settled

    keys = TRAIN_REPORT.settling
    a = cell_settling(_settle_table({"a": 0.0}), keys, 0.1)
    b = cell_settling(_settle_table({"b": 0.03}), keys, 0.1)
    assert a.test == pytest.approx(0.01) and b.test == pytest.approx(0.07) and a.settled and b.settled
    # the difference moved (0.07 - 0.01) dB / 1,000 steps x 500 steps = 0.03 dB over the last quarter
    assert not difference_settled(a, b, 0.1)    # more than a quarter of 0.1 dB
    assert difference_settled(a, b, 1.0)        # less than a quarter of 1 dB


# --------------------------------------------------------------------------- confounds
def test_a_finding_names_what_else_a_setting_changed(tmp_path):
    def make(run):
        three = run.labels["sh.degree"] == 3
        psnr = 30.0 + (1.0 if three else 0.0) + 0.01 * run.seed
        counts = {"refinements": 10, "opacity_resets": 7 if three else 4, "cloned": 500, "split": 300,
                  "pruned": 100, "pruned_size": 0, "relocated": 0, "added": 0}
        return metrics_of(psnr, **counts), flat_curves(psnr)

    _, text = results(tmp_path, spec_of(), make)
    assert "Also changed: glossy: opacity resets 7 instead of 4 (mean over seeds)" in text
    # Gaussian counts below the floor (20 per run) on both sides are left out, however far apart; events are not
    def few(run):
        three = run.labels["sh.degree"] == 3
        counts = {"refinements": 10, "opacity_resets": 4, "cloned": 500, "split": 300, "pruned": 100,
                  "pruned_size": 3 if three else 15, "relocated": 0, "added": 0}
        return metrics_of(30.0 + (1.0 if three else 0.0) + 0.01 * run.seed, **counts), flat_curves(30.0)

    _, few_text = results(tmp_path / "few", spec_of(), few)
    assert "Also changed" not in few_text
    _, more = results(tmp_path / "more", spec_of(), lambda run: (lambda m, c: (
        {**m, "pruned_size": 25 if run.labels["sh.degree"] == 3 else 15}, c))(*few(run)))
    assert "Also changed: glossy: pruned for size 25 instead of 15 (mean over seeds)" in more
    # the header's schedule as run: the recorded counts per cell, as they differ
    assert ("- **Schedule as run** (each run's recorded counts, in its 2,000 steps): `sh.degree=0` 10 refinements, "
            "4 opacity resets; `sh.degree=3` 10 refinements, 7 opacity resets") in text
    assert "was not recorded by these runs" not in text

    # a table from before the counts were recorded still reports, and says so
    _, text = results(tmp_path / "old", spec_of(), lambda run: (metrics_of(30.0 + run.seed * 0.1), flat_curves(30.0)))
    assert "Also changed" not in text and "was not recorded by these runs" in text

    # ... and names what the configs schedule: graphdeco's resets every 3,000 of 30,000 steps, scaled to
    # 2,000 (every 200), fire only inside the refine window: 2 below 500 (25 %), 7 below 1,500 (75 %)
    stops = parse_experiment({"name": "stops", "kind": "train", "scenes": ["glossy"], "seeds": [0, 1, 2],
                              "base": {"iterations": 2000, "data": {"resolution": 32, "views": 8, "spp": 2}},
                              "axes": {"strategy.refine_stop": ["25%", "75%"]}}, source="stops.toml")
    _, text = results(tmp_path / "stops", stops, lambda run: (metrics_of(30.0 + run.seed * 0.1 + (
        0.5 if run.labels["strategy.refine_stop"] == "75%" else 0.0)), flat_curves(30.0)))
    assert "Also changed: glossy: opacity resets 7 instead of 2 (planned), refinements 14 instead of 4 (planned)" in text
    assert "Opacity resets fire only inside the refine window" in text


def test_the_model_size_counts_the_sh_bands_each_gaussian_carries(tmp_path):
    # 1,000 Gaussians at SH degree 0 hold 14 floats each (3 + 3 + 4 + 1 + 3), at degree 3 59 (3 + 3 + 4 + 1 + 48):
    # 14,000 against 59,000 parameters, a ratio of 59 / 14 = 4.214 at the same Gaussian count
    def make(run):
        d = run.labels["sh.degree"]
        return metrics_of(30.0 + 0.01 * run.seed + (0.5 if d == 3 else 0.0), sh_degree=d), flat_curves(30.0)

    report, text = results(tmp_path, spec_of(), make)
    assert ("glossy: `0` 0.01 M parameters, 0.1 MB; `3` 0.06 M parameters, 0.2 MB (×4.214 `0`'s)") in text
    claim = next(c for c in report.findings["sh.degree"].claims if c.kind == "model size")
    assert claim.value == pytest.approx(59 / 14) and claim.reference == "0"
    # ... while the Gaussian count alone reads ×1.000
    assert "Gaussians ×1.000" in text
    # runs that recorded only their worker's lifetime peak RSS show no memory column, and say why
    assert "| peak RSS (MB) |" not in text and "- No peak-memory column: these runs recorded their worker" in text
    # a run's own peak (reset as it starts) is a column: it does not depend on the load that voids the times
    _, text = results(tmp_path / "own", spec_of(), lambda run: (lambda m, c: ({**m, "run_peak_rss_mb": 500.0}, c))(
        *make(run)))
    assert "| Gaussians | peak RSS (MB) | train time (s) |" in text and "| 1000 (no spread) | 500 (no spread) |" in text
    assert "No peak-memory column" not in text


def test_ssim_is_compared_and_named_as_the_trained_quantity(tmp_path):
    # SH 3's SSIM 0.01 + 0.001 s above SH 0's: a paired difference of +0.0110 over seeds 0..2
    def make(run):
        three = run.labels["sh.degree"] == 3
        m = metrics_of(30.0 + 0.01 * run.seed + (0.5 if three else 0.0))
        m["test_ssim"] = 0.8 + ((0.01 + 0.001 * run.seed) if three else 0.0)
        return m, flat_curves(30.0)

    report, text = results(tmp_path, spec_of(), make)
    vs = next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_ssim")
    assert vs.value == pytest.approx(0.011) and vs.significant and vs.practical  # above the 0.003 minimum effect
    # the other metrics' comparisons are in the axis's appendix section, SSIM the first of them
    appendix = text[text.index("## Appendix: sh.degree in full"):]
    assert "  - `3`: SSIM +0.0110 [95 % CI" in appendix and "SSIM 0.003" in appendix
    # the default loss weights D-SSIM by 0.2 in every run: the SSIM compared is the one trained
    assert "- SSIM: the loss, (1 − λ) L1 + λ D-SSIM, trains on the same SSIM (its 11-tap Gaussian window) in " \
           "every row (loss.ssim_lambda = 0.2)" in text
    # a grid whose loss is L1 alone trains no SSIM and says nothing of it
    _, text = results(tmp_path / "l1", spec_of({"base": {"iterations": 2000, "loss.ssim_lambda": 0.0, "data": {
        "resolution": 32, "views": 8, "spp": 2}}}), make)
    assert "- SSIM: the loss" not in text


# --------------------------------------------------------------------------- protocol
def test_the_header_states_the_protocol_the_runs_recorded(tmp_path):
    _, text = results(tmp_path, spec_of(), _lead(0.5))
    header = text.split("## sh.degree")[0]
    assert "- **Protocol**: quick (graphdeco's 30,000-step schedule scaled" in header
    assert "- **Schedule**: 2,000 iterations, graphdeco's 30,000-step schedule scaled to the run" in header
    assert "learning rates not scaled: positions 0.00016 → 1.6e-06 × scene extent" in header
    assert "- **Evaluation**: the test views at steps 500, 1,000, 1,500, 2,000" in header
    assert "rendered scenes at 32 px wide by Mitsuba, 2 spp" in header
    assert "LPIPS v0.1, AlexNet backbone, inputs scaled to [-1, 1]" in header
    # the default start (init = auto: the scene's points) is jittered with the seed (init.jitter 0.5)
    assert "the initial points (init = auto, seeded)" in header
    # ... and the header says what auto resolved to: these runs do not record it, so from the scene type
    # (a rendered scene has its points) and the curves' step-0 count (flat_curves: 1,000)
    assert ("- **Initialisation**: auto → surface on glossy: the scene's own surface points (exact geometry: a rendered scene's surfaces, a teacher's rendered depth; not SfM's), 1,000 Gaussians at "
            "step 0, jittered 0.5 × their neighbour spacing per seed (inferred") in header
    # sh.interval 1,000 scaled to 2,000 of 30,000 steps: round(66.7) = 67; bands at 67, 134, 201
    assert "SH degree raised one band every 67 steps (bands 1, 2, 3 at steps 67, 134, 201" in header

    # a config that names its protocol (a preset added to TrainConfig) is shown as named
    from splatbench.experiments.train_report import protocol_lines

    table = pd.read_parquet(tmp_path / "out" / "results.parquet")
    table["config.protocol"] = "graphdeco-30k"
    line = lambda t, head: next(x for x in protocol_lines(t) if x.startswith(head))  # noqa: E731
    assert "- **Protocol**: graphdeco-30k." in protocol_lines(table)
    # a graphdeco protocol lays the schedule over its 30,000 steps, whatever `schedule` the run recorded
    # ("scaled", the default): sh.interval 1,000 stays 1,000 (the old header scaled it to 2,000 / 30,000: 67)
    seven = table.assign(**{"config.protocol": "graphdeco-7k", "config.iterations": 7000})
    assert "SH degree raised one band every 1,000 steps (bands 1, 2, 3 at steps 1,000, 2,000, 3,000" \
        in line(seven, "- **Schedule as run**")
    # the refine interval (not scaled under the quick protocol) is the runs' own: 100 steps by default, as a
    # file sets it otherwise (a share of the run, each distinct value where cells differ)
    quick = table.assign(**{"config.protocol": "quick"})
    assert "the refine interval, 100 steps, is not scaled" in line(quick, "- **Schedule**")
    mixed = quick.assign(**{"config.strategy.refine_every": ['"5%"'] + ["15"] * (len(quick) - 1)})
    assert "the refine interval, 5% of the run / 15 steps (differs by cell), is not scaled" in line(mixed, "- **Schedule**")
    # its schedule is graphdeco's as written, not scaled to the runs' length (nor their LR decay)
    schedule = next(line for line in protocol_lines(table) if line.startswith("- **Schedule**"))
    assert "graphdeco's 30,000-step schedule as written" in schedule and "over 30,000 steps, not scaled" in schedule \
        and "scaled to the run (" not in schedule
    # the header names the scenes and says that one rendered scene falls short of the evidence rule
    assert "- **Scenes**: 1: glossy (rendered by Mitsuba); 0 real captures; a finding here holds on this scene " \
        "only" in "\n".join(protocol_lines(table))
    # a run that recorded its start: the method and count it recorded, nothing inferred
    recorded = table.assign(**{"metric.init_method": "sfm", "metric.init_points": 1234})
    init = next(line for line in protocol_lines(recorded) if line.startswith("- **Initialisation**"))
    assert "auto → sfm on glossy: SfM points triangulated from the training views, 1,234 Gaussians at step 0" \
        in init and "inferred" not in init
    # the background: these runs did not record the RGB auto resolved to, so the config's value, said unresolved
    assert "glossy `auto` (the RGB it resolved to is not recorded: these runs predate `metric.background`; auto " \
           "is white for a masked capture, else the mean colour" in line(table, "- **Background**")
    # an RGB set in the config is what the runs used: shown as the RGB
    assert "glossy (1, 1, 1), set by the config." in line(table.assign(**{"config.background": "[1.0, 1.0, 1.0]"}),
                                                             "- **Background**")
    # runs that recorded it: the RGB each scene rendered and evaluated against, and where it came from
    both = table.assign(**{"metric.background": "0.4706, 0.5, 0.52", "metric.background_source": "depth"})
    both = pd.concat([both, both.assign(scene="maryrose", **{"metric.background": "1, 1, 1",
                                                             "metric.background_source": "masks"})])
    assert line(both, "- **Background**").endswith(
        "glossy (0.4706, 0.5, 0.52), the mean colour of the pixels its depth marks empty, nothing hit (auto); "
        "maryrose (1, 1, 1), masked capture: its photos composited over it with their masks (auto).")
    # one statement per scene: a run that predates the record has the RGB its scene's runs with the same
    # background and data config recorded (auto resolves from the dataset, data.masks and config.background)
    some = pd.concat([both, table], ignore_index=True)
    assert "; glossy (0.4706, 0.5, 0.52), the mean colour of the pixels its depth marks empty, nothing hit (auto);" \
        in "; " + line(some, "- **Background**").split(": ", 1)[1] and "not recorded" not in line(some, "- **Background**")
    unmasked = pd.concat([both, table.assign(**{"config.data.masks": not table["config.data.masks"].iloc[0]})])
    assert "(auto) / `auto` (the RGB it resolved to is not recorded" in line(unmasked, "- **Background**")
    # the metrics line: each metric per test view, then the mean over the views (as graphdeco's metrics.py)
    metrics = line(table, "- **Metrics**")
    assert "averaged over the 1 test view: the mean of the views' PSNRs, as graphdeco's metrics.py" in metrics
    assert "not the PSNR of the pooled MSE (which is never higher than this mean: " in metrics \
        and "SSIM and LPIPS likewise" in metrics
    assert "averaged over the test views (1 on glossy, 8 on maryrose)" in line(
        pd.concat([table, table.assign(scene="maryrose", **{"metric.test_views": 8})]), "- **Metrics**")
    # the split per scene as the runs recorded it: a rendered scene's test views of its total, a capture's
    # train and test views; a capture's reduction and, where recorded, its image size in pixels
    views = int(table["config.data.views"].iloc[0])  # a rendered scene's train views are the rest of them
    assert line(table, "- **Split**").endswith(f"; glossy {views - 1} / 1 (train / test views).")
    # the rule as the loaders apply it (splatbench.data.dataset: i % test_every == 0), graphdeco's --eval holdout
    assert "view i is a test view when i % 8 = 0 (every 8th from the first, by sorted image name" \
        in line(table, "- **Split**")
    capture = table.assign(scene="fox", **{"config.data.path": "/data/fox", "config.data.downscale": 12,
                                           "config.data.views": None, "metric.test_views": 9})
    assert line(capture, "- **Split**").endswith("; fox – / 9 (train / test views; –: not recorded).")
    assert "each run's notes say which): fox 1/12 (image size not recorded by fox's runs)" \
        in line(capture, "- **Resolution**")
    sized = capture.assign(**{"metric.train_views": 58, "metric.image_width": 89, "metric.image_height": 158})
    assert "; fox 58 / 9 (train / test views)." in line(sized, "- **Split**")
    assert "fox 1/12 (89×158 px)" in line(sized, "- **Resolution**") \
        and "not recorded" not in line(sized, "- **Resolution**")
    # a run that predates the records takes them from the scene's runs with the same data config, not from
    # a run of another downscale (its size and views may differ)
    older = capture.assign(**{"metric.train_views": None, "metric.image_width": None, "metric.image_height": None})
    mixed = pd.concat([sized, older], ignore_index=True)
    assert "fox 1/12 (89×158 px)" in line(mixed, "- **Resolution**") and "; fox 58 / 9 (" in line(mixed, "- **Split**")
    other = pd.concat([sized, older.assign(**{"config.data.downscale": 24})], ignore_index=True)
    assert "(image size not recorded by fox's runs, or some of them)" in line(other, "- **Resolution**") \
        and "; fox 58 / – / 9 (train / test views; –: not recorded)" in line(other, "- **Split**")
    table["config.init.method"] = "random"
    assert "the random initial points" in "\n".join(protocol_lines(table))
    # given points kept as given (init_jitter = 0) do not vary with the seed, and the header says so
    table["config.init.method"], table["config.init.jitter"] = "surface", 0.0
    assert "not the initial points of init = surface" in "\n".join(protocol_lines(table))


def _sh_degree_runs() -> pd.DataFrame:
    """The run table of the records committed in reports/sh_degree/runs (skipped once they are gone)."""
    from pathlib import Path

    from splatbench.experiments.store import build_table, read_records

    folder = Path(__file__).resolve().parents[1] / "reports" / "sh_degree" / "runs"
    if not folder.is_dir():
        pytest.skip("reports/sh_degree/runs is gone (the report arrived)")
    return build_table(read_records(folder).values())


def test_the_sh_steps_in_the_header_are_where_the_real_runs_curves_part():
    # reports/sh_degree/runs (graphdeco-7k, sh.interval 1,000, recorded schedule "scaled"): SH 0 and SH 3 of one
    # seed are the same run, bit for bit, until band 1 starts training; the header's band-1 step must be the last
    # logged step (every 100) at which their training PSNR is still equal
    from splatbench.experiments.train_report import schedule_as_run

    table = _sh_degree_runs()
    fox = table[(table.scene == "fox") & (table.seed == 0)]
    zero, three = (json.loads(fox[fox["axis.sh.degree"].astype(str) == d].curves.iloc[0]) for d in ("0", "3"))
    assert zero["step"] == three["step"]
    parted = next(s for s, a, b in zip(zero["step"], zero["psnr"], three["psnr"]) if a != b)
    band1 = max(s for s in zero["step"] if s < parted)
    assert band1 == 1000 and f"SH degree raised one band every {band1:,} steps" in schedule_as_run(table)


def test_the_runs_said_to_refine_at_their_last_step_are_those_that_counted_one_refinement_more():
    # reports/sh_degree/runs (graphdeco-7k): the default strategy refines at 600, 700, ..., 7,000 (65 times,
    # the last right before the evaluation), the budget cells stop at refine_stop = 7,000 (64); the header's
    # count, from the configs, must pick out exactly the runs whose strategy counted 65
    from splatbench.experiments.train_report import protocol_lines, refined_at_end

    table = _sh_degree_runs()
    table = table[table["config.protocol"] == "graphdeco-7k"]
    late = [refined_at_end(table.loc[[i]]) == 1 for i in table.index]
    counts = table["metric.refinements"].astype(int)
    assert set(counts) == {64, 65} and late == list(counts == 65)
    assert f"{sum(late)} of {len(table)} runs refined at their last step" in "\n".join(protocol_lines(table))
    # runs that evaluated before the step's refinement (eval.before_refine, graphdeco's order) left it out
    assert refined_at_end(table.assign(**{"config.eval.before_refine": True})) == 0


def test_the_checks_runs_say_where_they_differ_from_graphdeco():
    # reports/sh_degree/runs' 30K check: refine_stop 15,000 < 30,000, so no refinement at the last step; on
    # ethiopian_head's white background, graphdeco's --white_background reset at step 500 is named
    from splatbench.experiments.train_report import check_schedule_note

    table = _sh_degree_runs()
    check = table[table["config.protocol"] == "graphdeco-30k"]
    (line,) = check_schedule_note(check).lines
    assert "refined at their last step" not in line and "on a white background (ethiopian_head)" in line
    grid = table[table["config.protocol"] == "graphdeco-7k"]
    assert "48 of 66 refined at their last step" in check_schedule_note(grid).lines[0]


# --------------------------------------------------------------------------- best at comparable size
def _bigger_lead(share: float):
    """SH 3 ahead of SH 0 by 0.5 dB on every seed, with ``share`` more Gaussians (plus seeded noise)."""
    def make(run):
        rng = np.random.default_rng(run.seed)
        three = run.labels["sh.degree"] == 3
        psnr = 30.0 + rng.normal(0, 0.5) + (0.5 + rng.normal(0, 0.004) if three else 0.0)
        count = round(10000 * (1.0 + rng.normal(0, 0.01)) * ((1.0 + share) if three else 1.0))
        return metrics_of(psnr, num_gaussians=count), flat_curves(psnr)
    return make


def test_best_is_not_named_between_models_of_different_sizes(tmp_path):
    """A 0.5 dB lead is named best at 3 % more Gaussians (below the 5 % minimum effect) or with
    fewer, but at 20 % more it is "no single best at comparable size", with the size ratio as a
    claim whose number is the paired geometric-mean ratio of the runs' counts."""
    report, text = results(tmp_path / "a", spec_of(), _bigger_lead(0.03))
    assert [c.label for c in report.findings["sh.degree"].claims if c.kind == "best"] == ["3"]
    assert "with no more than 5 % more Gaussians" in text

    report, text = results(tmp_path / "b", spec_of(), _bigger_lead(-0.3))  # the leader is smaller: named
    assert [c.label for c in report.findings["sh.degree"].claims if c.kind == "best"] == ["3"]

    report, text = results(tmp_path / "c", spec_of(), _bigger_lead(0.2))
    claims = report.findings["sh.degree"].claims
    assert not [c for c in claims if c.kind == "best"]
    lead = next(c for c in claims if c.kind == "no best")
    assert (lead.label, lead.reference) == ("3", "0") and lead.significant and lead.practical
    size = next(c for c in claims if c.kind == "size")
    assert size.metric == "num_gaussians" and size.value == pytest.approx(1.2, rel=0.01) and size.low > 1.05
    assert "glossy: no single best at comparable size (`3`" in text
    assert f"at {size.text} the Gaussians, more than the 5 % minimum effect" in lead.text and lead.text in text
    # smaller-worse and larger-better: both on the front, but so is every row of this two-row table, which
    # tells nothing: the line is written only where some row is off the front
    assert "Pareto front" not in lead.text
    from types import SimpleNamespace

    from splatbench.reports.findings import _on_front

    frame = pd.DataFrame({"scene": "s", "label": ["a", "b", "c"], "num_gaussians.mean": [1.0, 2.0, 3.0],
                          "test_psnr.mean": [30.0, 31.0, 30.5]})  # c: larger and worse than b, dominated
    table = SimpleNamespace(frame=frame)
    rows = [SimpleNamespace(label=x) for x in "abc"]
    gauss = MetricSpec("num_gaussians", "Gaussians", ".0f", "", "lower")
    assert _on_front(table, "s", gauss, PSNR, rows[:2]) and not _on_front(table, "s", gauss, PSNR, rows[1:])
    assert not _on_front(SimpleNamespace(frame=frame[:2]), "s", gauss, PSNR, rows[:2])  # all on the front

    # the experiment file's own minimum effect for the Gaussians (25 %) lets the same lead be named
    report, _ = results(tmp_path / "d", spec_of({"report": {"min_effect": {"num_gaussians": 0.25}}}),
                        _bigger_lead(0.2))
    assert [c.label for c in report.findings["sh.degree"].claims if c.kind == "best"] == ["3"]


def test_best_at_comparable_size_is_judged_by_bytes_where_bytes_per_gaussian_differ(tmp_path):
    """Review of sh_degree, item 2: SH 3 with 3 % more Gaussians than SH 0 (below the 5 % minimum
    effect, so the count alone names it best) holds 59 / 14 floats per Gaussian: ×1.03 · 59 / 14 =
    ×4.34 the bytes, far beyond 5 %: "no single best at comparable size", the size ratio in bytes
    with the Gaussians' beside it, the comparison "Against model size" (≥ 10 % larger in bytes)."""
    def make(run):
        metrics, curves = _bigger_lead(0.03)(run)
        return {**metrics, "sh_degree": run.labels["sh.degree"]}, curves

    report, text = results(tmp_path, spec_of(), make)
    claims = report.findings["sh.degree"].claims
    assert not [c for c in claims if c.kind == "best"]
    size = next(c for c in claims if c.kind == "size")
    # the paired geometric-mean bytes ratio: the Gaussians' (1.03, seeded noise ±1 % per seed) times 59 / 14
    assert size.metric == "bytes" and size.value == pytest.approx(1.03 * 59 / 14, rel=0.02)
    lead = next(c for c in claims if c.kind == "no best")
    assert f"at {size.text} the bytes (×1.0" in lead.text and "the Gaussians), more than the 5 % minimum" in lead.text
    assert "with no more than 5 % more bytes (float32 parameters: the cells' bytes per Gaussian differ)" in text
    assert "**Against model size**: glossy: ×4." in text and "% larger; the grid declares no matched-size" in text
    # one SH degree everywhere: the bytes per Gaussian are one number, so the count decides as before
    report, text = results(tmp_path / "one", spec_of(), _bigger_lead(0.03))
    assert [c.label for c in report.findings["sh.degree"].claims if c.kind == "best"] == ["3"]
    assert "more Gaussians" in text and "bytes per Gaussian differ" not in text


def test_the_size_pareto_figure_plots_bytes_where_bytes_per_gaussian_differ(tmp_path):
    """Review item 4: the figure of size against quality uses the size the findings use. SH 0 with 10 %
    more Gaussians than SH 3 (fewer Gaussians: SH 3 would be on the Gaussian-count front alone) is
    ×0.26 the bytes of SH 3 (14 / 59 floats per Gaussian): in megabytes SH 0 is the smaller cell, and the
    front runs SH 0 → SH 3; the axis and heading name the megabytes."""
    def make(run):
        d = run.labels["sh.degree"]
        psnr = 30.0 + (0.5 if d == 3 else 0.0) + 0.01 * run.seed
        return {**metrics_of(psnr, num_gaussians=1100 if d == 0 else 1000), "sh_degree": d}, flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    mb = {d: n * floats_per_gaussian(d) * 4 / 1e6 for d, n in ((0, 1100), (3, 1000))}
    assert mb[0] < mb[3]  # the smaller model in bytes has more Gaussians
    assert report.fronts["gaussians_vs_error"] == {"glossy": ["sh.degree=0", "sh.degree=3"]}
    assert "## Model size (MB, float32 parameters) against test PSNR (dB)" in text
    assert "no other cell is both smaller (fewer bytes) and better" in text
    assert "- Pareto front on glossy, smallest first: `sh.degree=0` → `sh.degree=3`" in text
    # one SH degree everywhere (no sh_degree recorded: bytes per Gaussian one number): the count, as declared
    report, text = results(tmp_path / "one", spec_of(), lambda run: (make(run)[0] | {"sh_degree": 0}, make(run)[1]))
    assert report.fronts["gaussians_vs_error"] == {"glossy": ["sh.degree=3"]}
    assert "## Gaussians against test PSNR (dB)" in text and "fewest Gaussians first: `sh.degree=3`" in text


def test_the_raster_kind_declares_no_size_for_its_best():
    from splatbench.experiments.raster_kind import REPORT as RASTER_REPORT

    assert TRAIN_REPORT.rules.size == "num_gaussians" and RASTER_REPORT.rules.size is None


# --------------------------------------------------------------------------- loaded times in the table
def test_a_time_timed_under_load_prints_no_number_in_the_table(tmp_path):
    """Every SH 0 run was timed under load: its time cells read "— (loaded)". One SH 3 run (seed 2)
    was: its cells average the other two seeds and say one run was left out. Quality is kept."""
    def make(run):
        zero = run.labels["sh.degree"] == 0
        psnr = 30.0 + (0.0 if zero else 1.0) + 0.01 * run.seed
        loaded = int(zero or run.seed == 2)
        seconds = 1000.0 if loaded else 10.0 + run.seed  # a loaded run's time would move the mean a lot
        return metrics_of(psnr, seconds=seconds, loaded=loaded), flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    rows = {line.split(" | ")[1]: line.split(" | ") for line in text.splitlines() if line.startswith("| glossy |")}
    heads = next(line for line in text.splitlines() if line.startswith("| scene |")).split(" | ")
    t, r, q = heads.index("train time (s)"), heads.index("render (ms/view)"), heads.index("test PSNR (dB)")
    assert rows["`0`"][t] == "— (loaded)" and rows["`0`"][r] == "— (loaded)"
    assert rows["`0`"][q].startswith("30.01 ± ")  # quality kept: the mean of 30.00, 30.01, 30.02
    # seeds 0 and 1 only: 10.0 and 11.0 -> 10.5 (the loaded 1000 s would make it 340.3)
    assert rows["`3`"][t].startswith("10.5 ± ") and rows["`3`"][t].endswith("(1 loaded run left out)")
    table = next(a for a in report.axes if a.axis == "sh.degree")
    assert table.stat("glossy", "3", "train_seconds").n == 2 and table.stat("glossy", "0", "train_seconds").n == 0


# --------------------------------------------------------------------------- outlier test views
def _views(seed: int, sh: int, floater: dict | None = None) -> list[float]:
    """Eight test views of a healthy run: each its own level (30-37 dB) and a seed-to-seed wobble of
    0.3 dB; ``floater``: {(seed, sh): (view, drop)} -- that run's view ``view`` ``drop`` dB lower."""
    rng = np.random.default_rng(100 * seed + sh)
    views = [30.0 + v + float(rng.normal(0, 0.3)) for v in range(8)]
    view, drop = (floater or {}).get((seed, sh), (None, 0.0))
    if view is not None:
        views[view] -= drop
    return [round(v, 6) for v in views]


def view_results(tmp_path, floater: dict | None = None, recorded=lambda run: True):
    """A results folder whose runs record their test views (`_views`) unless ``recorded(run)`` is
    false; each run's test PSNR is their mean, as a run's is."""
    def make(run):
        views = _views(run.seed, run.labels["sh.degree"], floater)
        curves = flat_curves(float(np.mean(views)))
        if recorded(run):
            curves["test_view_psnr"] = views
        return metrics_of(float(np.mean(views)), test_views=8), curves
    return results(tmp_path, spec_of(), make)


def test_a_run_with_one_test_view_far_below_the_same_view_of_its_other_seeds_is_flagged(tmp_path):
    report, text = view_results(tmp_path, floater={(1, 3): (4, 20.0)})
    section = report.findings["outlier test views"].markdown()
    assert "## Appendix: Outlier test views" in text and section in text
    flagged = [line for line in section.splitlines() if line.startswith("- **Outlier test view**")]
    assert len(flagged) == 1, section
    line = flagged[0]
    table = report.table
    run = table[(table.seed == 1) & (table["axis.sh.degree"] == 3)].iloc[0]
    views = _views(1, 3, {(1, 3): (4, 20.0)})
    others = np.median([_views(s, 3)[4] for s in (0, 2)])
    assert line.startswith(f"- **Outlier test view**: glossy, `sh.degree=3`, seed 1 (`{run.run_id}`): test view 4 "
                           f"at {views[4]:.2f} dB, {others - views[4]:.1f} dB below the same view in the cell's other "
                           f"seeds (their median {others:.2f} dB): likely a floater"), line
    assert "docs/history/2026-12-07-divergent-seed.md" in line
    # its cell's mean with and without it: 20 dB over 8 views is 2.5 dB in the run's mean
    cell = table[table["axis.sh.degree"] == 3]["metric.test_psnr"]
    with_it, without = cell.mean(), cell[table.seed != 1].mean()
    assert f"its cell's mean test PSNR is {with_it:.2f} dB with this run, {without:.2f} dB over the other seeds " \
           f"alone ({with_it - without:+.2f} dB)" in line
    assert with_it - without == pytest.approx(-2.5 / 3, abs=0.3)  # one seed of three down 2.5 dB
    assert "- Each run's test views against the same views in its cell's other seeds (flagged: more than 10 dB " \
           "below their median): 6 runs checked, 1 flagged." in section


def test_healthy_seeds_and_a_drop_below_the_threshold_are_not_flagged(tmp_path):
    # a 6 dB drop: above a healthy run's spread of one view, below the floaters' 15-25 dB (OUTLIER_VIEW_DB)
    report, text = view_results(tmp_path, floater={(1, 3): (4, 6.0)})
    section = report.findings["outlier test views"].markdown()
    assert "**Outlier test view**" not in text
    assert section.splitlines()[0] == ("- Each run's test views against the same views in its cell's other seeds "
                                       "(flagged: more than 10 dB below their median): 6 runs checked, 0 flagged.")


def test_the_view_lowest_in_every_run_is_named_with_what_it_costs_each_cell(tmp_path):
    """A view low in every seed is no seed's outlier (`view_outliers` cannot see it): the section names
    each scene's hardest view and how much each cell's mean would rise without it."""
    report, _ = view_results(tmp_path)
    lines = report.findings["outlier test views"].markdown().splitlines()
    assert lines[1].startswith("- **Hardest test view** per scene where it moves a cell's mean by 0.1 dB or more")
    # `_views`: view v sits at 30 + v dB (+-0.3 per seed), so view 0 is the lowest in all 6 runs, ~3.5 dB under the
    # median of 30..37 (33.5); without it a run's mean of 30..37 (33.5) becomes that of 31..37 (34.0): +0.5 dB
    runs = [_views(seed, sh) for seed in (0, 1, 2) for sh in (0, 3)]
    lowest = sum(int(np.argmin(v)) == 0 for v in runs)  # view 1 (31 dB) may dip under view 0 by the wobble
    assert lowest >= 4
    psnr = [v[0] for v in runs]
    gap = [float(np.median(v)) - v[0] for v in runs]
    rise = [np.mean([np.mean(_views(seed, sh)[1:]) - np.mean(_views(seed, sh)) for seed in (0, 1, 2)])
            for sh in (0, 3)]
    assert lines[2] == (f"  - glossy: test view 0, the lowest in {lowest} of 6 runs, {min(psnr):.1f}–{max(psnr):.1f} dB, "
                        f"{min(gap):.1f}–{max(gap):.1f} dB below its run's median view; without it each cell's mean "
                        f"test PSNR would rise by {min(rise):.2f}–{max(rise):.2f} dB, so it moves a mean difference "
                        f"between two cells by at most {max(rise) - min(rise):.2f} dB (the spread of those rises).")
    assert 0.4 < min(rise) <= max(rise) < 0.6
    # a view whose removal moves no cell's mean by the minimum effect is not named
    from splatbench.experiments.train_report import hardest_view_lines

    assert hardest_view_lines(report.table, min_effect=0.7) == []


def test_runs_without_a_per_view_record_are_counted_not_checked(tmp_path):
    # seed 2 of SH 0 finished before runs recorded their views; seeds 1 and 2 of SH 3 likewise, so seed 0 of SH 3
    # has no other seed to compare with; the floater in seed 1 of SH 0 is still found against seed 0 alone
    report, text = view_results(tmp_path, floater={(1, 0): (2, 18.0)},
                                recorded=lambda run: (run.seed, run.labels["sh.degree"]) not in
                                {(2, 0), (1, 3), (2, 3)})
    section = report.findings["outlier test views"].markdown()
    assert section.count("- **Outlier test view**: glossy, `sh.degree=0`, seed 1") == 1
    assert next(x for x in section.splitlines() if x.startswith("- Each run's")) == (
        "- Each run's test views against the same views in its cell's other seeds (flagged: more than 10 dB below "
        "their median): 2 runs checked, 1 flagged; 4 could not be: 3 without a per-view record (finished before "
        "runs recorded `curves.test_view_psnr`), 1 without another seed of its cell to compare with.")
    # a report of runs none of which recorded their views says nothing of them (a committed report stays as it was)
    report, text = view_results(tmp_path / "old", recorded=lambda run: False)
    assert "outlier test views" not in report.findings and "Outlier test view" not in text


def test_auto_is_defined_and_its_holdout_named_as_what_else_it_changed(tmp_path):
    # sh.degree = auto (splatbench.train.sh_schedule): bands on trial every sh.interval steps (1,000 scaled to
    # 2,000 of 30,000: 67), measured on every 8th training view, held out of training until band 3 has been
    # measured one interval after it starts: step 4 x 67 = 268 (auto_lookahead 2, the default)
    spec = spec_of({"axes": {"sh.degree": [0, 3, "auto"]}})

    def make(run):
        d = run.labels["sh.degree"]
        return metrics_of(30.0 + 0.01 * run.seed, sh_degree=0 if d == "auto" else d), flat_curves(30.0)

    _, text = results(tmp_path, spec, make)
    note = next(x for x in text.splitlines() if x.startswith("- `auto`"))
    assert note.startswith("- `auto` (a band added every 67 steps is kept if it gains ≥ 0.1 dB per band on every 8th "
                           "training view, held out of training until the degree settles) ended at SH degree 0 on "
                           "glossy (every seed).")
    # ... so where it ended at a fixed row's degree, its difference from that row is the holdout's, not SH's
    assert note.endswith("Also changed: it trained on about 7/8 of the training views until step 268, so its difference "
                         "from the row of the degree it ended at (glossy `0`) is the holdout's cost, not a degree's.")
    # ... and the Summary says so beside auto's differences (a referee reads them as a degree's otherwise)
    summary = text[text.index("## Summary"):text.index("## Protocol and runs")]
    assert "- **`auto`** ended at SH degree 0 on glossy: each of its differences is the degree it chose and its " \
           "holdout's cost together" in summary


# --------------------------------------------------------------------------- Holm's correction
def test_holm_steps_down_on_a_hand_worked_example():
    # m = 4 at 5 %: sorted 0.005 <= 0.05/4 = 0.0125 (rejected), 0.01 <= 0.05/3 = 0.0167 (rejected),
    # 0.03 > 0.05/2 = 0.025: stops, so 0.04 stays too although 0.04 < 0.05
    assert holm([0.01, 0.04, 0.03, 0.005]) == [True, False, False, True]
    # step-down, not Bonferroni: 0.001 <= 0.05/3, 0.02 <= 0.05/2, 0.04 <= 0.05/1 (Bonferroni's 0.05/3 keeps 0.001 only)
    assert holm([0.04, 0.001, 0.02]) == [True, True, True]
    # the stop holds every larger p-value: 0.045 would pass its own 0.05/1 but follows 0.03 > 0.05/3
    assert holm([0.045, 0.001, 0.03, 0.04]) == [False, True, False, False]
    # a p-value equal to its threshold is rejected (p <= alpha / (m - i)); so is a tie with a rejected one
    assert holm([0.025, 0.05]) == [True, True]
    assert holm([0.012, 0.012, 0.012, 0.9]) == [True, True, True, False]  # 0.012 <= 0.0125, 0.0167, 0.025
    # one test: Holm is the test itself; NaN (no p-value) is never rejected and holds the rest
    assert holm([0.049]) == [True] and holm([0.051]) == [False]
    assert holm([math.nan, 0.001]) == [False, True] and holm([]) == []
    assert holm([0.01, 0.02], alpha=0.01) == [False, False]  # 0.01 > 0.01 / 2


def test_the_p_value_agrees_with_the_interval_it_comes_from():
    """p < 0.05 exactly when the 95 % interval excludes the null, and it is scipy's paired t test (on the
    logs for a ratio): both come from the same t distribution and the same numbers."""
    rng = np.random.default_rng(7)
    seen = set()
    for trial in range(300):
        n = int(rng.integers(2, 7))
        a = rng.normal(30.0, 1.0, n)
        b = a + rng.normal(0.0, 1.0, n) + rng.choice([0.0, 0.3, 1.0])
        iv = paired_difference(list(a), list(b))
        p = t_p_value(iv)
        assert (p < 0.05) == iv.excludes(0.0), (a, b, iv, p)
        assert p == pytest.approx(stats.ttest_rel(b, a).pvalue, rel=1e-9)
        seen.add(iv.excludes(0.0))
        ratio = paired_ratio(list(np.exp(a / 10)), list(np.exp(b / 10)))
        q = t_p_value(ratio, 1.0)
        assert (q < 0.05) == ratio.excludes(1.0)
        assert q == pytest.approx(stats.ttest_rel(b / 10, a / 10).pvalue, rel=1e-6)  # log(exp(x / 10)) = x / 10
    assert seen == {True, False}  # both sides of 0.05 were tried
    # at the interval's edge: an interval that just touches 0 has p = 0.05 (half-width = estimate: t = t_{0.975, 2})
    assert t_p_value(Interval(1.0, 0.0, 2.0, 3, "paired t")) == pytest.approx(0.05, abs=1e-12)
    assert np.isnan(t_p_value(Interval(1.0, math.nan, math.nan, 1, "paired t")))  # one seed: no test


#: Per SH degree, its test PSNR above SH 0's on seeds 0, 1, 2: SH 3 by 2.0 / 2.1 / 2.2 dB (p < 0.001), SH 1 by
#: 0.35 / 0.5 / 0.65 (t = 5.77 on 2 degrees of freedom: p = 0.029, significant alone, above the 0.05 / 2 of its
#: Holm step), SH 2 by -0.3 / +0.1 / +0.5 (not significant).
HOLM_DIFFS = {0: (0.0, 0.0, 0.0), 1: (0.35, 0.5, 0.65), 2: (-0.3, 0.1, 0.5), 3: (2.0, 2.1, 2.2)}
HOLM_BASE = 30.0 + 0.4 * np.arange(3)  # SH 0 per seed


def _holm_grid(run):
    psnr = float(HOLM_BASE[run.seed]) + HOLM_DIFFS[run.labels["sh.degree"]][run.seed]
    return metrics_of(psnr), flat_curves(psnr)


def test_holm_keeps_one_comparison_and_marks_the_other_in_the_summary(tmp_path):
    report, text = results(tmp_path, spec_of({"axes": {"sh.degree": [0, 1, 2, 3]}}), _holm_grid)
    claims = report.findings["sh.degree"].claims
    vs = {c.label: c for c in claims if c.kind == "vs" and c.metric == "test_psnr"}
    p = {str(d): stats.ttest_rel(HOLM_BASE + np.array(diff), HOLM_BASE).pvalue for d, diff in HOLM_DIFFS.items() if d}
    assert 0.025 < p["1"] < 0.05 and p["3"] < 0.001 and p["2"] > 0.05  # what the grid was made to be
    assert vs["1"].significant and vs["3"].significant and not vs["2"].significant
    holm_claim = next(c for c in claims if c.kind == "holm")
    assert (holm_claim.value, holm_claim.n) == (1.0, 3)
    line = next(x for x in text.splitlines() if x.startswith("- **Holm's correction**"))
    assert line == (f"- **Holm's correction** over the 3 test PSNR comparisons of this axis (family-wise 5 %): 1 of the "
                    f"2 significant alone remains significant: glossy `3` (p < 0.001); the others' intervals are per "
                    f"comparison (the first kept out: glossy `1`, p = {p['1']:.3f} > 0.05/2). Seeds with the row above "
                    f"`0` (glossy): `1` 3/3; `2` 2/3; `3` 3/3.")
    summary = text[text.index("## Summary"):text.index("## Protocol and runs")]
    row = {label: next(x for x in summary.splitlines() if x.startswith(f"- **`{label}`** against"))
           for label in ("1", "2", "3")}
    assert "+0.50 dB [95 % CI" in row["1"] and "], not significant after Holm" in row["1"]
    assert "Holm" not in row["3"] and "Holm" not in row["2"]  # survives; not significant in the first place
    # the per-comparison wording stays: `1`'s findings line reads +0.50 dB as a difference, with no Holm mark
    body = next(x for x in text.splitlines() if x.startswith("  - `1`: test PSNR"))
    assert vs["1"].text in body and "Holm" not in body and vs["1"].practical
    assert "except Holm's over the 3 test PSNR ones against `0`" in text


def test_no_holm_line_without_a_family_to_correct(tmp_path):
    # one comparison (SH 3 against 0 on one scene): Holm is the test itself, so neither line nor mark
    report, text = results(tmp_path, spec_of(), _holm_grid)
    assert "Holm" not in text and not [c for c in report.findings["sh.degree"].claims if c.kind == "holm"]


def test_across_scenes_says_how_many_of_its_comparisons_survive_holm(tmp_path):
    """A row practical with one sign on every scene reads "Across scenes" per comparison; where some of
    those comparisons do not survive Holm, the Summary's mark says how many do (sh_degree's SH 3: 2 of 4)."""
    def make(run):
        # SH 3 above SH 0 on both scenes: on textured by 2.0 / 2.1 / 2.2 (p < 0.001: kept at 0.05 / 4), on
        # glossy by 0.35 / 0.5 / 0.65 (p = 0.029: significant alone, kept out at Holm's next step, 0.05 / 3);
        # SH 1 by -0.3 / +0.1 / +0.5 on both (not significant): the family has 4 comparisons
        up = {("textured", 3): (2.0, 2.1, 2.2), ("glossy", 3): (0.35, 0.5, 0.65)}.get(
            (run.scene, run.labels["sh.degree"]), (-0.3, 0.1, 0.5) if run.labels["sh.degree"] == 1 else (0, 0, 0))
        psnr = float(HOLM_BASE[run.seed]) + up[run.seed]
        return metrics_of(psnr), flat_curves(psnr)

    report, text = results(tmp_path, spec_of({"scenes": ["glossy", "textured"], "axes": {"sh.degree": [0, 1, 3]}}),
                           make)
    summary = text[text.index("## Summary"):text.index("## Protocol and runs")]
    three = next(x for x in summary.splitlines() if x.startswith("- **`3`** against"))
    assert "**Across scenes**: practical and of one sign on all 2 scenes (each per comparison; 1 of 2 significant " \
           "after Holm)" in three, three
