"""The report rules of issue 39 (item 4, 5 and the header of item 2): settled means flat *and* not
past its peak, "best" only where the lead's interval clears the minimum effect, a PSNR difference
whose SSIM or LPIPS goes the other way says so, "across scenes" only where the sign agrees on every
scene, ranks and Kendall's tau (across scenes and against a quick version), Gaussians and bytes
beside each comparison with the matched-size cells of ``[report] matched``, the Scenes line's real
captures and a quick-protocol report's first line.

Results folders are written by hand (made-up metrics and curves on the real grid of a small train
experiment), as tests/test_report_rules.py does: no training runs.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from splatbench.errors import InputError
from splatbench.experiments import parse_experiment
from splatbench.experiments.train_kind import REPORT as TRAIN_REPORT
from splatbench.experiments.train_kind import TRAIN
from splatbench.experiments.train_report import floats_per_gaussian, protocol_lines, smoke_test_line
from splatbench.metrics.stats import kendall_tau
from splatbench.reports.ranks import ranks
from splatbench.reports.settling import cell_settling, settling_finding
from tests.test_report_rules import flat_curves, metrics_of, results


def spec_of(scenes=("glossy",), axes=None, **extra):
    return parse_experiment({"name": "rules", "kind": "train", "scenes": list(scenes), "seeds": [0, 1, 2],
                             "base": {"iterations": 2000, "data": {"resolution": 32, "views": 8, "spp": 2}},
                             "axes": axes if axes is not None else {"sh.degree": [0, 3]}, **extra},
                            source="rules.toml")


def vs_line(text: str, label: str) -> str:
    return next(line for line in text.splitlines() if line.startswith(f"  - `{label}`: "))


def appendix_line(text: str, label: str) -> str:
    """The row's line of the other comparisons, in its axis's section "Appendix: <axis> in full"."""
    return vs_line(text[text.index("## Appendix: "):], label)


# --------------------------------------------------------------------------- past its peak
def _peaked(fall: float, seeds: int = 3) -> pd.DataFrame:
    """A 7K test curve (a point every 700 steps) that peaks at 2,100 steps and falls by ``fall`` dB
    by 4,200, then stays flat (so its last quarter is flat)."""
    steps = list(range(700, 7001, 700))
    rows = []
    for seed in range(seeds):
        values = [28.0 + 0.1 * seed + (s / 2100 if s <= 2100 else 1.0 - fall * min(1.0, (s - 2100) / 2100))
                  for s in steps]
        rows.append({"run_id": f"p{seed}", "status": "done", "scene": "fox", "seed": seed, "axis.x": "a",
                     "curves": json.dumps({"eval_step": steps, "eval_psnr": values})})
    return pd.DataFrame(rows)


def test_a_flat_curve_that_fell_from_its_peak_is_not_settled():
    cell = cell_settling(_peaked(0.3), TRAIN_REPORT.settling, 0.1)
    assert cell.flat and cell.past_peak and not cell.settled
    assert (cell.best_step, round(cell.fall, 6)) == (2100, 0.3)  # the mean curve's best and its fall
    assert "past its peak (best at step 2,100, 0.30 dB above its last value)" in cell.why_not()
    text = settling_finding(_peaked(0.3), TRAIN).markdown()
    assert "**Past its peak**" in text and "fox `x=a` (best at step 2,100, 0.30 dB above its last value)" in text
    assert "Settled: every cell" not in text and not settling_finding(_peaked(0.3), TRAIN).claims[0].settled
    # a fall within the minimum effect (0.05 dB < 0.1 dB) is settled; and the file's minimum effect moves it
    assert cell_settling(_peaked(0.05), TRAIN_REPORT.settling, 0.1).settled
    assert cell_settling(_peaked(0.3), TRAIN_REPORT.settling, 0.5).settled



def test_the_summary_counts_the_cells_either_mark_leaves_unsettled():
    """Not settled and past its peak overlap: the Summary gives how many cells either leaves
    unsettled (a past-its-peak cell may be flat, a moving one below its peak), counted once."""
    steps = list(range(700, 7001, 700))
    rows = []
    for scene, rise in (("fox", 0.0), ("maryrose", 0.001)):  # maryrose still rising 1 dB / 1,000 steps
        peaked = _peaked(0.3)
        for seed in range(3):
            base = json.loads(peaked.curves[seed])["eval_psnr"]
            values = base if scene == "fox" else [28.0 + rise * s for s in steps]
            rows.append({"run_id": f"{scene}{seed}", "status": "done", "scene": scene, "seed": seed, "axis.x": "a",
                         "curves": json.dumps({"eval_step": steps, "eval_psnr": values})})
    summary = settling_finding(pd.DataFrame(rows), TRAIN).summary[0]
    assert summary.startswith("- **2 of 2 cells not settled or past their peak** (1 still moving, 1 past their peak, "
                              "0 both)"), summary
    alone = settling_finding(_peaked(0.3), TRAIN).summary[0]  # one mark: no union line
    assert "not settled or past their peak" not in alone and "**Past its peak**: 1 of 1" in alone


# --------------------------------------------------------------------------- best
def test_best_needs_the_leads_interval_beyond_the_minimum_effect(tmp_path):
    """+0.12 dB (per seed +0.08, +0.12, +0.16: significant, estimate above 0.1 dB) has a lower bound of
    +0.12 − t · 0.04 / √3 = +0.021 dB: within the minimum effect, so no best (the rule of issue 39)."""
    deltas = {0: 0.08, 1: 0.12, 2: 0.16}

    def make(run):
        psnr = 30.0 + run.seed * 0.3 + (deltas[run.seed] if run.labels["sh.degree"] == 3 else 0.0)
        return metrics_of(psnr), flat_curves(psnr)

    report, text = results(tmp_path, spec_of(), make)
    claims = report.findings["sh.degree"].claims
    lead = next(c for c in claims if c.kind == "no best")
    assert lead.significant and lead.practical and lead.low == pytest.approx(0.12 - 4.302653 * 0.04 / math.sqrt(3),
                                                                             abs=1e-4)
    assert not [c for c in claims if c.kind == "best"]
    assert "not beyond the 0.1 dB minimum effect" in lead.text and lead.text in text


# --------------------------------------------------------------------------- the other way
def _ssim_make(ssim_gain: float):
    """SH 3 ahead by +0.5 dB (+0.01 per seed); its SSIM ``ssim_gain`` (+0.0005 per seed) from SH 0's."""
    def make(run):
        three = run.labels["sh.degree"] == 3
        psnr = 30.0 + run.seed * 0.01 + ((0.5 + 0.01 * run.seed) if three else 0.0)
        ssim = 0.9 + run.seed * 0.001 + ((ssim_gain + 0.0005 * run.seed) if three else 0.0)
        return metrics_of(psnr, test_ssim=ssim), flat_curves(psnr)
    return make


