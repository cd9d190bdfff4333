"""``[extra.DIMENSION]``: cells outside the grid (docs/experiments.md, "Extra cells"), as
experiments/sh_degree.toml's bytes-matched SH 0 / SH 3 pair: the grid's run ids stay what they
were, the extra cells are crossed with nothing, they are rows of their dimension's table only, and
the report compares them only where ``[report] matched`` names them (docs/reports.md, "Model
size"): the primary comparisons against the reference, their Holm family and the best are the
grid's alone.

Results folders are written by hand (made-up metrics and curves), as tests/test_report_rules.py
does: no training runs.
"""

from __future__ import annotations

import numpy as np
import pytest

from splatbench.errors import InputError
from splatbench.experiments import expand, parse_experiment
from splatbench.experiments.train_report import floats_per_gaussian
from splatbench.reports.tables import axis_rows
from tests.test_report_rules import flat_curves, metrics_of, results

#: 590 Gaussians at SH 0 and 140 at SH 3 hold the same floats: 590 x 14 = 140 x 59 = 8,260.
BUDGET = {0: 590, 3: 140}
BUDGETED = {"strategy.name": "budget", "strategy.budget_mode": "final_count"}
EXTRA = {"sh.degree": {f"{d} at {n}": {"sh.degree": d, "strategy.budget": n, **BUDGETED} for d, n in BUDGET.items()}}
MATCHED = {"matched": {"sh.degree": ["0 at 590", "3 at 140"]}}


def spec_of(axes=None, scenes=("glossy",), **more):
    return parse_experiment({"name": "extra", "kind": "train", "scenes": list(scenes), "seeds": [0, 1, 2],
                             "base": {"iterations": 2000, "data": {"resolution": 32, "views": 8, "spp": 2}},
                             "axes": axes if axes is not None else {"sh.degree": [0, 1, 3]}, **more},
                            source="x.toml")


def test_the_bytes_of_the_pair_are_equal():
    assert BUDGET[0] * floats_per_gaussian(0) == BUDGET[3] * floats_per_gaussian(3)


# --------------------------------------------------------------------------- the grid
def test_extra_cells_add_runs_and_leave_the_grids_run_ids_as_they_were():
    axes = {"sh.degree": [0, 1, 3], "loss.ssim_lambda": [0.0, 0.2]}
    plain = expand(spec_of(axes, ("glossy", "diffuse")))
    runs = expand(spec_of(axes, ("glossy", "diffuse"), extra=EXTRA))
    grid = [r for r in runs if r.labels["sh.degree"] in (0, 1, 3)]
    assert [r.run_id for r in grid] == [r.run_id for r in plain]  # the same ids, in the same order
    # crossed with nothing: 2 cells x 2 scenes x 3 seeds, after each scene's grid cells
    extra = [r for r in runs if r not in grid]
    assert len(runs) == len(plain) + 2 * 2 * 3 and len(extra) == 12
    assert [r.labels["sh.degree"] for r in runs[:24]] == [0] * 6 + [1] * 6 + [3] * 6 + ["0 at 590"] * 3 + \
        ["3 at 140"] * 3
    for r in extra:
        d = int(r.labels["sh.degree"][0])
        assert (r.config["sh"]["degree"], r.config["strategy"]["budget"]) == (d, BUDGET[d])
        assert r.config["loss"]["ssim_lambda"] == 0.2  # the base's (the kind's default), not an axis value's
        assert r.labels["loss.ssim_lambda"] == 0.2
    # a check names the grid's cells only, and its runs are the same with or without extra cells
    check = {"protocol": "graphdeco-7k", "scene": "glossy", "cells": [{"sh.degree": 0}, {"sh.degree": 3}]}
    from splatbench.experiments import check_runs
    assert [r.run_id for r in check_runs(spec_of(check=check))] == \
        [r.run_id for r in check_runs(spec_of(check=check, extra=EXTRA))]
    with pytest.raises(InputError, match=r"check\.cells\[1\]\.sh\.degree: '3 at 140' is not a value"):
        spec_of(check={**check, "cells": [{"sh.degree": 0}, {"sh.degree": "3 at 140"}]}, extra=EXTRA)


