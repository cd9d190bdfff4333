"""The report of ``splatbench validate mitsuba``: ``table.csv``, ``table.md``, ``plot.png``."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from splatbench.report_files import markdown_table, save_figure, write_csv, write_text
from splatbench.validate.mitsuba.cases import SweepRow
from splatbench.validate.mitsuba.checks import Check
from splatbench.validate.mitsuba.probe import ProbeRow
from splatbench.validate.mitsuba.renderers import MATCHED_OPTIONS

#: Default output folder of `write_report`, relative to the current folder.
DEFAULT_OUT = Path("out") / "validate_mitsuba"  # the committed baseline: --out reports/validate_mitsuba


@dataclass(frozen=True)
class ReportPaths:
    """Files written by `write_report`."""

    csv: Path
    markdown: Path
    plot: Path
    extra: dict = field(default_factory=dict)


_LABELS = {"size": "screen size sigma (px)", "anisotropy": "anisotropy (largest / smallest axis)",
           "angle": "field angle (deg)", "overlap": "depth gap between overlapping Gaussians (sigma)",
           "sh": "SH degree"}


def _fmt(x: float) -> str:
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def sweep_markdown(rows: Sequence[SweepRow], width: int) -> str:
    """The rows as a markdown table (one per sweep)."""
    lines = [f"Rasterizer vs Mitsuba `volprim_rf_dedup`, {width}x{width}, one ray per pixel centre, linear RGB, "
             f"peak 1. `shipped`: `volprim_rf_basic` as shipped. Options `matched`: {MATCHED_OPTIONS}; "
             f"`3dgs`: the rasterizer's defaults (eps2d 0.3, alpha_min 1/255, alpha_max 0.99).", ""]
    header = ["sweep", "parameter", "value", "options", "N", "PSNR (dB)", "max error", "mean error", "PSNR shipped",
              "max error shipped", "re-hit pixels"]
    lines.append(markdown_table(header, ([_fmt(v) for v in r.columns().values()] for r in rows)))
    return "\n".join(lines) + "\n"


def probe_markdown(probe: Sequence[ProbeRow]) -> str:
    """`intersection_probe` rows as a markdown table (fraction of wrong hit/miss decisions)."""
    ratios = sorted({r.distance_ratio for r in probe})
    sigmas = sorted({r.sigma for r in probe})
    cell = {(r.sigma, r.distance_ratio): r for r in probe}
    lines = ["## Mitsuba's ray-ellipsoid test (llvm_ad_rgb): wrong hit/miss decisions", "",
             "Fraction of rays whose hit/miss differs from the exact test m_ray < 3 (max |m_ray - 3| among "
             "them in brackets); rows: sigma (world units), columns: ray-origin distance / sigma.", ""]

    def text(r: ProbeRow | None) -> str:
        return "" if r is None else f"{r.wrong:.2%}" + (f" ({r.max_m_error:.2g})" if r.wrong else "")

    lines.append(markdown_table(["sigma", *(f"D/sigma {x:g}" for x in ratios)],
                                ([f"{sg:g}", *(text(cell.get((sg, ra))) for ra in ratios)] for sg in sigmas)))
    return "\n".join(lines) + "\n"


def write_report(rows: Sequence[SweepRow], out_dir: str | Path = DEFAULT_OUT, *, width: int = 128,
                 probe: Sequence[ProbeRow] = (), checks: Sequence[Check] = ()) -> ReportPaths:
    """Write ``table.csv``, ``table.md`` and ``plot.png`` (PSNR and max error per sweep) to ``out_dir``.

    With ``probe`` rows, also ``intersection.csv`` and a section of ``table.md``; with
    ``checks``, a pass/fail section of ``table.md``.
    """
    from splatbench.plotting import panels, pyplot

    plt = pyplot()
    out = Path(out_dir)
    csv_path = write_csv(out / "table.csv", SweepRow.column_names(),
                         ({k: (_fmt(v) if isinstance(v, float) else v) for k, v in r.columns().items()} for r in rows))
    text = sweep_markdown(rows, width)
    extra = {}
    if probe:
        extra["intersection"] = write_csv(out / "intersection.csv", [f.name for f in fields(ProbeRow)],
                                          (asdict(r) for r in probe))
        text += "\n" + probe_markdown(probe)
    if checks:
        text += "\n## Checks\n\n" + "".join(f"- {'PASS' if c.passed else 'FAIL'} {c.name}: {c.detail}\n"
                                             for c in checks)
    md_path = write_text(out / "table.md", text)

    sweeps = list(dict.fromkeys(r.sweep for r in rows))
    fig, axes = panels(plt, max(1, len(sweeps)), 4.2, 3.6)
    for ax, name in zip(axes, sweeps):
        ax2 = ax.twinx()
        for opt, style in (("matched", "-"), ("3dgs", ":")):
            sel = [r for r in rows if r.sweep == name and r.options == opt]
            if not sel:
                continue
            x = [r.value for r in sel]
            ax.plot(x, [min(r.metrics.psnr, 120.0) for r in sel], "o" + style, color="tab:blue",
                    label=f"PSNR ({opt})")
            ax2.semilogy(x, [max(r.metrics.max_error, 1e-9) for r in sel], "s" + style, color="tab:red",
                         label=f"max error ({opt})")
        ax.set_xlabel(_LABELS.get(name, name))
        ax.set_ylabel("PSNR (dB)", color="tab:blue")
        ax2.set_ylabel("max |error|", color="tab:red")
        ax.set_title(name)
        ax.grid(alpha=0.3)
        if name == "size":
            ax.set_xscale("log", base=2)
        lines = ax.get_legend_handles_labels()
        lines2 = ax2.get_legend_handles_labels()
        ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=7, loc="center left", framealpha=0.8)
    fig.suptitle(f"splat rasterizer vs Mitsuba volprim_rf (ray-traced Gaussians), {width}x{width}")
    fig.tight_layout()
    plot_path = save_figure(fig, out / "plot.png")
    return ReportPaths(csv_path, md_path, plot_path, extra)