def test_a_psnr_lead_whose_ssim_goes_the_other_way_says_so(tmp_path):
    report, text = results(tmp_path, spec_of(), _ssim_make(-0.0105))
    best = next(c for c in report.findings["sh.degree"].claims if c.kind == "best")
    assert "**but SSIM goes the other way** (SSIM -0.0100 [95 % CI" in best.text and best.text in text
    assert "**The other way** (against the test PSNR difference, significantly): glossy: SSIM -0.0100" \
        in vs_line(text, "3")
    # the report's summary, before the protocol, says so too: of the best and of the comparison (issue 39 item 4)
    summary = text[text.index("## Summary"):text.index("## Protocol and runs")]
    vs = next(c for c in report.findings["sh.degree"].claims if c.kind == "vs" and c.metric == "test_psnr")
    assert f"- **`3`** against `0`, test PSNR: glossy {vs.text}; **the other way** (against the test PSNR difference): SSIM on glossy." in summary
    assert "glossy `3` (" in summary and "**but SSIM goes the other way**" in summary
    # SSIM going the same way is not named
    _, text = results(tmp_path / "b", spec_of(), _ssim_make(0.01))
    assert "the other way" not in text.lower()


def test_the_report_opens_with_its_summary_and_ends_with_its_appendix(tmp_path):
    """The layout (docs/reports.md, "Layout"): the summary first, then the protocol, each axis's primary findings,
    the check and the figures; every other number in "Appendix: ..." sections at the end."""
    report, text = results(tmp_path, spec_of(("glossy", "diffuse")), _ssim_make(-0.0105))
    heads = [line for line in text.splitlines() if line.startswith("## ")]
    assert heads[:3] == ["## Summary", "## Protocol and runs", "## sh.degree"]
    first = next(i for i, h in enumerate(heads) if h.startswith("## Appendix: "))
    assert all(h.startswith("## Appendix: ") for h in heads[first:]), heads
    assert heads[first:first + 3] == ["## Appendix: sh.degree in full", "## Appendix: Settling", "## Appendix: Ranks"]
    found = report.findings["sh.degree"]
    appendix = text[text.index("## Appendix: sh.degree in full"):]
    body = text[:text.index("## Appendix: sh.degree in full")]
    assert found.markdown() in body and found.appendix_markdown() in appendix
    # the body's comparisons state the primary metric alone; the others are the appendix's
    assert "; SSIM " not in vs_line(body, "3") and appendix_line(text, "3").startswith("  - `3`: SSIM ")
    assert report.findings["settling"].markdown() in appendix and "- Settled: every cell" in body