def test_an_extra_cell_is_a_row_of_its_dimension_alone():
    spec = spec_of({"sh.degree": [0, 3], "loss.ssim_lambda": [0.0, 0.2]}, extra=EXTRA)
    plain = spec_of({"sh.degree": [0, 3], "loss.ssim_lambda": [0.0, 0.2]})
    runs = expand(spec)
    rows = axis_rows(spec, "sh.degree")
    assert [(r.label, r.extra) for r in rows] == [("0", False), ("3", False), ("0 at 590", True), ("3 at 140", True)]
    assert rows[:2] == axis_rows(plain, "sh.degree")  # the grid's rows pool what they pooled before
    assert rows[2].run_ids == {r.run_id for r in runs if r.labels["sh.degree"] == "0 at 590"} and len(rows[2].run_ids) == 3
    assert axis_rows(spec, "loss.ssim_lambda") == axis_rows(plain, "loss.ssim_lambda")  # not a row of another axis


@pytest.mark.parametrize("extra, message", [
    ({"lr": {"a": {"sh.degree": 0}}}, r"extra\.lr: not an axis of the grid"),
    ({"sh.degree": {"3": {"sh.degree": 3, **BUDGETED}}}, r"extra\.sh\.degree\.3: a value of the grid's 'sh\.degree'"),
    ({"sh.degree": {"a": 3}}, r"extra\.sh\.degree\.a: expected a table of config fields"),
    ({"sh.degree": {}}, r"extra\.sh\.degree: expected a table of label"),
    ({"sh.degree": {"a": {"seed": 1}}}, r"extra\.sh\.degree\.a: 'seed' is set by the top-level"),
    ({"sh.degree": {"a": {"sh.degree": 1}}}, r"extra\.sh\.degree\.a: the same runs as a cell of the grid"),
    ({"sh.degree": {"a": {"sh.degree": 9}}}, r"extra\.sh\.degree\.a: .*sh"),
    ({"sh.degree": {"a": {"scenes": ["thin"], **BUDGETED}}}, r"extra\.sh\.degree\.a\.scenes: 'thin' is not one of"),
    ({"sh.degree": {"a": {"scenes": ["glosy"], **BUDGETED}}}, r"'glosy' is not one of .*; did you mean 'glossy'\?"),
    ({"sh.degree": {"a": {"scenes": "glossy", **BUDGETED}}},
     r"extra\.sh\.degree\.a\.scenes: expected a list of distinct scene names \(e\.g\. scenes = \['glossy'\]\)"),
    ({"sh.degree": {"a": {"scenes": [], **BUDGETED}}}, r"extra\.sh\.degree\.a\.scenes: expected a list"),
])
def test_a_bad_extra_cell_is_one_line(extra, message):
    with pytest.raises(InputError, match=message) as caught:
        expand(spec_of(extra=extra))
    assert "\n" not in str(caught.value)


def test_matched_may_name_extra_cells_and_nothing_else():
    assert spec_of(extra=EXTRA, report=MATCHED).matched == {"sh.degree": ("0 at 590", "3 at 140")}
    with pytest.raises(InputError, match=r"report\.matched\.sh\.degree: '0 at 591' is not a value"):
        spec_of(extra=EXTRA, report={"matched": {"sh.degree": ["0 at 591", "3 at 140"]}})


