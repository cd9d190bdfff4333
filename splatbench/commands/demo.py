"""`splatbench demo`: the main job.

1. A rasterizer check on real data: the bundled Mip-NeRF 360 "garden" SfM capture
   (138,766 Gaussians seeded as 3DGS does, 648x420) rendered by the Dr.Jit
   rasterizer, and at quarter resolution by the float64 reference; prints the render
   time and their largest difference, writes ``out/demo/garden.png`` and
   ``garden_difference.png`` (the difference per pixel on a log colour scale, the
   parity tolerance marked), and names both (a few seconds).
2. The demo experiment, ``experiments/demo.toml``: its scenes rendered with Mitsuba
   (cached by content hash under ``data/scenes``), its training grid run on the local
   executor (resumable: runs already done are skipped), results under ``results/demo``.
   Not its ``[check]`` (the headline at graphdeco's 7K protocol: six 7,000-step runs, beyond
   the demo's 15 minutes); ``splatbench run experiments/demo.toml`` runs it, and the report
   says "7K check: not run" until then.
3. Its report, ``out/demo/report/report.md`` (tables, findings, figures, results.parquet);
   prints the table, the findings and, last, the report's path. The committed baseline
   ``reports/demo`` is refreshed on purpose with ``--report-dir reports/demo``, so a
   fresh clone stays clean after its first ``make demo``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click
import numpy as np

#: The demo experiment shipped with the repository.
DEMO_EXPERIMENT = Path(__file__).resolve().parents[2] / "experiments" / "demo.toml"


def garden_check(out: Path, scale: float) -> None:
    """Render the garden capture with the rasterizer and (at ``scale``) the reference."""
    import splatbench
    from splatbench.backends import reference_render
    from splatbench.verification.bounds import FORWARD_ATOL, over_bound
    from splatbench.images import save_png
    from splatbench.plotting import difference_figure
    from splatbench.workloads import GARDEN_SFM, load_npz

    workload = load_npz(GARDEN_SFM, view=0)
    g, camera = workload.gaussians, workload.camera
    splatbench.render(g, camera)  # compile (kernels are cached in ~/.drjit)
    t0 = time.perf_counter()
    full = splatbench.render(g, camera)
    seconds = time.perf_counter() - t0
    image = save_png(full.rgb, out / "garden.png")
    click.echo(f"Dr.Jit rasterizer: {len(g)} Gaussians at {camera.width}x{camera.height} in {seconds * 1e3:.0f} ms")

    small = camera.scaled(scale)
    fast = splatbench.render(g, small)
    ref = reference_render(None, g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, small, band=True)
    err = np.abs(fast.rgb - ref.rgb)
    difference = difference_figure(err.max(axis=-1), out / "garden_difference.png", tolerance=FORWARD_ATOL,
                                   title=f"|Dr.Jit rasterizer - float64 reference|, garden at "
                                         f"{small.width}x{small.height}")
    # the max is over every pixel, the boundary band included: the parity rule is per pixel
    # (FORWARD_ATOL, widened by depth ties), strict outside the band the oracle derives
    pixels = small.width * small.height
    over, outside = over_bound(err.max(axis=-1), ref.band, ref.tie_slack)
    click.echo(f"reference check at {small.width}x{small.height}: max |fast - reference| = {err.max():.2e} "
               f"over all pixels; {over} of {pixels} above the {FORWARD_ATOL:.0e} parity tolerance, {outside} "
               f"of them outside the boundary band of {int(ref.band.sum())} pixels where float32 may take a "
               f"discrete decision differently (allowed: 0) (image: {image}; the difference, on a colour scale: "
               f"{difference})")


@click.command()
@click.option("--experiment", type=click.Path(path_type=Path, dir_okay=False), default=None,
              help="Experiment file (default: the repository's experiments/demo.toml).")
@click.option("--results", type=click.Path(path_type=Path, file_okay=False), default=Path("results"),
              show_default=True, help="Results folder.")
@click.option("--report-dir", "report_dir", type=click.Path(path_type=Path, file_okay=False), default=None,
              help="Report folder (default: out/<experiment name>/report; the committed baseline is "
                   "reports/demo, refreshed with --report-dir reports/demo).")
@click.option("--workers", type=int, default=None, help="Parallel runs (default: the file's [runner] workers).")
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("out/demo"), show_default=True,
              help="Folder for the garden check's images.")
@click.option("--scale", default=0.25, show_default=True, help="Resolution factor of the garden reference check.")
@click.option("--garden/--no-garden", default=True, show_default=True, help="Run the garden rasterizer check.")
def demo(experiment: Path | None, results: Path, report_dir: Path | None, workers: int | None, out: Path,
         scale: float, garden: bool) -> None:
    """Check the rasterizer on real data, run the demo experiment, write its report."""
    from splatbench.experiments.runner import run_experiment
    from splatbench.experiments.grid import load_experiment
    from splatbench.reports.report import build_report, write_report

    t_start = time.perf_counter()
    path = experiment or (DEMO_EXPERIMENT if DEMO_EXPERIMENT.is_file() else Path("experiments") / "demo.toml")
    spec = load_experiment(path)  # a bad experiment file is one line before any work
    if garden:
        garden_check(out, scale)

    t0 = time.perf_counter()  # the runner renders the pending runs' scenes first (cached), then runs them
    summary = run_experiment(spec, workers=workers if workers is not None else spec.runner.workers,
                             executor="local", results_dir=results, progress=True, check=False)
    click.echo(f"{spec.name}: {summary.line()} in {time.perf_counter() - t0:.0f} s (results in {summary.folder})")
    if spec.check is not None:
        click.echo(f"{spec.name}: its [check] (the headline at {spec.check.protocol}) is not run by the demo; "
                   f"`splatbench run {path}` runs it, and the report says \"not run\" until then")

    report = build_report(spec, results)
    report_path = write_report(report, report_dir or Path("out") / spec.name / "report")
    for table in report.axes:
        click.echo("")
        click.echo(table.markdown())
        if table.axis in report.findings:
            click.echo("")
            click.echo(report.findings[table.axis].markdown())
    click.echo("")
    click.echo(f"demo finished in {time.perf_counter() - t_start:.0f} s")
    click.echo(f"report: {report_path.resolve()}")
    if summary.failed:
        sys.exit(1)