# --------------------------------------------------------------------------- across scenes
def test_a_difference_holds_across_scenes_only_with_one_sign_on_every_scene(tmp_path):
    def make_with(sign_on_diffuse: float):
        def make(run):
            gain = 0.5 * (sign_on_diffuse if run.scene == "diffuse" else 1.0)
            psnr = 30.0 + run.seed * 0.01 + (gain + 0.01 * run.seed if run.labels["sh.degree"] == 3 else 0.0)
            return metrics_of(psnr), flat_curves(psnr)
        return make

    _, text = results(tmp_path / "a", spec_of(("glossy", "diffuse")), make_with(1.0))
    assert "**Across scenes**: practical and of one sign on all 2 scenes" in vs_line(text, "3")
    _, text = results(tmp_path / "b", spec_of(("glossy", "diffuse")), make_with(-1.0))
    line = vs_line(text, "3")
    assert "**Across scenes**" not in line
    assert "**Per scene only** (not practical with one sign on every scene: practical on 2 of 2 scenes, with " \
           "opposite signs: glossy +, " \
           "diffuse −)" in line


def test_the_difference_over_the_scenes_as_the_sample(tmp_path):
    """Beside the per-scene intervals (over seeds), the mean of the per-scene differences with a t
    interval over the scenes (df = scenes - 1): what another scene like these would give. Gains 0.5,
    1.0 and 1.5 dB (+0.01 dB a seed: each scene's mean difference is its gain + 0.01) are practical
    with one sign on all three scenes, yet over the scenes the interval crosses zero; two scenes (df 1)
    print none."""
    from scipy import stats

    gains = {"glossy": 0.5, "diffuse": 1.0, "textured": 1.5}

    def make(run):
        gain = gains[run.scene] + 0.01 * run.seed if run.labels["sh.degree"] == 3 else 0.0
        psnr = 30.0 + run.seed * 0.01 + gain
        return metrics_of(psnr), flat_curves(psnr)

    _, text = results(tmp_path / "a", spec_of(tuple(gains)), make)
    diffs = np.array([g + 0.01 for g in gains.values()])
    half = stats.t.ppf(0.975, 2) * diffs.std(ddof=1) / np.sqrt(3)  # 4.303 x 0.5 / sqrt(3) = 1.24 dB
    low, high = diffs.mean() - half, diffs.mean() + half
    assert low < 0 < high
    line = vs_line(text, "3")
    assert "**Across scenes**: practical and of one sign on all 3 scenes" in line
    assert (f"; over the scenes, taken as a random sample of scenes (df 2; not in Holm's family), {diffs.mean():+.2f} "
            f"dB [95 % CI {low:+.2f}, {high:+.2f}], no significant difference, inconclusive") in line
    _, text = results(tmp_path / "b", spec_of(("glossy", "diffuse")), make)
    assert "over the scenes" not in text


