"""`splatbench conform BACKEND`: run the conformance probes on a rasterizer; exit 1 when any fails."""

from __future__ import annotations

import json
import sys
import time

import click

from splatbench.devices import device_option


def _number(x: float | None) -> str:
    return "-" if x is None else f"{x:.2e}"


def format_table(report, seconds: float) -> str:
    """The report as a table (probe, status, deviation, tolerance), then the cause of each failure or
    warning, then one summary line."""
    rows = [("probe", "status", "deviation", "tolerance")]
    rows += [(r.name, r.status.upper() if r.status != "pass" else "pass", _number(r.deviation), _number(r.tolerance))
             for r in report.results]
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    lines = [f"conform {report.backend} on {report.device}"
             + (f" (declared: {', '.join(f'{k}={v:g}' if isinstance(v, float) else f'{k}={v}' for k, v in report.declared.items())})" if report.declared
                else " (nothing declared: graphdeco's conventions assumed)")]
    lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    flagged = [r for r in report.results if r.status in ("fail", "warn")]
    if flagged:
        lines.append("")
    for r in flagged:
        lines.append(f"{r.status.upper()} {r.name}: {r.cause}.")
        lines.append(f"    measured: {r.detail}")
        if r.tolerance_source:
            lines.append(f"    tolerance: {r.tolerance_source}")
    counts = report.counts()
    lines.append("")
    lines.append(f"{report.backend}: {counts['pass']} pass, {counts['warn']} warn, {counts['fail']} fail, "
                 f"{counts['skip']} skip ({len(report.results)} probes, {seconds:.1f} s)"
                 + ("" if report.passed else f"; failed: {', '.join(report.failed)}"))
    return "\n".join(lines)


@click.command()
@click.argument("backend")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (a 'probes' list) instead of a table.")
@device_option
@click.option("--probe", "probes", multiple=True, help="Run only this probe (repeatable); see --list.")
@click.option("--list", "list_probes", is_flag=True, help="List the probes and what each checks, then exit.")
def conform(backend: str, as_json: bool, device: str, probes: tuple[str, ...], list_probes: bool) -> None:
    """Check BACKEND against 3DGS conventions on small probe scenes.

    BACKEND is a built-in name (drjit, torch, gsplat, reference, ...), an installed entry
    point (group "splatbench.backends") or your own code as module:function. Each probe
    isolates one convention or classic bug and reports pass / fail / warn / skip with the
    measured deviation from the float64 oracle, its derived tolerance and, for a failure, the
    most likely cause. Exit status: 0 when no probe fails, 1 when any fails, 2 on bad input.
    """
    from splatbench.backends.conform import PROBES
    from splatbench.backends.conform import conform as run_conform

    if list_probes:
        width = max(len(p.name) for p in PROBES)
        for p in PROBES:
            click.echo(f"{p.name.ljust(width)}  {p.kind:<13}  {p.checks}")
        return
    start = time.perf_counter()
    report = run_conform(backend, device=device, probes=probes or None)
    seconds = time.perf_counter() - start
    if as_json:
        click.echo(json.dumps({**report.to_dict(), "seconds": round(seconds, 2)}, indent=2))
    else:
        click.echo(format_table(report, seconds))
    sys.exit(0 if report.passed else 1)