@pytest.mark.parametrize("matched, message", [
    # one extra label: crossed with nothing, it is no cell's twin (a new user's trial: every size line vanished)
    ("3 at 140", r"'3 at 140' is an extra cell, crossed with nothing, .*\['0 at 590', '3 at 140'\]"),
    (["3 at 140"], r"a list names cells matched to each other: give two or more"),
    (3, r"one value names each cell's matched twin on another axis, and the grid has no other"),
    ("0", r"'0' is not a value of the grid's 'sh\.degree' \(its values: 0, 1, 3, .*\); write 0$"),
])
def test_a_matched_entry_that_names_no_comparison_is_one_line(matched, message):
    with pytest.raises(InputError, match=message) as caught:
        spec_of(extra=EXTRA, report={"matched": {"sh.degree": matched}})
    assert "\n" not in str(caught.value)


def test_two_matched_extra_cells_of_one_value_are_one_line():
    """With a 2x2 of extra cells (SH 0 and SH 3, each at both budgets), a list naming both SH 0 cells
    has no single twin of the grid's SH 0: the findings would pick one silently."""
    extra = {"sh.degree": {**EXTRA["sh.degree"],
                           **{f"{d} at {n}": {"sh.degree": d, "strategy.budget": n, **BUDGETED}
                              for d, n in ((0, 140), (3, 590))}}}
    assert spec_of(extra=extra, report={"matched": {"sh.degree": ["0 at 140", "3 at 140"]}}).matched \
        == {"sh.degree": ("0 at 140", "3 at 140")}
    with pytest.raises(InputError, match=r"report\.matched\.sh\.degree: the extra cells '0 at 590' and '0 at 140' "
                                         r"both set sh\.degree = 0, .*name one extra cell per value") as caught:
        spec_of(extra=extra, report={"matched": {"sh.degree": ["0 at 590", "3 at 140", "0 at 140"]}})
    assert "\n" not in str(caught.value)


def test_matched_extra_cells_of_one_value_at_disjoint_scenes_are_each_scenes_own():
    """Two cells setting one value are allowed where their ``scenes`` are disjoint (each scene's matched
    size its own); where they share a scene, or one runs everywhere, that scene is named on one line."""
    scenes = ("glossy", "diffuse", "thin")
    per_scene = {"sh.degree": {f"{d} at {n}": {"sh.degree": d, "strategy.budget": n, "scenes": [scene], **BUDGETED}
                               for scene, (n0, n3) in (("glossy", (590, 140)), ("diffuse", (1180, 280)))
                               for d, n in ((0, n0), (3, n3))}}
    names = ["0 at 590", "3 at 140", "0 at 1180", "3 at 280"]
    spec = spec_of(scenes=scenes, extra=per_scene, report={"matched": {"sh.degree": names}})
    assert spec.matched == {"sh.degree": tuple(names)}
    overlap = {"sh.degree": {**per_scene["sh.degree"],
                             "0 at 1180": {**per_scene["sh.degree"]["0 at 1180"], "scenes": ["thin", "glossy"]}}}
    with pytest.raises(InputError, match=r"report\.matched\.sh\.degree: the extra cells '0 at 590' and '0 at 1180' "
                                         r"both set sh\.degree = 0, both at glossy, .*disjoint `scenes`") as caught:
        spec_of(scenes=scenes, extra=overlap, report={"matched": {"sh.degree": names}})
    assert "\n" not in str(caught.value)
    everywhere = {"sh.degree": {**per_scene["sh.degree"], "3 at 280": {"sh.degree": 3, "strategy.budget": 280,
                                                                          **BUDGETED}}}
    with pytest.raises(InputError, match=r"the extra cells '3 at 140' and '3 at 280' both set sh\.degree = 3, both "
                                         r"at glossy, ") as caught:
        spec_of(scenes=scenes, extra=everywhere, report={"matched": {"sh.degree": names}})
    assert "\n" not in str(caught.value)