def test_the_authors_notes_on_the_data_are_printed_as_theirs(tmp_path):
    """``[report] notes``: what the author knows of the data that no number shows (maryrose's defective
    mask), in the Summary, marked as the author's; anything but a list of one-line strings is one line."""
    note = "glossy's test view 3: its target was rendered with a wrong light"
    report, text = results(tmp_path, spec_of(report={"notes": [note]}),
                           lambda run: (metrics_of(30.0 + run.seed * 0.01), flat_curves(30.0)))
    summary = text[text.index("## Summary"):text.index("## Protocol and runs")]
    assert f"**Notes from the experiment file** (its author's, on the data; not computed from the runs):\n\n- {note}\n" \
        in summary
    _, plain = results(tmp_path / "b", spec_of(), lambda run: (metrics_of(30.0 + run.seed * 0.01), flat_curves(30.0)))
    assert "Notes from the experiment file" not in plain
    for bad in (note, [""], ["two\nlines"], [3]):
        with pytest.raises(InputError, match=r"report\.notes: expected a list of one-line strings") as caught:
            spec_of(report={"notes": bad})
        assert "\n" not in str(caught.value)


# --------------------------------------------------------------------------- ranks
def test_kendall_tau_b_against_hand_counted_pairs():
    # one discordant pair (b, c) of 6: (5 − 1) / 6
    assert kendall_tau({"a": 1, "b": 2, "c": 3, "d": 4}, {"a": 1, "b": 3, "c": 2, "d": 4}) == (pytest.approx(4 / 6), 4)
    # ties: x = 1, 2, 2, 3 and y = 1, 2, 3, 3: 4 concordant, 0 discordant, one tie on each side:
    # tau-b = 4 / sqrt((6 − 1) (6 − 1)) = 0.8
    assert kendall_tau({"a": 1, "b": 2, "c": 2, "d": 3}, {"a": 1, "b": 2, "c": 3, "d": 3})[0] == pytest.approx(0.8)
    assert kendall_tau({"a": 1, "b": 2}, {"a": 2, "b": 1})[0] == pytest.approx(-1.0)
    assert math.isnan(kendall_tau({"a": 1}, {"a": 1})[0]) and math.isnan(kendall_tau({"a": 1, "b": 1},
                                                                                      {"a": 1, "b": 2})[0])
    assert ranks({"x": 30.0, "y": 31.0, "z": 31.0}, "higher") == {"x": 3.0, "y": 1.5, "z": 1.5}
    assert ranks({"x": 0.1, "y": 0.3}, "lower") == {"x": 1.0, "y": 2.0}


def test_cells_less_than_the_minimum_effect_apart_are_tied_in_the_ranks():
    from splatbench.reports.ranks import tied

    # glossy at 7K, seed 0: SH 1 31.26, SH 3 31.19 (0.07 dB apart, under the 0.1 dB minimum effect), auto 31.05,
    # SH 0 30.81: 1 and 3 tie (their mean), auto is 0.21 below the group's head, so it stands alone
    means = {"0": 30.81, "1": 31.26, "3": 31.19, "auto": 31.05}
    levels = tied(means, "higher", 0.1)
    assert levels["1"] == levels["3"] == pytest.approx((31.26 + 31.19) / 2)
    assert levels["auto"] == 31.05 and levels["0"] == 30.81
    assert ranks(levels, "higher") == {"0": 4.0, "1": 1.5, "3": 1.5, "auto": 3.0}
    assert tied(means, "higher", None) == means
    # a chain closer than the minimum effect step by step joins only while within it of the group's head
    assert len(set(tied({"a": 1.0, "b": 0.95, "c": 0.9, "d": 0.85}, "higher", 0.1).values())) == 2
    # lower is better: the same rule from the lowest
    assert tied({"x": 0.010, "y": 0.012, "z": 0.030}, "lower", 0.005)["x"] == pytest.approx(0.011)
    # a ratio's minimum effect is relative: 1.00 and 1.04 within x1.05 tie, 1.10 does not
    assert len(set(tied({"a": 1.00, "b": 1.04, "c": 1.10}, "lower", 0.05, ratio=True).values())) == 2


