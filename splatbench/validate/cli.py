"""`splatbench validate mitsuba`: the rasterizer against Gaussians ray-traced by Mitsuba."""

from __future__ import annotations

import sys
from pathlib import Path

import click

_SWEEP_NAMES = ("size", "anisotropy", "angle", "overlap", "sh")


@click.group()
def validate() -> None:
    """Cross-check the rasterizer against independent renderers."""


@validate.command("mitsuba")
@click.option("--out", type=click.Path(path_type=Path), default=Path("out") / "validate_mitsuba",
              show_default=True, help="Folder for table.csv, table.md, plot.png and intersection.csv.")
@click.option("--resolution", type=click.IntRange(min=16), default=128, show_default=True,
              help="Image width and height of every sweep scene.")
@click.option("--sweep", "sweeps", multiple=True, type=click.Choice(_SWEEP_NAMES),
              help="Run only these sweeps (repeatable). Default: all.")
@click.option("--no-probe", is_flag=True, help="Skip the ray-ellipsoid intersection probe.")
def mitsuba(out: Path, resolution: int, sweeps: tuple[str, ...], no_probe: bool) -> None:
    """Compare splatbench.render with Mitsuba's volprim_rf_basic on the same Gaussians.

    Sweeps screen size, anisotropy, field angle, depth overlap and SH degree; prints
    the table, writes it (CSV, markdown) with a plot, and checks the tight regime
    against the derived bound (docs/validation.md). Exits with status 1 if a check fails.
    """
    from splatbench.validate import mitsuba as vm

    names = list(sweeps) or list(_SWEEP_NAMES)
    rows = vm.run_sweeps(resolution, names, progress=True)
    checks = vm.check_trends(rows)
    if "size" in names:
        checks = vm.check_tight(resolution) + checks
    probe = [] if no_probe else vm.intersection_probe()
    paths = vm.write_report(rows, out, width=resolution, probe=probe, checks=checks)
    click.echo(vm.sweep_markdown(rows, resolution))
    if probe:
        click.echo(vm.probe_markdown(probe))
    for c in checks:
        click.echo(f"{'PASS' if c.passed else 'FAIL'}  {c.name}: {c.detail}")
    click.echo(f"report: {paths.markdown} ({paths.csv.name}, {paths.plot.name}"
               + (", intersection.csv" if probe else "") + ")")
    if not all(c.passed for c in checks):
        sys.exit(1)