# --------------------------------------------------------------------------- the report
def _make(run):
    """Natural cells: 1000 Gaussians (+ 10 per seed); SH 3 +1.0 dB (+0.02 per seed) and SH 1 +0.5 dB
    over SH 0. The extra cells at their budgets: SH 3 +0.3 dB (+0.02 per seed) over SH 0."""
    label = run.labels["sh.degree"]
    degree = run.config["sh"]["degree"]
    if isinstance(label, str):
        psnr = 29.0 + 0.01 * run.seed + ((0.3 + 0.02 * run.seed) if degree == 3 else 0.0)
        count = BUDGET[degree]
    else:
        psnr = 30.0 + 0.01 * run.seed + {0: 0.0, 1: 0.5 + 0.01 * run.seed, 3: 1.0 + 0.02 * run.seed}[degree]
        count = 1000 + 10 * run.seed
    return metrics_of(psnr, num_gaussians=count, sh_degree=degree), flat_curves(psnr)


def _report(tmp_path, spec, keep=lambda run: True):
    """The report of ``spec`` from made-up results (`_make`) of the runs ``keep`` selects."""
    return results(tmp_path, spec, _make, keep)


def _primary(report) -> list[tuple]:
    """The claims of the grid's own comparisons: each row against the reference (Holm's family among
    them), Holm's line and the best."""
    return [(c.kind, c.scene, c.label, c.metric, c.value, c.low, c.high, c.significant, c.text)
            for c in report.findings["sh.degree"].claims if c.kind in ("vs", "holm", "best", "no best", "size")]


def _line(text: str, label: str) -> str:
    return next(line for line in text.splitlines() if line.startswith(f"  - `{label}`: "))


def test_extra_cells_are_compared_only_at_a_matched_size(tmp_path):
    scenes = ("glossy", "diffuse")
    plain, plain_text = _report(tmp_path / "a", spec_of(scenes=scenes))
    report, text = _report(tmp_path / "b", spec_of(scenes=scenes, extra=EXTRA, report=MATCHED))
    # the grid's comparisons, Holm's family and the best are what they are without the extra cells
    assert _primary(report) == _primary(plain) and any(c[0] == "holm" for c in _primary(report))
    assert "  - `0 at 590`: " not in text and "  - `3 at 140`: " not in text  # never against the reference
    holm = next(line for line in text.splitlines() if line.startswith("- **Holm's correction**"))
    assert holm in plain_text and "over the 4 test PSNR comparisons" in holm
    # the extra cells' rows in the table
    assert "| glossy | `0 at 590` | 3 | 29.01 ± " in text and "| diffuse | `3 at 140` | 3 | 29.33 ± " in text
    # their difference: (0.3 + 0.02 s) over seeds 0..2, +0.32 dB, at x1.000 the bytes (8,260 floats each)
    # what each extra cell sets besides its axis value is named (the budget strategy: not the grid's)
    head = ("- **At a matched size** (`[report] matched`: `0 at 590`, `3 at 140` end at one byte count; "
            "`sh.degree = 0 at 590` sets `strategy.budget = 590`, `strategy.name = budget`, `strategy.budget_mode = "
            "final_count`; `sh.degree = 3 at 140` sets `strategy.budget = 140`, `strategy.name = budget`, "
            "`strategy.budget_mode = final_count`): `3 at 140` against `0 at 590`: glossy +0.32 dB [95 % CI ")
    assert head in text
    matched = [c for c in report.findings["sh.degree"].claims if c.kind == "matched"]
    assert [(c.scene, c.label, c.reference, round(c.value, 6)) for c in matched] == \
        [("glossy", "3 at 140", "0 at 590", 0.32), ("diffuse", "3 at 140", "0 at 590", 0.32)]
    # SH 3 against SH 0 (×4 the bytes) gives the pair's difference; SH 1 has no pair: said so
    three = _line(text, "3")
    assert "(≥ 10 % larger at its natural size); at a matched size (`3 at 140` against `0 at 590`): test PSNR " \
           "+0.32 dB [95 % CI" in three and "at ×1.000 the bytes (×0.237 the Gaussians)" in three
    assert "quality and size are not separated" not in three and "quality and size are not separated" in \
        _line(plain_text, "3")
    assert "no matched-size cell of this comparison: the matched cells are `0 at 590`, `3 at 140`" in _line(text, "1")
    # the Summary's line of `3` gives the matched-size difference beside the size change, per scene
    summary = next(line for line in text.splitlines() if line.startswith("- **`3`** against `0`"))
    assert "; at a matched size (`3 at 140` against `0 at 590`, both also setting `strategy.name = budget`, " \
           "`strategy.budget_mode = final_count`; not in Holm's family): glossy +0.32 dB [95 % CI " in summary and \
        "; diffuse +0.32 dB [95 % CI " in summary


