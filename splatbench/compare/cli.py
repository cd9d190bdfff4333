"""`splatbench compare`: any rasterizers side by side against the float64 oracle.

Writes ``DIR/report.md``, ``DIR/results.parquet`` and ``DIR/time_vs_error*.png``
(default ``out/compare``; ``--out reports/compare`` refreshes the committed baseline); see `splatbench.compare.run` for what is measured
and docs/backends.md ("compare") for how to read it.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import click

from splatbench.devices import device_option
from splatbench.workloads import model_options


@click.command()
@click.option("--backend", "backends", multiple=True, required=True, metavar="NAME|module:function",
              help="A backend (repeatable): drjit, torch, torch64, gsplat, reference, mitsuba, an installed "
                   "entry point, or user code as module:function.")
@click.option("--synthetic", "synthetic", nargs=2, multiple=True, metavar="N WxH",
              help="A synthetic workload: N Gaussians at WxH pixels (repeatable).")
@click.option("--seed", default=0, show_default=True, type=int,
              help="Seed of the synthetic workloads, the cotangents and the finite-difference sample.")
@click.option("--workload", "workloads", multiple=True, metavar="garden|FILE.npz",
              help="The bundled garden SfM view, or a workload npz (repeatable).")
@model_options
@click.option("--scene", "scenes", multiple=True, metavar="NAME",
              help="A workload by the experiment grids' name: synthetic-N-S, synthetic-N-WxH, garden, garden-vK "
                   "(repeatable).")
@device_option
@click.option("--repeats", default=5, show_default=True, type=int, help="Timed rounds (median and spread).")
@click.option("--out", "out", type=click.Path(path_type=Path, file_okay=False), default=Path("out/compare"),
              show_default=True, help="Folder for report.md, results.parquet and the figures.")
@click.option("--error-scale", "error_scale", type=float, default=None,
              help="Resolution factor of the error and gradient measurement [default: the largest 1/2^k with "
                   "at most 20,000 pixels].")
@click.option("--grad-oracle", "grad_oracle", default="auto", show_default=True, metavar="auto|fd|none|NAME",
              help="Gradient oracle: a float64 backend (auto: torch64), fd (central differences), or none.")
@click.option("--fd-entries", "fd_entries", default=12, show_default=True, type=int,
              help="Entries per parameter group for the finite-difference oracle.")
@click.option("--max-call-seconds", "max_call_s", default=60.0, show_default=True, type=float,
              help="Backends predicted to take longer per forward at full resolution are not timed.")
def compare(backends: tuple[str, ...], synthetic: tuple[tuple[str, str], ...], seed: int, workloads: tuple[str, ...],
            models: tuple[str, ...], up: str | None, model_views: int, model_size: str,
            scenes: tuple[str, ...], device: str, repeats: int, out: Path, error_scale: float | None,
            grad_oracle: str, fd_entries: int, max_call_s: float) -> None:
    """Compare rasterizers against the float64 oracle: errors, gradients, time, memory.

    Without --synthetic, --workload, --model or --scene, compares on `--synthetic 2000 128x128`.
    Synthetic workloads are seen from a random camera pose (seeded by --seed), so that a
    world-space mistake (a view direction from the world origin, W for its transpose) shows.
    """
    from splatbench.compare.run import CompareSettings, run_compare
    from splatbench.compare.report import findings, result_table, write_compare
    from splatbench.backends.registry import get_backend
    from splatbench.workloads import parse_models, parse_synthetic, parse_workload, workload_spec

    settings = CompareSettings(repeats=repeats, device=device, seed=seed, error_scale=error_scale,
                               grad_oracle=grad_oracle, fd_entries=fd_entries, max_call_s=max_call_s)
    settings.validate()
    specs = [parse_synthetic(count, size, seed, posed=True) for count, size in synthetic]
    specs += [parse_workload(w) for w in workloads]
    specs += parse_models(models, up, model_views, model_size)
    specs += [workload_spec(name, seed) for name in scenes]
    if not specs:
        specs = [parse_synthetic("2000", "128x128", seed, posed=True)]
    resolved = [get_backend(b) for b in backends]  # unknown names fail here, before any work
    launched = sys.argv and (Path(sys.argv[0]).name == "splatbench"
                             or Path(sys.argv[0]).parts[-2:] == ("splatbench", "__main__.py"))  # python -m splatbench
    command = "splatbench " + shlex.join(sys.argv[1:]) if launched \
        else "splatbench compare " + shlex.join(_args(backends, synthetic, workloads, scenes, models))
    result = run_compare(resolved, specs, settings, progress=lambda line: click.echo(line, err=True),
                         command=command)
    path = write_compare(result, out)
    table = result_table(result)
    for line in findings(table):
        click.echo(f"- {line.replace('**', '')}")
    click.echo(f"report: {path}")


def _args(backends, synthetic, workloads, scenes, models=()) -> list[str]:
    args = [a for b in backends for a in ("--backend", b)]
    args += [a for n, s in synthetic for a in ("--synthetic", n, s)]
    args += [a for w in workloads for a in ("--workload", w)]
    args += [a for m in models for a in ("--model", m)]
    return args + [a for s in scenes for a in ("--scene", s)]