def test_a_report_ranks_its_cells_per_scene_and_against_its_quick_version(tmp_path):
    gains = {"glossy": {0: 0.0, 1: 0.5, 3: 1.0}, "diffuse": {0: 1.0, 1: 0.5, 3: 0.0}}  # reversed order

    def make(run):
        psnr = 30.0 + gains[run.scene][run.labels["sh.degree"]] + 0.01 * run.seed
        return metrics_of(psnr), flat_curves(psnr)

    spec = spec_of(("glossy", "diffuse"), {"sh.degree": [0, 1, 3]})
    report, text = results(tmp_path / "a", spec, make)
    ranked = {(c.scene, c.label): c.value for c in report.findings["ranks"].claims if c.kind == "rank"}
    assert ranked[("glossy", "sh.degree=3")] == 1 and ranked[("diffuse", "sh.degree=3")] == 3
    tau = next(c for c in report.findings["ranks"].claims if c.kind == "tau")
    assert tau.value == pytest.approx(-1.0) and tau.n == 3
    assert "- **Rank agreement across scenes** (Kendall's τ-b" in text and "glossy / diffuse -1.00 (3 cells)" in text
    assert "| `sh.degree=3` | 1 (31.01 dB) | 3 (30.01 dB) |" in text
    assert "no quick version" in text

    # the quick version: the same grid's table, glossy in the same order, diffuse with 0 and 1 swapped
    quick = pd.read_parquet(tmp_path / "a" / "out" / "results.parquet")
    swap = {0: 0.5, 1: 1.0, 3: 0.0}
    quick["metric.test_psnr"] = [30.0 + (gains[s][int(d)] if s == "glossy" else swap[int(d)]) for s, d in
                                 zip(quick.scene, quick["axis.sh.degree"])]
    quick.to_parquet(tmp_path / "quick.parquet")
    spec = spec_of(("glossy", "diffuse"), {"sh.degree": [0, 1, 3]},
                   report={"quick": str(tmp_path / "quick.parquet")})
    report, text = results(tmp_path / "b", spec, make)
    q = {c.scene: c.value for c in report.findings["ranks"].claims if c.kind == "quick tau"}
    # glossy the same order (+1); diffuse: quick 1 > 0 > 3 against 0 > 1 > 3: one discordant pair of 3
    assert q == {"glossy": pytest.approx(1.0), "diffuse": pytest.approx(1 / 3)}
    assert "- **Quick protocol against this one** (Kendall's τ-b" in text and "diffuse +0.33 (3 cells)" in text
    # the Summary repeats them in brief, with how coarse a tau over 3 cells is (3 pairs: steps of 2/3)
    summary = text[text.index("## Summary"):text.index("## Protocol and runs")]
    assert ("- **Ranks**: the two scenes' orders agree by Kendall's τ -1.00; the quick protocol's order against this "
            "one's: glossy +1.00, diffuse +0.33 (over 3 cells a τ-b moves in steps of about 0.67)") in summary
    # a pointer to nothing is one line
    with pytest.raises(InputError, match=r"report\.quick: .*missing\.parquet does not exist"):
        results(tmp_path / "c", spec_of(report={"quick": str(tmp_path / "missing.parquet")}), make)


# --------------------------------------------------------------------------- model size
LOSS_GRID = {"variants": {"size": {"natural": {"strategy.name": "default"},
                                   "matched": {"strategy.name": "budget", "strategy.budget": 600,
                                               "strategy.budget_mode": "final_count"}}}}


def _loss_make(run):
    one = run.labels["loss.ssim_lambda"] == 1.0
    matched = run.labels["size"] == "matched"
    psnr = 30.0 + 0.01 * run.seed + ((0.2 + 0.01 * run.seed) if matched else (1.0 + 0.02 * run.seed)) * one
    count = 600 + run.seed if matched else (5000 if one else 1000) + 10 * run.seed
    return metrics_of(psnr, num_gaussians=count, sh_degree=3), flat_curves(psnr)