def test_extra_cells_without_runs_say_so_and_change_no_comparison(tmp_path):
    spec = spec_of(extra=EXTRA, report=MATCHED)
    plain, _ = _report(tmp_path / "a", spec_of())
    report, text = _report(tmp_path / "b", spec, keep=lambda run: not isinstance(run.labels["sh.degree"], str))
    assert _primary(report) == _primary(plain)
    assert "(9 done, 0 failed, 6 not run)" in text
    assert "and 2 extra cells outside it (`sh.degree = 0 at 590`, `sh.degree = 3 at 140`" in text
    assert "| glossy | `3 at 140` | 0 | – |" in text
    assert "`strategy.budget_mode = final_count`): no done runs of these cells yet, so nothing is compared at a " \
           "matched size." in text
    assert "its matched-size cells, `3 at 140` against `0 at 590`, have no done runs yet)" in _line(text, "3")
    assert not [c for c in report.findings["sh.degree"].claims if c.kind == "matched"]


def test_an_extra_cell_runs_at_its_scenes_alone_and_the_report_says_where_it_did_not(tmp_path):
    """``scenes = [...]`` in an extra cell (sh_degree's pair on its captures: glossy's 20,000-Gaussian
    start is over SH 3's budget): its runs are at those scenes alone, the grid's unchanged, and the
    comparison it would repeat says at a scene without it that quality and size are not separated
    there (not "no done runs yet", which would promise runs that the file never makes)."""
    scenes = ("glossy", "diffuse")
    only = {"sh.degree": {k: {**v, "scenes": ["diffuse"]} for k, v in EXTRA["sh.degree"].items()}}
    spec = spec_of(scenes=scenes, extra=only, report=MATCHED)
    runs = expand(spec)
    everywhere = expand(spec_of(scenes=scenes, extra=EXTRA, report=MATCHED))
    extra = [r for r in runs if isinstance(r.labels["sh.degree"], str)]
    assert {r.scene for r in extra} == {"diffuse"} and len(extra) == 2 * 3
    assert [r.run_id for r in runs] == [r.run_id for r in everywhere if r.scene == "diffuse"
                                        or not isinstance(r.labels["sh.degree"], str)]
    report, text = _report(tmp_path, spec)
    three = _line(text, "3")
    assert "its matched-size cells, `3 at 140` against `0 at 590`, are not run at glossy (their `scenes`): quality " \
           "and size are not separated here)" in three
    assert "at a matched size (`3 at 140` against `0 at 590`): test PSNR +0.32 dB [95 % CI" in three  # diffuse
    matched = [c for c in report.findings["sh.degree"].claims if c.kind == "matched"]
    assert [(c.scene, c.label) for c in matched] == [("diffuse", "3 at 140")]
    summary = next(line for line in text.splitlines() if line.startswith("- **`3`** against `0`"))
    assert "; at a matched size (`3 at 140` against `0 at 590`, both also setting `strategy.name = budget`, " \
           "`strategy.budget_mode = final_count`; not in Holm's family): glossy not run (the pair's `scenes`); diffuse " \
           "+0.32 dB" in summary
    # the table has no rows of the pair at glossy (none were to run there), and its rows at diffuse
    assert "| glossy | `3 at 140` |" not in text and "| diffuse | `3 at 140` | 3 |" in text
    assert "2 extra cells outside it (`sh.degree = 0 at 590` (diffuse only), `sh.degree = 3 at 140` (diffuse only)" in text


