"""The files of `splatbench compare`: ``results.parquet``, ``report.md`` and figures.

    result_table(result) -> DataFrame     one row per backend x workload (columns below)
    findings(table) -> list[str]          statements computed from the table's numbers only
    run_record(result) -> CompareRecord   what report.md reads besides the table (``run.json``)
    read_run_record(path) -> CompareRecord  ``run.json`` back, checked field by field
    render_markdown(record, table, figures, out) -> str   report.md's text
    write_compare(result, out) -> Path    DIR/results.parquet, DIR/run.json, DIR/report.md, DIR/time_vs_error*.png
    rewrite_report(out) -> Path           report.md and figures again from results.parquet and run.json

Columns: backend, version, workload, n, width, height, error_width, error_height,
device, status ("ok" or "error"), error; verdict_mode, forward_verdict, band (boundary band
pixels), band_share (band / error pixels), tie_pixels (pixels whose bound depth ties widen);
``{matched,exact}_{rgb,alpha,depth}_{max_abs,psnr,frac_off,outliers,outside_band}``; grad_oracle,
grad_bound, grad_verdict, grad_band (Gaussians in the gradient band),
``grad_{group}_{rel_l2,cosine,norm,oracle_norm,rest_rel_l2,band_rel_l2}`` (rest: outside the gradient band, the
verdict's; band: the band's entries against their own oracle norm);
``{fwd,fwd_bwd}_ms_{median,q1,q3,min,max}``, fwd_runs_ms / fwd_bwd_runs_ms (JSON
lists), timing_note, peak_mb, memory_kind; loadavg_start / loadavg_end (JSON [1, 5,
15 min]), cpu_count, loaded (the larger 1-min load average above cpu_count / 2).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import pandas as pd

from splatbench.backends.base import GROUPS, OUTPUTS
from splatbench.compare.run import CompareResult, CompareRow, CompareSettings
from splatbench.verification.bounds import FORWARD_ATOL, GRAD_TERM_OPS, OFF_THRESHOLD, U32
from splatbench.guards import dataclass_from_mapping
from splatbench.compare.measure import spread
from splatbench.errors import InputError
from splatbench.fsutil import read_text
from splatbench.metrics.machine import MachineInfo
from splatbench.report_files import markdown_table, run_header, write_json, write_parquet, write_text

MODES = ("matched", "exact")
STATS = ("max_abs", "psnr", "frac_off", "outliers", "outside_band")
RUN_RECORD = "run.json"


def _row(row: CompareRow, cpu_count: int) -> dict:
    flat = {k: getattr(row, k) for k in ("backend", "version", "workload", "n", "width", "height", "error_width",
                                          "error_height", "device")}
    flat.update(status="error" if row.error else "ok", error=row.error, verdict_mode=row.verdict_mode,
                forward_verdict=row.forward_verdict, band=row.band,
                band_share=row.band / max(1, row.error_width * row.error_height), tie_pixels=row.tie_pixels,
                grad_band=row.grad_band)
    for mode in MODES:
        errors = getattr(row, mode)
        for out in OUTPUTS:
            for stat in STATS:
                e = errors.get(out)
                flat[f"{mode}_{out}_{stat}"] = math.nan if e is None else float(getattr(e, stat))
    flat.update(grad_oracle=row.grad_oracle, grad_bound=row.grad_bound, grad_verdict=row.grad_verdict)
    for group in GROUPS:
        g = row.grads.get(group)
        for stat in ("rel_l2", "cosine", "norm", "oracle_norm", "rest_rel_l2", "band_rel_l2"):
            flat[f"grad_{group}_{stat}"] = math.nan if g is None else getattr(g, stat)
    t = row.timing
    for name, runs in (("fwd", t.fwd_ms), ("fwd_bwd", t.fwd_bwd_ms)):
        for stat, value in spread(runs).items():
            flat[f"{name}_ms_{stat}"] = value
        flat[f"{name}_runs_ms"] = json.dumps(list(runs))
    load = max(row.loadavg_start[:1] + row.loadavg_end[:1], default=math.nan)
    flat.update(timing_note=t.note, peak_mb=t.peak_mb, memory_kind=t.memory_kind,
                loadavg_start=json.dumps(list(row.loadavg_start)), loadavg_end=json.dumps(list(row.loadavg_end)),
                cpu_count=cpu_count, loaded=bool(load > cpu_count / 2))
    return flat


def result_table(result: CompareResult) -> pd.DataFrame:
    """One row per backend x workload (module doc)."""
    cpus = result.machine.cpu_count or 1
    return pd.DataFrame([_row(r, cpus) for r in result.rows])


# ----------------------------------------------------------------------------- findings
def _ok(table: pd.DataFrame) -> pd.DataFrame:
    return table[table.status == "ok"]


def _accuracy_findings(table: pd.DataFrame) -> list[str]:
    lines = []
    for backend, rows in table.groupby("backend", sort=False):
        judged = rows[rows.forward_verdict != "n/a"]
        if judged.empty:
            continue
        outside = judged[judged.forward_verdict == "outside bound"]
        if outside.empty:
            worst = max(((r[f"{r.verdict_mode}_{o}_max_abs"], o, r.workload, r[f"{r.verdict_mode}_{o}_outliers"],
                          r.band) for _, r in judged.iterrows()
                         for o in OUTPUTS if math.isfinite(r[f"{r.verdict_mode}_{o}_max_abs"])), default=None)
            tail = (f" (largest difference {worst[0]:.1e}, {worst[1]} on {worst[2]}, where {int(worst[3])} pixels "
                    f"exceed the bound, all in the boundary band of {int(worst[4])} pixels)") if worst else ""
            lines.append(f"**{backend}** matches the float64 oracle within the float32 bound on every output of "
                         f"{len(judged)} workload(s){tail}.")
        for _, r in outside.iterrows():
            bad = [f"{o} {int(r[f'{r.verdict_mode}_{o}_outside_band'])} pixels over the bound outside the band "
                   f"(max {r[f'{r.verdict_mode}_{o}_max_abs']:.1e})" for o in OUTPUTS
                   if r[f"{r.verdict_mode}_{o}_outside_band"] > 0]
            lines.append(f"**{backend}** is OUTSIDE the bound on {r.workload}: {'; '.join(bad)}; "
                         f"boundary band {int(r.band)} pixels.")
        grads = rows[rows.grad_verdict != "n/a"]
        for _, r in grads.iterrows():
            judged = [g for g in GROUPS if not math.isnan(r[f"grad_{g}_rel_l2"])]
            worst = max(judged, key=lambda g: _judged(r, g))
            verdict = "within" if r.grad_verdict == "within bound" else "OUTSIDE"
            zero = [f"{g} (L2 norm {r[f'grad_{g}_norm']:.1e} where the oracle's is exactly 0)" for g in GROUPS
                    if g not in judged and not math.isnan(r[f"grad_{g}_norm"])]
            band = "" if math.isnan(r.get(f"grad_{worst}_rest_rel_l2", math.nan)) else (
                f" outside the gradient band of {int(r.get('grad_band', 0))} Gaussians (with it "
                f"{r[f'grad_{worst}_rel_l2']:.1e}; the band's own {r[f'grad_{worst}_band_rel_l2']:.1e})")
            lines.append(f"**{backend}** gradients on {r.workload} are {verdict} the bound: worst relative L2 "
                         f"{_judged(r, worst):.1e}{band} ({worst}; bound {r.grad_bound:.1e}, oracle "
                         f"{r.grad_oracle.split(' (')[0]})"
                         + (f"; no relative error for {', '.join(zero)}." if zero else "."))
    return lines


def _speed_findings(table: pd.DataFrame) -> list[str]:
    lines = []
    for workload, rows in _ok(table).groupby("workload", sort=False):
        # Only backends that render correctly are ranked: a fast wrong answer is no speed.
        wrong = rows[rows.forward_verdict == "outside bound"]
        if not wrong.empty:
            lines.append(f"On {workload}, not ranked by speed (forward outside the bound): "
                         f"{', '.join(wrong.backend)}.")
        rows = rows[rows.forward_verdict != "outside bound"]
        for stage, label in (("fwd_bwd", "forward+backward"), ("fwd", "forward")):
            col = f"{stage}_ms_median"
            timed = rows[rows[col].notna()].sort_values(col, kind="stable")
            if timed.empty:
                continue
            best = timed.iloc[0]
            others = [f"{r.backend} ×{r[col] / best[col]:.1f} slower ({r[col]:.1f} ms)"
                      for _, r in timed.iloc[1:].iterrows()]
            lines.append(f"On {workload}, **{best.backend}** is the fastest {label} ({best[col]:.1f} ms median)"
                         + (f"; {', '.join(others)}." if others else "."))
        for _, r in rows[rows.fwd_ms_median.isna() & rows.timing_note.str.startswith("not timed")].iterrows():
            lines.append(f"On {workload}, {r.backend} was {r.timing_note}.")
    return lines


def _exact_findings(table: pd.DataFrame) -> list[str]:
    lines = []
    for workload, rows in _ok(table).groupby("workload", sort=False):
        rows = rows[rows.exact_rgb_psnr.notna()].sort_values("exact_rgb_psnr", ascending=False, kind="stable")
        if rows.empty:
            continue
        listed = ", ".join(f"{r.backend} {r.exact_rgb_psnr:.1f} dB" for _, r in rows.iterrows())
        lines.append(f"On {workload}, rgb PSNR to the exact Gaussian mixture (the cost of each backend's "
                     f"approximations): {listed}.")
    return lines


def findings(table: pd.DataFrame) -> list[str]:
    """Statements computed from ``table`` (`result_table`): accuracy verdicts, speed ratios,
    distance to the exact mixture, failures, and whether the machine was loaded."""
    lines = _accuracy_findings(table) + _speed_findings(table) + _exact_findings(table)
    for _, r in table[table.status == "error"].iterrows():
        lines.append(f"**{r.backend}** failed on {r.workload}: {r.error}")
    loaded = table[table.loaded]
    if not loaded.empty:
        peak = max(json.loads(s)[0] for s in list(loaded.loadavg_start) + list(loaded.loadavg_end)
                   if json.loads(s))
        lines.append(f"Times were taken on a loaded machine (1-min load average up to {peak:.2f} on "
                     f"{int(table.cpu_count.iloc[0])} cores, above half the cores): the backends took turns within "
                     f"each round, so their ratios are fairer than their absolute times.")
    return lines


# ----------------------------------------------------------------------------- figures
def time_figures(table: pd.DataFrame, out: Path) -> list[Path]:
    """Forward (and forward+backward) median time against rgb PSNR to the exact mixture, one
    panel per workload, Pareto front marked (`splatbench.plotting.pareto_figure`)."""
    from splatbench.plotting import pareto_figure
    from splatbench.metrics.spec import MetricSpec

    quality = MetricSpec("exact_rgb_psnr", "rgb PSNR to the exact mixture (dB)", ".1f", "dB", "higher")
    paths = []
    for stage, name, label in (("fwd", "time_vs_error.png", "forward"),
                               ("fwd_bwd", "time_vs_error_fwd_bwd.png", "forward+backward")):
        ok = _ok(table)
        ok = ok[ok[f"{stage}_ms_median"].notna() & ok.exact_rgb_psnr.notna()]
        if ok.empty:
            continue
        means = pd.DataFrame({"scene": ok.workload, "cell": ok.backend, "time": ok[f"{stage}_ms_median"],
                              "quality": ok.exact_rgb_psnr}).reset_index(drop=True)
        time_spec = MetricSpec(f"{stage}_ms_median", f"{label} time (ms, median)", ".1f", "ms", "lower")
        pareto_figure(means, list(dict.fromkeys(means.scene)), time_spec, quality, out / name,
                      f"{label} time against error to the exact mixture, per workload")
        paths.append(out / name)
    return paths


# ----------------------------------------------------------------------------- markdown
def _num(x, fmt: str) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if isinstance(x, float) and math.isinf(x):
        return "∞" if x > 0 else "−∞"
    return format(x, fmt)


def _error_cells(r, mode: str) -> list[str]:
    return ["–" if math.isnan(r[f"{mode}_{o}_max_abs"]) else
            f"{_num(r[f'{mode}_{o}_max_abs'], '.1e')} / {_num(r[f'{mode}_{o}_psnr'], '.1f')} / "
            f"{_num(100 * r[f'{mode}_{o}_frac_off'], '.1f')}%" for o in OUTPUTS]


def _count(x) -> str:
    """A count cell ("–" when the column is missing: a table written before it existed)."""
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else str(int(x))


def _judged(r, group: str) -> float:
    """The relative L2 error the verdict reads: outside the gradient band when there is one."""
    rest = r.get(f"grad_{group}_rest_rel_l2", math.nan)
    return r[f"grad_{group}_rel_l2"] if rest is None or math.isnan(rest) else rest


def _grad_cell(r, group: str) -> str:
    if math.isnan(r[f"grad_{group}_rel_l2"]) and r[f"grad_{group}_oracle_norm"] == 0:
        return f"oracle 0; norm {r[f'grad_{group}_norm']:.0e}"
    cell = f"{_num(r[f'grad_{group}_rel_l2'], '.1e')} / {_num(1 - r[f'grad_{group}_cosine'], '.0e')}"
    rest = r.get(f"grad_{group}_rest_rel_l2", math.nan)
    if rest is not None and not math.isnan(rest):
        cell += f" / {_num(rest, '.1e')}"
    return cell


def _outlier_cell(r) -> str:
    counts = [(r[f"{r.verdict_mode}_{o}_outliers"], r[f"{r.verdict_mode}_{o}_outside_band"]) for o in OUTPUTS]
    counts = [(int(c), int(out)) for c, out in counts if not math.isnan(c)]
    if not counts:
        return "–"
    return f"{max(c for c, _ in counts)} / {max(out for _, out in counts)}"


def _band_cell(r) -> str:
    if r.verdict_mode == "exact":
        return "none (exact)"
    return f"{int(r.band)} ({100 * r.band_share:.2f}%); ties {int(r.tie_pixels)}"


def _spread_cell(r, stage: str) -> str:
    if math.isnan(r[f"{stage}_ms_median"]):
        return "–"
    return (f"{r[f'{stage}_ms_median']:.1f} [{r[f'{stage}_ms_q1']:.1f}–{r[f'{stage}_ms_q3']:.1f}] "
            f"({r[f'{stage}_ms_min']:.1f}–{r[f'{stage}_ms_max']:.1f})")


@dataclass(frozen=True)
class CompareRecord:
    """What the report needs besides the table (``run.json``): the command that reproduces
    the run, how long it took (s), when the record was written (ISO 8601, UTC), the machine,
    the settings and the per-workload notes."""

    command: str
    seconds: float
    written: str
    machine: MachineInfo
    settings: CompareSettings
    notes: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        """``run.json``'s object: `run_header`'s keys, then ``settings`` and ``notes``."""
        return {"command": self.command, "seconds": self.seconds, "written": self.written,
                "machine": asdict(self.machine), "settings": asdict(self.settings), "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, data: Any, what: str) -> CompareRecord:
        """The record `to_dict` wrote, checked at the boundary (`guards.dataclass_from_mapping`:
        unknown keys, types): a missing, unknown or mistyped field is a one-line `InputError`
        starting ``what:`` and naming it (``settings.repeats``)."""
        data = _whole(data, cls, what)
        machine = dataclass_from_mapping(MachineInfo, _whole(data["machine"], MachineInfo, f"{what}: machine"),
                                         prefix="machine.", source=what)
        settings = dataclass_from_mapping(CompareSettings, _whole(data["settings"], CompareSettings,
                                                                  f"{what}: settings"), prefix="settings.", source=what)
        notes = data["notes"]
        if not (isinstance(notes, list) and all(isinstance(n, str) for n in notes)):
            raise InputError(f"{what}: notes: expected a list of strings, got {notes!r}")
        return dataclass_from_mapping(cls, {**data, "machine": machine, "settings": settings, "notes": tuple(notes)},
                                      source=what)


def _whole(data: Any, cls: type, what: str) -> dict[str, Any]:
    """``data`` when it is a JSON object holding every field of the dataclass ``cls`` (a missing
    one is not given its default: the file is read as written); else a one-line `InputError`."""
    if not isinstance(data, dict):
        raise InputError(f"{what}: expected a JSON object, got {type(data).__name__}")
    missing = [f.name for f in fields(cls) if f.name not in data]
    if missing:
        raise InputError(f"{what}: missing {', '.join(map(repr, missing))}")
    return data


def run_record(result: CompareResult) -> CompareRecord:
    """The run's `CompareRecord`, written now (`run_header`: the command, the time, the machine)."""
    header = run_header(result.command or "run_compare(...)", result.seconds, result.machine)
    return CompareRecord(header["command"], header["seconds"], header["written"], result.machine, result.settings,
                         tuple(result.notes))