def test_a_difference_with_more_gaussians_is_also_given_at_the_matched_size(tmp_path):
    axes = {"loss.ssim_lambda": [0.0, 1.0]}
    spec = spec_of(axes=axes, **LOSS_GRID, report={"matched": {"size": "matched"}})
    assert spec.matched == {"size": ("matched",)}
    report, text = results(tmp_path / "a", spec, _loss_make)
    line = vs_line(text, "1")
    # Gaussians and bytes (59 floats per Gaussian at SH degree 3, 4 bytes each) beside the comparison: the
    # row pools natural and matched runs: seed s has (5000 + 10 s + 600 + s) / 2, 2,805.5 over seeds 0..2
    mb_one = (5000 + 600 + 11 * 1) / 2 * floats_per_gaussian(3) * 4 / 1e6
    assert f"Gaussians and bytes (mean over seeds, `1` against `0`): glossy 2,806 Gaussians, {mb_one:.2f} MB" \
        in appendix_line(text, "1")
    # the matched axis's own rows (matched against natural) are the size comparison itself: nothing added
    assert "**Against model size**" not in vs_line(text, "matched")
    matched = next(c for c in report.findings["loss.ssim_lambda"].claims if c.kind == "matched")
    assert matched.value == pytest.approx(0.21) and matched.reference == "0" and matched.label == "1"
    natural = math.exp(np.mean([math.log((5000 + 10 * s) / (1000 + 10 * s)) for s in range(3)]))  # paired, geometric
    assert f"**Against model size**: glossy: ×{natural:.3f} the Gaussians (≥ 10 % more at its natural size); at the matched " \
           "size (`size = matched` sets `strategy.name = budget`, `strategy.budget = 600`, " \
           "`strategy.budget_mode = final_count`): test PSNR +0.21 dB [95 % CI" in line
    assert "at ×1.000 the Gaussians" in line

    # without [report] matched the same line says that quality and size are not separated
    _, text = results(tmp_path / "b", spec_of(axes=axes, **LOSS_GRID), _loss_make)
    assert "the grid declares no matched-size cell, `[report] matched`: quality and size are not separated" \
        in vs_line(text, "1")


def test_matched_cells_of_the_compared_axis_are_compared_with_each_other(tmp_path):
    variants = {"densify": {"none": {"strategy.name": "none"}, "default": {"strategy.name": "default"},
                            "mcmc": {"strategy.name": "mcmc", "strategy.cap_max": 600},
                            "budget": {"strategy.name": "budget", "strategy.budget": 600,
                                       "strategy.budget_mode": "final_count"}}}
    counts = {"none": 300, "default": 3000, "mcmc": 600, "budget": 600}
    gain = {"none": 0.0, "default": 2.0, "mcmc": 1.5, "budget": 1.0}

    def make(run):
        d = run.labels["densify"]
        psnr = 28.0 + gain[d] + 0.01 * run.seed * (1 + list(gain).index(d))
        return metrics_of(psnr, num_gaussians=counts[d] + run.seed), flat_curves(psnr)

    spec = spec_of(axes={}, variants=variants, report={"matched": {"densify": ["mcmc", "budget"]}})
    report, text = results(tmp_path, spec, make)
    assert "- **At a matched size** (`[report] matched`: `mcmc`, `budget` end at one Gaussians count;" in text
    # budget − mcmc per seed: (1.0 + 0.04 s) − (1.5 + 0.03 s) = −0.5 + 0.01 s, −0.49 over seeds 0..2
    assert "`budget` against `mcmc`: glossy -0.49 dB [95 % CI" in text and "at ×1.000 the Gaussians." in text
    # default (×10 the Gaussians of none) has no matched-size cell of its own: said so
    assert "no matched-size cell of this comparison: the matched cells are `mcmc`, `budget`" \
        in vs_line(text, "default")


