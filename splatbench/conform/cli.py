"""`splatbench conform BACKEND`: run the conformance probes on a rasterizer, diagnose what fails; exit 1 when a
convention differs from the declaration or a defect remains."""

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
    rows += [(r.name, r.status.upper() if r.status in ("fail", "warn") else r.status, _number(r.deviation),
              _number(r.tolerance)) for r in report.results]
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    version = "" if report.version == "unknown" else f" {report.version}"
    lines = [f"conform {report.backend}{version} on {report.device}"
             + (f" (declared: {', '.join(f'{k}={v:g}' if isinstance(v, float) else f'{k}={v}' for k, v in report.declared.items())})" if report.declared
                else " (nothing declared: graphdeco's conventions assumed)")]
    lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    if report.diagnosis:
        lines.append("")
        lines.append("diagnosis: conventions that differ from the declaration")
    for d in report.diagnosis:
        alike = f" (or {', '.join(map(str, d.alike))}: the probes cannot tell)" if d.alike else ""
        lines.append(f"  {d.axis}: {d.found}{alike} (declared or graphdeco: {d.expected}); explains "
                     f"{len(d.explains)} probe{'s' * (len(d.explains) != 1)}: {', '.join(d.explains)}")
    if report.defects:
        lines.append("")
        lines.append("defects: what no convention explains (root causes)")
    for d in report.defects:
        follows = f"; also fails because of it: {', '.join(d.follows)}" if d.follows else ""
        lines.append(f"  {d.probe}: {d.cause}{follows}")
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
    verdict = "" if report.passed else "; " + "; ".join(
        [f"differs: {', '.join(d.axis for d in report.diagnosis)}"] * bool(report.diagnosis)
        + [f"defects: {', '.join(d.probe for d in report.defects)}"] * bool(report.defects))
    lines.append(f"{report.backend}: {counts['pass']} pass, {counts['explained']} explained, {counts['warn']} warn, "
                 f"{counts['fail']} fail, {counts['skip']} skip ({len(report.results)} probes, {seconds:.1f} s)"
                 + verdict)
    return "\n".join(lines)


@click.command()
@click.argument("backend")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (a 'probes' list) instead of a table.")
@device_option
@click.option("--probe", "probes", multiple=True, help="Run only this probe (repeatable); see --list.")
@click.option("--list", "list_probes", is_flag=True, help="List the probes and what each checks, then exit.")
@click.option("--save-images", "save_dir", type=click.Path(file_okay=False), default=None,
              help="Write PROBE_backend.png, PROBE_oracle.png and PROBE_difference.png (with a colour scale) here.")
@click.option("--no-diagnose", is_flag=True, help="Only judge each probe; do not search the conventions.")
def conform(backend: str, as_json: bool, device: str, probes: tuple[str, ...], list_probes: bool,
            save_dir: str | None, no_diagnose: bool) -> None:
    """Check BACKEND against 3DGS conventions on small probe scenes, and diagnose what fails.

    BACKEND is a built-in name (drjit, torch, gsplat, reference, ...), an installed entry
    point (group "splatbench.backends") or your own code as module:function (its folder on
    PYTHONPATH). Each probe isolates one convention or classic bug and reports pass / fail /
    warn / skip / explained with the measured deviation from the float64 oracle and its derived
    tolerance. Failing probes are diagnosed: the conventions (docs/backends.md) that explain
    them, then the defects no convention explains, each with its root-cause probe. Exit
    status: 0 when nothing differs from the declaration and no defect remains, 1 otherwise,
    2 on bad input.
    """
    from splatbench.conform import PROBES
    from splatbench.conform import conform as run_conform

    if list_probes:
        width = max(len(p.name) for p in PROBES)
        for p in PROBES:
            click.echo(f"{p.name.ljust(width)}  {p.kind:<13}  {p.checks}")
        return
    start = time.perf_counter()
    report = run_conform(backend, device=device, probes=probes or None, diagnose=not no_diagnose)
    seconds = time.perf_counter() - start
    if save_dir:
        from splatbench.conform.images import save_images
        from splatbench.backends.registry import get_backend

        chosen = tuple(p for p in PROBES if p.name in {r.name for r in report.results})
        save_images(get_backend(backend), chosen, save_dir, report.device)
    if as_json:
        click.echo(json.dumps({**report.to_dict(), "seconds": round(seconds, 2)}, indent=2, default=str))
    else:
        click.echo(format_table(report, seconds))
    sys.exit(0 if report.passed else 1)