def test_a_matched_pair_on_three_scenes_gives_its_difference_over_the_scenes(tmp_path):
    """The pair's differences 0.2, 0.3 and 0.7 dB (+0.02 dB a seed: each scene's mean is its gain + 0.02) at
    three scenes, not run at a fourth: the Summary adds their mean with a t interval over the three scenes
    (df 2), as `findings.over_scenes` does for the grid's comparisons; the fourth is left out, not a gap."""
    from scipy import stats

    gains = {"diffuse": 0.2, "textured": 0.3, "thin": 0.7}
    scenes = ("glossy", *gains)
    only = {"sh.degree": {k: {**v, "scenes": list(gains)} for k, v in EXTRA["sh.degree"].items()}}

    def make(run):
        metrics, curves = _make(run)
        if isinstance(run.labels["sh.degree"], str) and run.config["sh"]["degree"] == 3:
            psnr = 29.0 + 0.01 * run.seed + gains[run.scene] + 0.02 * run.seed
            return metrics_of(psnr, num_gaussians=BUDGET[3], sh_degree=3), flat_curves(psnr)
        return metrics, curves

    _, text = results(tmp_path, spec_of(scenes=scenes, extra=only, report=MATCHED), make)
    diffs = np.array([g + 0.02 for g in gains.values()])
    half = stats.t.ppf(0.975, 2) * diffs.std(ddof=1) / np.sqrt(3)
    summary = next(line for line in text.splitlines() if line.startswith("- **`3`** against `0`"))
    assert "glossy not run (the pair's `scenes`)" in summary
    assert (f"; thin +0.72 dB [95 % CI +0.67, +0.77]; over the scenes, taken as a random sample of scenes (df 2; not "
            f"in Holm's family), {diffs.mean():+.2f} dB [95 % CI {diffs.mean() - half:+.2f}, "
            f"{diffs.mean() + half:+.2f}], no significant difference, inconclusive.") in summary


def test_per_scene_matched_cells_compare_each_scene_with_its_own_cells(tmp_path):
    """A matched size per scene: glossy's pair at 590 / 140 Gaussians, diffuse's at 1,180 / 280 (each pair
    at one byte count, 1,180 x 14 = 280 x 59), each cell run at its scene alone. Each scene's matched
    difference is from its own cells: SH 3 +0.3 dB (+0.02 a seed) over SH 0 at glossy, +0.9 dB at diffuse;
    SH 0's cells differ by scene (29.0 and 27.0 dB), so a difference against the other scene's SH 0 cell,
    or the other scene's gain, gives neither value (and the other scene's cells have no runs here)."""
    budgets = {"glossy": (590, 140), "diffuse": (1180, 280)}
    gains, floors = {"glossy": 0.3, "diffuse": 0.9}, {"glossy": 29.0, "diffuse": 27.0}
    extra = {"sh.degree": {f"{d} at {n}": {"sh.degree": d, "strategy.budget": n, "scenes": [scene], **BUDGETED}
                           for scene, (n0, n3) in budgets.items() for d, n in ((0, n0), (3, n3))}}
    names = ["0 at 590", "3 at 140", "0 at 1180", "3 at 280"]
    spec = spec_of(scenes=tuple(budgets), extra=extra, report={"matched": {"sh.degree": names}})

    def make(run):
        metrics, curves = _make(run)
        if not isinstance(run.labels["sh.degree"], str):
            return metrics, curves
        degree = run.config["sh"]["degree"]
        psnr = floors[run.scene] + 0.01 * run.seed + ((gains[run.scene] + 0.02 * run.seed) if degree == 3 else 0.0)
        count = run.config["strategy"]["budget"]
        return metrics_of(psnr, num_gaussians=count, sh_degree=degree), flat_curves(psnr)

    report, text = results(tmp_path, spec, make)
    # the matched cells against each other: each scene's SH 3 cell against that scene's SH 0 cell
    matched = [c for c in report.findings["sh.degree"].claims if c.kind == "matched"]
    assert [(c.scene, c.label, c.reference, round(c.value, 6)) for c in matched] == \
        [("glossy", "3 at 140", "0 at 590", 0.32), ("diffuse", "3 at 280", "0 at 1180", 0.92)]
    line = next(line for line in text.splitlines() if line.startswith("- **At a matched size**"))
    assert "end at one byte count at each scene, each value one cell there (their `scenes`); " in line
    assert "): `3 at 140` against `0 at 590`: glossy +0.32 dB [95 % CI " in line and \
        ". `3 at 280` against `0 at 1180`: diffuse +0.92 dB [95 % CI " in line and "at ×1.000 the bytes" in line
    assert "`0 at 1180` against" not in line  # SH 0's second cell is diffuse's reference, not a compared cell
    # the grid's SH 3 against SH 0, at each scene through that scene's pair
    three = _line(text, "3")
    assert "at a matched size (`3 at 140` against `0 at 590`): test PSNR +0.32 dB [95 % CI" in three
    assert "at a matched size (`3 at 280` against `0 at 1180`): test PSNR +0.92 dB [95 % CI" in three
    assert "not run at" not in three
    summary = next(line for line in text.splitlines() if line.startswith("- **`3`** against `0`"))
    # the Summary reads the scenes as one list: what every pair sets once, each scene with its own pair,
    # and no interval over the scenes (each pair is at its own scene's size)
    assert "; at a matched size (each scene's own pair, both cells also setting `strategy.name = budget`, " \
           "`strategy.budget_mode = final_count`; " \
           "not in Holm's family): glossy (`3 at 140` against `0 at 590`) +0.32 dB [95 % CI " in summary, summary
    assert "; diffuse (`3 at 280` against `0 at 1180`) +0.92 dB [95 % CI " in summary and summary.count("at a matched") == 1
    assert "over the scenes" not in summary.split("at a matched size")[1]