def test_report_matched_and_quick_are_checked_when_the_file_is_read():
    with pytest.raises(InputError, match=r"report\.matched\.size: 'smaller' is not a value of the grid's 'size'"):
        spec_of(axes={"loss.ssim_lambda": [0.0]}, **LOSS_GRID, report={"matched": {"size": "smaller"}})
    with pytest.raises(InputError, match=r"report\.matched\.lr: not an axis of the grid"):
        spec_of(report={"matched": {"lr": 1}})
    with pytest.raises(InputError, match=r"report\.quick: expected the path"):
        spec_of(report={"quick": 3})


# --------------------------------------------------------------------------- header
def test_the_scenes_line_counts_real_captures_and_a_quick_report_says_smoke_test(tmp_path):
    _, text = results(tmp_path, spec_of(("glossy", "diffuse", "thin")), lambda run: (
        metrics_of(30.0 + run.seed * 0.1), flat_curves(30.0)))
    lines = text.splitlines()
    assert lines[2].startswith("**A smoke test, not evidence**: this grid's runs follow the quick protocol")
    table = pd.read_parquet(tmp_path / "out" / "results.parquet")
    scenes = lambda t: next(x for x in protocol_lines(t) if x.startswith("- **Scenes**"))  # noqa: E731
    assert "0 real captures; a finding here holds on these scenes only" in scenes(table)
    # two dataset folders (config.data.path) are real captures; a teacher scene is not
    table["config.data.path"] = [("/data/" + s) if s in ("glossy", "diffuse") else None for s in table.scene]
    assert scenes(table).startswith("- **Scenes**: 3: diffuse (a real capture), glossy (a real capture), thin "
                                    "(rendered by Mitsuba); enough scenes for a headline (3, 2 of them real captures: "
                                    "docs/reports.md).")
    table["config.data.path"] = [("/data/" + s) if s == "glossy" else None for s in table.scene]
    table["config.data.model"] = [("/m/" + s) if s == "diffuse" else None for s in table.scene]
    assert "diffuse (a teacher scene rendered from a trained model, not a capture)" in scenes(table)
    assert "1 real capture; a finding here" in scenes(table)
    # a teacher scene is fit by the model family and rasterizer that rendered it: the line says so, once
    assert scenes(table).count("Inverse crime: diffuse was rendered by this project's rasterizer from a trained "
                               "3DGS model and is fit by the same model family and rasterizer") == 1
    assert "its absolute numbers are not comparable with captures or published numbers." in scenes(table)
    # a Mitsuba scene is no inverse crime, and no published benchmark either; a capture is neither
    assert " thin, rendered by Mitsuba (not by this rasterizer: no inverse crime in the images, though a start " \
           "from the scene's own surface is exact geometry no capture has), is no published benchmark: its " \
           "absolute numbers are not the field's." in scenes(table)
    table["config.data.path"] = [("/data/" + s) for s in table.scene]  # three captures: no note at all
    table["config.data.model"] = None
    assert "Inverse crime" not in scenes(table) and "Mitsuba" not in scenes(table)
    # a report at graphdeco's 7K column is no smoke test
    assert smoke_test_line(table.assign(**{"config.protocol": "graphdeco-7k"})) == []
    assert smoke_test_line(table)[0].startswith("**A smoke test, not evidence**")


def test_a_peak_before_a_reset_says_the_reset_lies_between():
    """fox's SH 3 at 7K peaked at 5,600 and was 0.13 dB below it at 7,000, one evaluation after the
    opacity reset at 6,000: the rule is unchanged (past its peak), and the text names the reset between
    the best step and the end, which a reader needs to tell a reset's dip from a fall; a reset before
    the best step is not named."""
    import dataclasses

    frame = _peaked(0.3).assign(**{"config.iterations": 7000})  # a config column: the resets are read
    at = {"reset": 2500}  # the curve is at its best (2,100) at its last evaluation before: it fell after
    keys = dataclasses.replace(TRAIN_REPORT.settling, resets=lambda config: (1000, at["reset"]))
    cell = cell_settling(frame, keys, 0.1)
    assert cell.past_peak and cell.reset_after_best == 2500
    assert "past its peak (best at step 2,100, 0.30 dB above its last value; the reset at step 2,500 lies " \
           "between)" in cell.why_not()
    # a reset after the fall (at 4,200 the curve is 0.3 dB below its best, glossy's case): not named
    for reset in (2000, 5000):  # before the best step (2,100), or after the curve had already fallen
        at["reset"] = reset
        cell = cell_settling(frame, keys, 0.1)
        assert cell.reset_after_best is None and cell.why_not().endswith("0.30 dB above its last value)"), reset