def read_run_record(path: str | Path) -> CompareRecord:
    """The `CompareRecord` in ``path`` (a ``run.json``): a one-line `InputError` naming the file
    when it cannot be read, is not JSON or does not hold a record."""
    text = read_text(path, RUN_RECORD)
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise InputError(f"{RUN_RECORD}: {str(path)!r} is not JSON ({exc})") from None
    return CompareRecord.from_dict(data, f"{RUN_RECORD}: {str(path)!r}")


def _gradient_section(table: pd.DataFrame) -> list[str]:
    """The report's "Gradients" section; a table written before the gradient band (no ``grad_band``
    column) keeps the text and bound it was judged under."""
    banded = "grad_band" in table.columns
    sizes = "".join(f"; {GRAD_TERM_OPS * U32 * math.sqrt(w * h):.1e} at {w}x{h} ({name})" for name, w, h in
                    table[["workload", "error_width", "error_height"]].drop_duplicates().itertuples(index=False))
    zero = ("A group whose oracle gradient is exactly 0 (the quaternions of isotropic Gaussians, which a rotation "
            "does not change) has no relative error: the cell shows the backend's L2 norm, and the group is left "
            "out of the verdict.")
    band = (". The **gradient band** (`reference/band.py`; its size in Gaussians per row) is the Gaussians whose "
            "own term float32 may compute under another discrete decision (a contribution kept or skipped at the "
            "cutoff or alpha_min, the early stop, a depth swap, the alpha_max clamp): measured apart and budgeted "
            "(their error may reach their own oracle gradient, relative L2 1, not more). Outside it, every other "
            "term at such a pixel changes by a relative w_p at most (a_k of the flipped contribution, T at the "
            "stop, T a_i a_j for a swap), adding sqrt(sum_p w_p² / P) to the bound. ") if banded else (
            "; plus sqrt(b / P) for the b pixels over the forward bound (in the boundary band), each "
            "changing its terms by a whole contribution. ")
    cells = ("relative L2 error / (1 − cosine) / relative L2 error outside the gradient band (the verdict's)"
             if banded else "relative L2 error / (1 − cosine)")
    head = ["workload", "backend", "oracle", *GROUPS, *(["gradient band"] if banded else []), "bound", "verdict"]
    rows = [[r.workload, r.backend, r.grad_oracle or "–", *[_grad_cell(r, g) for g in GROUPS],
             *([_count(r.get("grad_band"))] if banded else []), _num(r.grad_bound, ".1e"), r.grad_verdict]
            for _, r in table.iterrows()]
    return [
        "## Gradients", "",
        "Random-cotangent VJP of sum(v·(rgb, alpha, depth)) (v_depth kept where the oracle's alpha > 0.05) at the "
        f"error resolution; each cell: {cells}. The oracle is named per row: `torch64` "
        "(float64 autograd, same conventions, every entry) or `fd` (central differences of the float64 "
        "reference on a random sample of entries).", "",
        f"**Bound**: one gradient entry sums a term per pixel, each ~{GRAD_TERM_OPS} float32 operations (relative "
        f"error {GRAD_TERM_OPS}u); cancellation under random cotangents amplifies that by at most sqrt(P) "
        f"(`tests/test_raster_grads.py`): {GRAD_TERM_OPS}·u·sqrt(P){sizes}{band}{zero}", "",
        markdown_table(head, rows), ""]