def test_the_ranks_order_the_grids_cells_alone(tmp_path):
    """An extra cell is a size control, compared only at a matched size: the Ranks section orders the
    grid's cells as it does without the extra cells (rank and tau claims equal)."""
    plain, _ = _report(tmp_path / "a", spec_of(scenes=("glossy", "diffuse")))
    report, text = _report(tmp_path / "b", spec_of(scenes=("glossy", "diffuse"), extra=EXTRA, report=MATCHED))
    def ranked(r):
        return [(c.kind, c.scene, c.label, c.value) for c in r.findings["ranks"].claims]
    assert ranked(report) == ranked(plain) and ranked(report)
    ranks = text[text.index("## Appendix: Ranks"):]
    assert "`0 at 590`" not in ranks.split("\n- ")[0]


def test_a_pair_that_missed_its_count_or_still_moves_says_so(tmp_path):
    """Cells declared matched are matched only where they ended at one size: an SH 0 budget run that
    fell short (ended at 140 Gaussians, x4.2 fewer bytes than SH 3 at 140) is said to be not at one size,
    never claimed at a matched size (a new user's trial: a pair x4.07 apart was printed "at a matched
    size"). A pair whose curves still rise is marked not settled, as the grid's comparisons are."""
    def short(run):  # SH 0's budget cell ends at SH 3's count; SH 3's extra cell still rises fast
        metrics, curves = _make(run)
        label = run.labels["sh.degree"]
        if label == "0 at 590":
            metrics = {**metrics, "num_gaussians": 140}
        if label == "3 at 140":
            curves = flat_curves(metrics["test_psnr"], rise=0.6)
        return metrics, curves

    report, text = results(tmp_path / "short", spec_of(extra=EXTRA, report=MATCHED), short)
    three = _line(text, "3")
    assert "its matched-size cells, `3 at 140` against `0 at 590`, did not end at one size at glossy: test PSNR " \
           "+0.32 dB" in three and "at ×4.214 the bytes" in three and "quality and size are not separated here" in three
    matched = next(line for line in text.splitlines() if line.startswith("- **At a matched size**"))
    assert "glossy +0.32 dB" in matched and ": **not at one size** (a run that missed its count" in matched
    assert not [c for c in report.findings["sh.degree"].claims if c.kind == "matched"]
    summary = next(line for line in text.splitlines() if line.startswith("- **`3`** against `0`"))
    assert "not in Holm's family): glossy not at one size (×4.214)" in summary

    def rising(run):  # at one size, but SH 3's extra cell still rises 0.6 dB over the last quarter
        metrics, curves = _make(run)
        return metrics, (flat_curves(metrics["test_psnr"], rise=0.6) if run.labels["sh.degree"] == "3 at 140"
                         else curves)

    report, text = results(tmp_path / "rising", spec_of(extra=EXTRA, report=MATCHED), rising)
    matched = next(line for line in text.splitlines() if line.startswith("- **At a matched size**"))
    assert "at ×1.000 the bytes" in matched and ", **not settled** (" in matched
    assert ", **not settled** (" in _line(text, "3").split("at a matched size")[1]
    summary = next(line for line in text.splitlines() if line.startswith("- **`3`** against `0`"))
    assert "not in Holm's family): glossy +0.32 dB [95 % CI " in summary and "], not settled" in summary