def test_the_uint8_shift_the_metrics_line_states_is_what_quantizing_does():
    """The Metrics line says how much lower a float-image PSNR would read on uint8 (the field's
    metrics): Sheppard's correction, 1/(12·255²) added to the MSE. Checked by quantizing: uint8
    targets, predictions off by a smooth residual of RMSE 0.02 (34 dB); the sample's MSE increase
    matches within its Monte Carlo error: each pixel's increase 2·e·q + q² has sd about 2 · 0.02 · (1/255)/√12
    = 4.5e-5, so its mean over 4e6 pixels has a standard error of 2.3e-8, 1.8 % of 1.28e-6: the 5 %
    tolerance is 2.8 of them (a fixed seed; a formula off by a factor, e.g. 1/(4·255²), fails)."""
    from splatbench.experiments.train_report import UINT8_MSE, _uint8_shift

    rng = np.random.default_rng(0)
    target = rng.integers(20, 236, 4_000_000) / 255.0
    pred = target + rng.normal(0.0, 0.02, target.size)
    added = np.mean((np.round(pred * 255) / 255 - target) ** 2) - np.mean((pred - target) ** 2)
    assert added == pytest.approx(UINT8_MSE, rel=0.05)
    text = _uint8_shift(pd.DataFrame({"metric.test_psnr": [30.0, 34.0]}))
    drop = 10 * math.log10(1 + UINT8_MSE * 10 ** 3.4)
    assert f"at 34.0 dB, this grid's highest run mean, about {drop:.3f} dB lower" in text and 0.01 < drop < 0.02
    assert _uint8_shift(pd.DataFrame({"seed": [0]})) == ""


def test_a_strategy_note_filed_among_warnings_is_listed_but_not_counted(tmp_path):
    """Runs made before the training loop told a strategy's note from its warning recorded the budget
    strategy's last-refinement prune ("strategy 'budget' ended at 13,976 Gaussians, 24 below ...") among
    their warnings: the Summary and the header count only what starts with "warning:"; the Warnings
    section still lists every entry (nothing a run recorded is dropped) and says which are notes."""
    from splatbench.experiments import RunRecord, expand
    from splatbench.experiments.store import write_record, write_table
    from splatbench.reports import build_report, write_report

    spec = spec_of()
    records = []
    for run in expand(spec):
        psnr = 30.0 + (1.0 if run.config["sh"]["degree"] == 3 else 0.0) + 0.01 * run.seed
        said = {0: ["strategy 'budget' ended at 13,976 Gaussians, 24 below its budget of 14,000"],
                1: ["warning: strategy 'budget' ended at 84 Gaussians, below its budget of 120"]}.get(run.seed, [])
        rec = RunRecord(run_id=run.run_id, experiment=spec.name, kind="train", scene=run.scene, seed=run.seed,
                        status="done", config=dict(run.config), labels=dict(run.labels),
                        metrics=metrics_of(psnr), curves=flat_curves(psnr), error=None, seconds=1.0,
                        started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:01+00:00", worker="h:1",
                        warnings=tuple(said))
        write_record(tmp_path / "res", rec)
        records.append(rec)
    write_table(tmp_path / "res" / spec.name, records)
    text = write_report(build_report(spec, tmp_path / "res"), tmp_path / "out").read_text()
    assert "**Warnings**: 2 of 6 runs warned (1 distinct: \"warning: strategy 'budget' ended at 84" in text
    assert "**Warnings:** 2 run(s) warned" in text
    section = text[text.index("## Warnings"):]
    assert "2 entries without \"warning:\" are strategies' notes" in section
    assert section.count("ended at 13,976 Gaussians") == 2 and section.count("ended at 84 Gaussians") == 2
