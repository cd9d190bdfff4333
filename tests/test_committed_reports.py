"""The committed baseline reports (issue 6 §3): each shipped experiment has
``reports/<name>/report.md``, its figures and ``results.parquet``; the report covers
the grid the experiment file writes now, and every table and finding in it is what the
committed ``results.parquet`` gives.

Rebuilding from the parquet (`report_from_table`) and comparing text checks the
committed numbers, not the code: a report edited by hand, or left behind when a grid
or its results changed, fails here.

A report left behind on purpose, until its grid is rerun, says so: a ``STALE.md``
beside it (why, and the command that refreshes it) and a banner at the top of its
``report.md``. Such a report is checked to be stale -- its runs are *not* the grid's --
so the marker cannot outlive a rerun, and its experiment file must still expand.

A new experiment whose grid has not been run yet has ``reports/<name>/PENDING.md``
(why, and the command that produces the report) and no ``report.md``: its
experiment file must expand, and the marker must go when the report arrives.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest

from splatbench.experiments import check_runs, expand, load_experiment
from splatbench.reports import report_from_table
from splatbench.reports.check import CHECK_TABLE_NAME, check_appendix_lines, check_lines, header_line
from splatbench.strategies import refines_at

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted(p.stem for p in (ROOT / "experiments").glob("*.toml"))


def _load(name: str):
    """The shipped experiment ``name``; skipped when it reads a user's data that is not beside the
    checkout (experiments/real_capture.toml reads ../shared/data/fox, which is never bundled)."""
    from splatbench.errors import InputError

    try:
        return load_experiment(ROOT / "experiments" / f"{name}.toml")
    except InputError as exc:
        if "does not exist" in str(exc) or "not a dataset folder" in str(exc) or "is not a file" in str(exc):
            pytest.skip(f"experiments/{name}.toml reads data that is not here: {exc}")
        raise


def _quick_inputs() -> dict[str, str]:
    """The shipped experiments whose committed run table is another's quick version and no report of its
    own (`[report] quick = "../reports/NAME"`; sh_degree_quick): NAME -> the experiment that reads it."""
    from splatbench.errors import InputError

    out = {}
    for name in SHIPPED:
        try:
            spec = load_experiment(ROOT / "experiments" / f"{name}.toml")
        except InputError:
            continue  # data not here: _load skips its own tests
        if spec.quick is not None:
            folder = (ROOT / "experiments" / spec.quick).resolve()
            if folder.parent == ROOT / "reports" and (folder / "results.parquet").is_file():
                out[folder.name] = name
    return out


def test_every_shipped_experiment_is_reported():
    quick = _quick_inputs()
    missing = [name for name in SHIPPED if not (ROOT / "reports" / name / "report.md").is_file()
               and not (ROOT / "reports" / name / "PENDING.md").is_file() and name not in quick]
    assert not missing, f"no committed report for: {missing} (run `make reports`)"


def test_a_quick_version_holds_every_run_of_its_grid():
    """A quick version committed as another report's input (no report.md of its own: it is no evidence)
    holds the finished runs of the grid its experiment file makes now, every one."""
    for name in _quick_inputs():
        folder = ROOT / "reports" / name
        assert not (folder / "report.md").is_file(), f"reports/{name}: a quick version has no report of its own"
        table = pd.read_parquet(folder / "results.parquet")
        assert list(table.run_id) == [r.run_id for r in expand(_load(name))], f"reports/{name}: not its grid's runs"
        assert set(table.status) == {"done"}, f"reports/{name}: runs not done"


def test_make_reports_keeps_only_the_table_of_each_quick_version(tmp_path):
    """`make reports` writes a quick version's run table alone (no report.md): its QUICK_INPUTS are read
    from the experiment files' `[report] quick` lines by a sed pattern; that pattern must find what the
    spec parser finds, or a quick version would get a report of its own (or a report lose its own)."""
    import shutil
    import subprocess

    make = shutil.which("make")
    if make is None:
        pytest.skip("no make on this machine")
    probe = tmp_path / "probe.mk"
    probe.write_text(f"include {ROOT / 'Makefile'}\nshow-quick-inputs:\n\t@echo $(QUICK_INPUTS)\n")
    out = subprocess.run([make, "-s", "-f", str(probe), "show-quick-inputs"], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout.split()
    assert sorted(out) == sorted(_quick_inputs()), f"Makefile QUICK_INPUTS {out} against [report] quick"


def test_a_pending_report_is_not_there_yet_and_its_grid_expands():
    # One test looping over the PENDING.md reports, not one per report: usually there are none,
    # and an empty parametrisation would print a "got empty parameter set" skip in every run.
    for name in (n for n in SHIPPED if (ROOT / "reports" / n / "PENDING.md").is_file()):
        folder = ROOT / "reports" / name
        assert not (folder / "report.md").is_file(), f"reports/{name} is reported now: delete reports/{name}/PENDING.md"
        assert f"make reports REPORTS={name}" in (folder / "PENDING.md").read_text(encoding="utf-8"), name
        assert expand(_load(name)), name


@pytest.mark.parametrize("name", SHIPPED)
def test_committed_report_matches_its_parquet(name):
    folder = ROOT / "reports" / name
    if not (folder / "report.md").is_file():
        pending = (folder / "PENDING.md").is_file()
        pytest.skip(f"reports/{name} " + ("pending (PENDING.md)" if pending else
                                           "not committed (reported by the test above)"))
    spec = _load(name)
    table = pd.read_parquet(folder / "results.parquet")
    runs = expand(spec)
    text = (folder / "report.md").read_text(encoding="utf-8")
    banner = text.split("\n")[2] if text.count("\n") > 2 else ""
    if (folder / "STALE.md").is_file():
        assert banner.startswith("> **Stale:**") and "(STALE.md)" in banner, f"reports/{name}: no stale banner"
        assert list(table.run_id) != [r.run_id for r in runs], \
            f"reports/{name} covers its grid now: delete reports/{name}/STALE.md and the banner"
        return
    assert "**Stale:**" not in banner, f"reports/{name}: a stale banner without STALE.md"
    # The report is of the grid as the file writes it now, and every run finished.
    assert list(table.run_id) == [r.run_id for r in runs]
    assert set(table.status) == {"done"}
    report = report_from_table(spec, table, len(runs))
    assert f"({len(runs)} done, 0 failed, 0 not run)" in text
    for axis in report.axes:
        assert axis.markdown() in text, f"reports/{name}: the `{axis.axis}` table differs from results.parquet"
        if axis.axis in report.findings:
            found = report.findings[axis.axis]
            assert found.markdown() in text, f"reports/{name}: `{axis.axis}` findings differ"
            assert found.appendix_markdown() in text, f"reports/{name}: `{axis.axis}` findings' appendix differs"
            for line in found.summary:  # the summary: the findings' own texts, cut short
                assert line in text, f"reports/{name}: `{axis.axis}` summary differs: {line[:80]!r}"
    for finding in ("parity", "settling", "ranks"):  # the run findings: their own sections
        if finding in report.findings:
            assert report.findings[finding].markdown() in text, f"reports/{name}: the {finding} finding differs"
    if spec.kind == "train":  # issue 29: the header names the protocol and the headline's 7K check
        assert "- **Protocol**: " in text, f"reports/{name}: no protocol in the header"
        if spec.check is None:
            assert "**7K check: none declared**" in text, f"reports/{name}: the header does not name the 7K check"
    if spec.check is not None:  # the check's section is what check.parquet gives (none there: "not run")
        checked = pd.read_parquet(folder / CHECK_TABLE_NAME) if (folder / CHECK_TABLE_NAME).is_file() else None
        if checked is not None:
            assert set(checked.run_id) <= {r.run_id for r in check_runs(spec)}, f"reports/{name}: stale check.parquet"
        check = report_from_table(spec, table, len(runs), checked).check
        assert header_line(check) in text, f"reports/{name}: the header's 7K check differs from {CHECK_TABLE_NAME}"
        more = check_appendix_lines(check)
        for line in (*check_lines(check, f"splatbench run experiments/{name}.toml", bool(more)), *more):
            assert line in text, f"reports/{name}: the 7K check's section differs: {line[:80]!r}"
    for line in text.splitlines():
        if line.startswith("![") and "](" in line:
            figure = folder / line.split("](", 1)[1].rstrip(")")
            assert figure.is_file() and figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", figure


@pytest.mark.parametrize("name", SHIPPED)
def test_a_committed_report_rebuilds_to_its_own_text(name, tmp_path):
    """What `splatbench report --rebuild` writes from a committed report's own parquet is the
    committed ``report.md``, every line of it (the command line it names aside, which carries the
    options it was written with): the tables, findings, figures' fronts, metrics and warnings are
    what the code makes of those runs today, so a change to how reports are written that changes
    a committed report fails here until it is rebuilt. A stale report cannot be rebuilt (its runs
    are not the grid's: the test above) and is skipped."""
    from splatbench.reports.report import write_report

    folder = ROOT / "reports" / name
    if not (folder / "report.md").is_file() or (folder / "STALE.md").is_file():
        pytest.skip(f"reports/{name} has no current report")
    spec = _load(name)
    checked = pd.read_parquet(folder / CHECK_TABLE_NAME) if (folder / CHECK_TABLE_NAME).is_file() else None
    report = report_from_table(spec, pd.read_parquet(folder / "results.parquet"), len(expand(spec)), checked)
    rebuilt = write_report(report, tmp_path).read_text(encoding="utf-8").splitlines()
    committed = (folder / "report.md").read_text(encoding="utf-8").splitlines()

    def unnamed(lines: list[str]) -> list[str]:  # the command's options: where it was run from
        return [re.sub(r"^Generated by `splatbench report [^`]*`", "Generated by", line) for line in lines]

    assert len(rebuilt) == len(committed), f"reports/{name}: {len(rebuilt)} lines rebuilt, {len(committed)} committed"
    for new, old in zip(unnamed(rebuilt), unnamed(committed)):
        assert new == old, f"reports/{name}: the rebuilt report differs from the committed one"


@pytest.mark.parametrize("name", SHIPPED)
def test_the_readme_line_of_an_unsettled_report_says_so(name):
    """Issue 29 (6): a report whose headline comparisons had not settled (a cell's test curve still
    moving over the last quarter, `splatbench.reports.settling`) is marked "not settled" in the
    README's table line too, and no README line prints an interval of ±0.00."""
    folder = ROOT / "reports" / name
    if not (folder / "report.md").is_file() or (folder / "STALE.md").is_file():
        pytest.skip(f"reports/{name} has no current report")
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    rows = [line for line in readme.splitlines() if line.startswith(f"| [`reports/{name}`]")]
    assert len(rows) == 1, f"README: expected one table line for reports/{name}"
    spec = _load(name)
    report = report_from_table(spec, pd.read_parquet(folder / "results.parquet"), len(expand(spec)))
    unsettled = [c for f in report.findings.values() for c in f.claims
                 if c.kind in ("vs", "best") and c.metric == "test_psnr" and c.settled is False]
    if unsettled:
        assert "not settled" in rows[0].lower(), f"README: reports/{name} is not settled; its line must say so"
    assert "±0.00" not in rows[0] and "± 0.00" not in rows[0]


@pytest.mark.parametrize("name", SHIPPED)
def test_the_readme_line_of_a_training_report_names_its_7k_check(name):
    """Issue 29 (2): the README's line of a current training report repeats its 7K check's verdict
    ("7K check: holds", "does not hold", "not run", "incomplete"), or says none is declared."""
    folder = ROOT / "reports" / name
    if not (folder / "report.md").is_file() or (folder / "STALE.md").is_file():
        pytest.skip(f"reports/{name} has no current report")
    spec = _load(name)
    if spec.kind != "train":
        pytest.skip(f"reports/{name} is not a training report")
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    rows = [line for line in readme.splitlines() if line.startswith(f"| [`reports/{name}`]")]
    assert len(rows) == 1, f"README: expected one table line for reports/{name}"
    if spec.check is None:
        assert "7K check: none declared" in rows[0], f"README: reports/{name}'s line must name its 7K check"
        return
    checked = pd.read_parquet(folder / CHECK_TABLE_NAME) if (folder / CHECK_TABLE_NAME).is_file() else None
    check = report_from_table(spec, pd.read_parquet(folder / "results.parquet"), len(expand(spec)), checked).check
    assert check.headline in rows[0], f"README: reports/{name}'s line must say {check.headline!r}"


@pytest.mark.parametrize("name", SHIPPED)
def test_no_committed_report_prints_an_interval_of_zero(name):
    """Issue 29: an interval of ±0.00 is never printed (seeds that varied nothing give no interval)."""
    path = ROOT / "reports" / name / "report.md"
    if not path.is_file():
        pytest.skip(f"reports/{name} not committed")
    text = path.read_text(encoding="utf-8")
    zero = re.search(r"±\s*0\.0*(?!\d)|\[95 % CI ([+-]?[0-9.]+), \1\]", text)  # ± 0.00; an interval [a, a]
    assert zero is None, f"reports/{name} prints {zero.group(0)!r}"


#: The training grids that may run the quick protocol: the main job (it must fit `make demo`) and the
#: study of the protocol itself; and sh_degree's quick version, no report of its own: the input of
#: sh_degree's quick-versus-7K rank agreement. Every other training grid is evidence and runs
#: graphdeco's (issue 39).
QUICK_GRIDS = ("demo", "quick_protocol", "sh_degree_quick")


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_grids_follow_the_report_protocol(name):
    """Issues 11, 39: every grid has >= 3 seeds. A training grid runs graphdeco's schedule as
    written at its 7K (or 30K) column, except the demo and quick_protocol (the quick protocol:
    >= 2,000 iterations of the scaled schedule; the demo fits `make demo`); a rendered scene is
    >= 128 px, a real capture's short side may be under 128 px (it is read as the field reads
    it, only downscaled). A check reruns its two cells, every seed, at graphdeco-7k or -30k.
    Raster grids time >= 7 alternated pairs."""
    spec = _load(name)
    assert len(spec.seeds) >= 3, f"experiments/{name}.toml: {len(spec.seeds)} seed(s)"
    for run in expand(spec):
        if spec.kind == "train":
            assert run.config["schedule"] == "scaled"
            if name in QUICK_GRIDS:
                assert run.config["protocol"] == "quick"
                if name != "demo":
                    assert run.config["iterations"] >= 2000, run.labels
                    if "path" not in run.config["data"]:  # a rendered scene
                        assert _short_side(spec, run.config["data"]) >= 128, run.labels
            else:
                assert (run.config["protocol"], run.config["iterations"]) in \
                    (("graphdeco-7k", 7000), ("graphdeco-30k", 30_000)), (name, run.labels)
                if "path" not in run.config["data"]:  # a rendered scene
                    assert _short_side(spec, run.config["data"]) >= 128, run.labels
        elif spec.kind == "raster":
            assert run.config["repeats"] >= 7
    if spec.check is not None:  # issue 29 (2): the headline's two cells at a graphdeco column, every seed
        checks = check_runs(spec)
        assert len(checks) == 2 * len(spec.seeds) and {r.seed for r in checks} == set(spec.seeds)
        assert {(r.config["protocol"], r.config["iterations"]) for r in checks} <= \
            {("graphdeco-7k", 7000), ("graphdeco-30k", 30_000)}


@pytest.mark.parametrize("name", [n for n in SHIPPED if n not in QUICK_GRIDS])
def test_no_7k_run_is_evaluated_right_after_a_refinement(name):
    """Issue 39 (docs/training.md, "Evaluation order"): a refinement right before the evaluation cost
    0.06-0.26 dB at 7K, not alike across cells, so every run of a graphdeco-column grid or check either
    evaluates in graphdeco's order (``eval.before_refine``) or makes no refinement at its last step
    (a count-matched cell with ``refine_stop`` at it, a strategy that never refines)."""
    spec = _load(name)
    if spec.kind != "train":
        return
    for run in [*expand(spec), *check_runs(spec)]:
        c, st = run.config, run.config["strategy"]
        refines = st["name"] != "none" and refines_at(c["iterations"], st["refine_start"], st["refine_stop"],
                                                      st["refine_every"])
        assert c["eval"].get("before_refine", False) or not refines, \
            f"experiments/{name}.toml: {run.labels} at {run.scene} evaluates step {c['iterations']} after its refinement"


def _short_side(spec, data: dict) -> float:
    """The image's short side in a training run: ``data.resolution`` for a rendered scene (catalog
    or teacher); for a dataset folder, its ``transforms.json`` size over ``downscale`` (a folder
    without one, or absent here, counts as passing: nothing to read)."""
    if "resolution" in data:
        return data["resolution"]
    folder = Path(data["path"])
    folder = folder if folder.is_absolute() else (ROOT / "experiments" / folder)
    meta = folder / "transforms.json"
    if not meta.is_file():
        return float("inf")
    head = json.loads(meta.read_text(encoding="utf-8"))
    if not ("w" in head and "h" in head):
        return float("inf")
    return min(head["w"], head["h"]) / data.get("downscale", 1)


#: Issue 39 (6): a README result row carries the question, the headline with its interval, the scenes,
#: the protocol and the verdict; the details stay in the report.
README_ROW_CHARS = 400


def test_every_row_of_the_readme_results_table_is_short():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    rows = [line for line in readme.splitlines() if line.startswith("| [`reports/")]
    assert rows, "README: no results table"
    long = {line[:40]: len(line) for line in rows if len(line) > README_ROW_CHARS}
    assert not long, f"README: result rows over {README_ROW_CHARS} characters: {long}"
