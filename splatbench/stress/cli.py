"""`splatbench stress`: degenerate and non-finite input through the rasterizer."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from splatbench.devices import device_option
from splatbench.report_files import write_json
from splatbench.stress.cases import CATEGORIES

SHOWN_FAILURES = 5  # failing cases listed per category (all of them go to --json)


def format_report(report) -> list[str]:
    """One line per category, then the first failing cases of each."""
    width = max(len(c.category) for c in report.categories)
    lines = [f"{'category':<{width}}  {'cases':>6}  {'culled (Gaussians)':>18}  {'rejected':>8}  "
             f"{'non-finite outputs':>18}  {'non-finite grads':>16}  {'errors':>6}"]
    for c in report.categories:
        lines.append(f"{c.category:<{width}}  {c.cases:>6}  {c.culled:>18}  {c.rejected:>8}  "
                     f"{c.nonfinite_outputs:>18}  {c.nonfinite_grads:>16}  {len(c.errors):>6}")
    for c in report.categories:
        lines += [f"FAIL {line}" for line in c.failures[:SHOWN_FAILURES]]
        if len(c.failures) > SHOWN_FAILURES:
            lines.append(f"... and {len(c.failures) - SHOWN_FAILURES} more failing {c.category} cases (see --json)")
    verdict = "ok" if report.ok else "FAILED"
    lines.append(f"{verdict}: {report.cases} cases in {report.seconds:.1f} s (seed {report.seed})")
    return lines


@click.command()
@click.option("--cases", default=200, show_default=True, type=click.IntRange(min=1),
              help="Cases to run, spread round-robin over the categories.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0), help="Master seed.")
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None,
              help="Also write the full report (every failing case) as JSON here.")
@click.option("--category", "categories", multiple=True, type=click.Choice(CATEGORIES),
              help="Only these categories (repeatable; default: all).")
@click.option("--jobs", default=None, type=click.IntRange(min=1),
              help="Worker processes (default: the CPU count, at most 4); 1 runs in this process.")
@device_option
def stress(cases: int, seed: int, json_path: Path | None, categories: tuple[str, ...], jobs: int | None,
           device: str) -> None:
    """Render degenerate and non-finite scenes forward and backward; exit 1 on any
    NaN/Inf output or gradient, or any unexpected error (see docs/stress.md)."""
    import os

    from tqdm import tqdm

    from splatbench.raster.device import get_device
    from splatbench.stress.runner import run

    get_device(device)  # 'cuda' without a GPU: one line before the progress bar, not a failure per case
    with tqdm(total=cases, file=sys.stderr, unit="case", desc="stress") as bar:
        report = run(cases, seed, categories=categories or CATEGORIES, device=device,
                     jobs=jobs or min(4, os.cpu_count() or 1), on_case=lambda result: bar.update(1))
    for line in format_report(report):
        click.echo(line)
    if json_path is not None:
        write_json(json_path, report.to_dict(), indent=2)
        click.echo(f"report: {json_path.resolve()}")
    if not report.ok:
        sys.exit(1)