def test_extra_cells_of_a_variant_axis_say_what_they_set():
    """densification.toml's mcmc and budget are extra cells of its `densify` variant: the matched line
    names their fields as it names a variant's (an extra label is no variant: looking it up there failed)."""
    from splatbench.reports.findings import setting_text

    spec = parse_experiment({"name": "d", "kind": "train", "scenes": ["glossy"], "seeds": [0],
                             "base": {"iterations": 100, "data": {"resolution": 32, "views": 8, "spp": 2}},
                             "variants": {"densify": {"none": {"strategy": {"name": "none"}},
                                                      "default": {"strategy": {"name": "default"}}}},
                             "extra": {"densify": {"mcmc": {"strategy": {"name": "mcmc", "cap_max": 600}},
                                                   "budget": {"strategy": {"name": "budget", "budget": 600,
                                                                           "budget_mode": "final_count"}}}},
                             "report": {"matched": {"densify": ["mcmc", "budget"]}}}, source="x.toml")
    assert setting_text(spec, "densify", ["mcmc", "budget"]) == (
        "`densify = mcmc` sets `strategy.name = mcmc`, `strategy.cap_max = 600`; `densify = budget` sets "
        "`strategy.name = budget`, `strategy.budget = 600`, `strategy.budget_mode = final_count`")


def test_extra_cells_that_set_the_same_fields_say_them_once():
    """loss_weighting.toml's three matched cells set the same budget-strategy fields: the matched line says
    them once ("... each set ..."), not three times; cells that differ keep one clause each (above)."""
    from splatbench.reports.findings import setting_text

    budget = {"name": "budget", "budget": 600, "budget_mode": "final_count"}
    spec = parse_experiment({"name": "w", "kind": "train", "scenes": ["glossy"], "seeds": [0],
                             "base": {"iterations": 100, "data": {"resolution": 32, "views": 8, "spp": 2}},
                             "axes": {"loss.ssim_lambda": [0.2, 0.0]},
                             "extra": {"loss.ssim_lambda": {
                                 "0.2 at 600": {"loss": {"ssim_lambda": 0.2}, "strategy": budget},
                                 "0 at 600": {"loss": {"ssim_lambda": 0.0}, "strategy": budget}}},
                             "report": {"matched": {"loss.ssim_lambda": ["0.2 at 600", "0 at 600"]}}}, source="x.toml")
    assert setting_text(spec, "loss.ssim_lambda") == (
        "`loss.ssim_lambda = 0.2 at 600` and `loss.ssim_lambda = 0 at 600` each set `strategy.name = budget`, "
        "`strategy.budget = 600`, `strategy.budget_mode = final_count`")