def render_markdown(record: CompareRecord, table: pd.DataFrame, figures: list[Path], out: Path) -> str:
    """``report.md`` from the table (`result_table`) and the run record (`run_record`)."""
    m, s = record.machine, record.settings
    text = [
        "# splatbench compare: rasterizers against the float64 oracle", "",
        f"Command: `{record.command}`  ",
        f"Written {record.written} in {record.seconds:.0f} s; "
        f"{m.cpu_count} CPUs ({m.cpu_model}), device {s.device}, torch {m.torch}, drjit {m.drjit}.  ",
        f"Load average (1, 5, 15 min) at the start {m.loadavg_start}, at the end {m.loadavg_end}; "
        + ("**loaded** (1-min load above half the cores): absolute times are inflated by others' work."
           if table.loaded.any() else "not loaded."),
        "", "## Workloads", "", *[f"- {n}" for n in record.notes], "",
        "## Findings", "", "Computed from `results.parquet` by `splatbench.compare.report.findings`.", "",
        *[f"- {line}" for line in findings(table)], "",
        "## Forward error", "",
        f"Each cell: max abs / PSNR (dB, peak 1) / share of pixels off by more than {OFF_THRESHOLD:.0e}. Depth is "
        "compared as depth·alpha / z_max (z_max = max(1, largest oracle depth)): the composited sum, since "
        "depth = sum / alpha amplifies alpha's error by 1/alpha.", "",
        f"**Bound** (derived in `tests/test_raster_parity.py`): float32 unit roundoff u = 2^-24; a pixel sums "
        f"L <= ~150 terms T·a·c, T a product of up to L factors and a·c ~20 operations, so |error| <= "
        f"(2L + 20)·u·max|c| ~ 4e-5 for |c| <= 2, and {FORWARD_ATOL:.0e} per pixel for the random-walk sum. A pixel "
        "where some contribution lies within float32 error of a discrete decision (the cutoff, alpha_min, the "
        "early stop) may differ by a whole contribution: the oracle computes these pixels, the **boundary band**, "
        "from worst-case float32 error bounds of every quantity those decisions read (`reference/band.py`); two "
        "contributions whose depths may swap in float32 widen that pixel's bound by what the swap can change (the "
        "tie slack, `ties` pixels). Outside the band the bound holds strictly: the verdict is \"within bound\" "
        "when no pixel outside the band exceeds it. Against the matched oracle (the exact one, which has no band, "
        "for a backend declaring `exact`).", "",
        "### Against the oracle with each backend's declared conventions (\"matched\")", "",
        markdown_table(["workload", "backend", "rgb", "alpha", "depth", "pixels over bound / outside band",
                        "boundary band (share); ties", "verdict"],
                       [[r.workload, r.backend, *_error_cells(r, "matched"), _outlier_cell(r), _band_cell(r),
                         r.forward_verdict] for _, r in table.iterrows()]), "",
        "### Against the exact Gaussian mixture", "",
        "`reference` in mode \"exact\" (docs/conventions.md): no alpha_min skip, alpha clamp, radius cutoff or "
        "early stop, and also no log-scale clip or culling but the camera's clip planes, so Gaussians off-screen "
        "count in full; graphdeco's Jacobian clamp stays, as part of the projection model.", "",
        markdown_table(["workload", "backend", "rgb", "alpha", "depth"],
                       [[r.workload, r.backend, *_error_cells(r, "exact")] for _, r in table.iterrows()]), "",
        *_gradient_section(table),
        "## Time and memory", "",
        f"At each workload's full resolution, {s.repeats} rounds after one untimed warm-up per backend; within a "
        "round the backends take turns (ABC ABC ...), forward runs first, then forward+backward runs. Cells: median "
        "[quartiles] (min–max), ms. Peak MB: " + "; ".join(sorted({k.removesuffix(", forward only")
                                                              for k in table.memory_kind if k}))
        + " (one forward+backward; one forward for a backend with finite-difference gradients).", "",
        markdown_table(["workload", "backend", "forward ms", "forward+backward ms", "peak MB",
                        "load avg before → after", "note"],
                       [[r.workload, r.backend, _spread_cell(r, "fwd"), _spread_cell(r, "fwd_bwd"),
                         _num(r.peak_mb, ".0f"),
                         f"{json.loads(r.loadavg_start)[:1]} → {json.loads(r.loadavg_end)[:1]}"
                         + (" loaded" if r.loaded else ""), r.timing_note or ""] for _, r in table.iterrows()]), "",
    ]
    for path in figures:
        text += [f"![{path.stem}]({path.relative_to(out)})", ""]
    failed = table[table.status == "error"]
    text += ["## Errors", ""]
    text += [f"- {r.backend} on {r.workload}: {r.error}" for _, r in failed.iterrows()] or ["None."]
    return "\n".join(text) + "\n"


def write_compare(result: CompareResult, out: str | Path) -> Path:
    """Write ``out``/results.parquet, ``out``/run.json, the figures and ``out``/report.md;
    returns report.md's path."""
    out = Path(out)
    record = run_record(result)
    write_parquet(out / "results.parquet", result_table(result))
    write_json(out / RUN_RECORD, record.to_dict(), indent=1)
    return _write_report(out, record)


def rewrite_report(out: str | Path) -> Path:
    """(Re)write ``out``/report.md and its figures from ``out``/results.parquet and run.json."""
    out = Path(out)
    return _write_report(out, read_run_record(out / RUN_RECORD))


def _write_report(out: Path, record: CompareRecord) -> Path:
    """report.md and the figures from ``out``/results.parquet (the numbers as stored) and ``record``."""
    table = pd.read_parquet(out / "results.parquet")
    figures = time_figures(table, out)
    return write_text(out / "report.md", render_markdown(record, table, figures, out))
