"""`splatbench bench`: benchmarks (see docs/benchmarks.md)."""

from __future__ import annotations

from pathlib import Path

import click

from splatbench.devices import device_option
from splatbench.workloads import model_options


@click.group()
def bench() -> None:
    """Benchmarks of the rasterizer (run time, memory, throughput)."""


@bench.command()
@click.option("--synthetic", "synthetic", nargs=2, multiple=True, metavar="N WxH",
              help="A synthetic workload: N Gaussians at WxH pixels (repeatable).")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the synthetic workloads.")
@click.option("--workload", "workloads", multiple=True, metavar="FILE.npz|garden",
              help="A workload npz, or 'garden' (bundled SfM capture, view 0) (repeatable).")
@model_options
@click.option("--repeats", default=5, show_default=True, type=int, help="Timed runs per measurement (median).")
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("out/bench"), show_default=True,
              help="Folder for raster.csv and raster.json.")
@device_option
@click.option("--option", "options", multiple=True, metavar="KEY=VALUE",
              help="Rasterizer option (repeatable), e.g. tile_size=8.")
def raster(synthetic: tuple[tuple[str, str], ...], seed: int, workloads: tuple[str, ...], models: tuple[str, ...],
           up: str | None, model_views: int, model_size: str, repeats: int, out: Path, device: str,
           options: tuple[str, ...]) -> None:
    """Time the rasterizer per workload (times, stages, memory).

    Without --synthetic, --workload or --model, runs the standard suite: synthetic 10000
    256x256, 100000 512x512, 1000000 800x800, and the garden view. Each workload
    runs in its own subprocess so its peak RSS is its own.
    """
    from splatbench.bench.raster import (BenchSettings, format_table, leak_warnings, run_suite, standard_suite,
                                         write_csv, write_json)
    from splatbench.metrics.machine import load_average, machine_info
    from splatbench.workloads import parse_models, parse_synthetic, parse_workload
    from splatbench.guards import check_image_size
    from splatbench.overrides import parse_overrides

    settings = BenchSettings(repeats=repeats, device=device, options=parse_overrides(options, "--option"))
    settings.validate()
    specs = [parse_synthetic(count, size, seed) for count, size in synthetic]
    for spec in specs:  # before any workload runs (Dr.Jit's array limit, this machine's memory)
        check_image_size(spec.width, spec.height, field="--synthetic")
    specs += [parse_workload(w) for w in workloads]
    specs += parse_models(models, up, model_views, model_size)
    if not specs:
        specs = standard_suite(seed)

    machine = machine_info(device)
    csv_path, json_path = out / "raster.csv", out / "raster.json"

    def save(results) -> None:
        machine.loadavg_end = load_average()
        write_csv(results, csv_path)
        write_json(results, machine, settings, json_path)

    click.echo(f"bench raster: {len(specs)} workload(s), {repeats} repeats, device {machine.device}, "
               f"{machine.cpu_count} CPUs, load average {machine.loadavg_start}", err=True)
    results = run_suite(specs, settings, progress=lambda line: click.echo(line, err=True), on_result=save)
    click.echo(format_table(results))
    for line in leak_warnings(results):
        click.echo(line)
    click.echo(f"load average at the end: {machine.loadavg_end}")
    busy = machine.loadavg_start[0]  # before the benchmark: others' load (at the end its own threads count too)
    if busy > machine.cpu_count / 2:
        click.echo(f"warning: the 1-minute load average was {busy} on {machine.cpu_count} CPUs before the benchmark "
                   "started: the times, and 'met', are not evidence; run on a quiet machine (docs/benchmarks.md) or "
                   "compare alternately with `splatbench bench ab`")
    click.echo(f"wrote {csv_path} and {json_path}")


@bench.command("ab")
@click.option("--against", required=True, metavar="COMMIT", help="The old commit to time against (e.g. c11f838).")
@click.option("--synthetic", "synthetic", nargs=2, multiple=True, metavar="N WxH",
              help="A synthetic workload (repeatable). Default (no workload given): 10000 256x256, 100000 512x512, "
                   "1000000 800x800.")
@click.option("--workload", "workloads", multiple=True, metavar="FILE.npz|garden",
              help="A workload npz, or 'garden' (bundled SfM capture, view 0) (repeatable).")
@model_options
@click.option("--repeats", default=5, show_default=True, type=int, help="Timed runs per side (median; >= 5).")
@click.option("--warmup", default=2, show_default=True, type=int, help="Untimed runs per side first.")
@click.option("--threads", default=2, show_default=True, type=int, help="Dr.Jit and torch threads per side.")
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("out/bench"), show_default=True,
              help="Folder for ab.json.")
def ab(against: str, synthetic: tuple[tuple[str, str], ...], workloads: tuple[str, ...], models: tuple[str, ...],
       up: str | None, model_views: int, model_size: str, repeats: int, warmup: int, threads: int,
       out: Path) -> None:
    """Forward+backward of this checkout against COMMIT, timed in alternation (CPU),
    with the two sides' images and gradients compared.

    The old commit is checked out into a temporary git worktree; each side runs in
    its own process on the same workload file. The ratio old/new of the medians is
    printed only when the load of other processes (the load average minus the
    workers' own share) stayed at or below half the cores (see docs/benchmarks.md).
    Each line also says whether the image and the gradients of d(sum rgb) are
    bit-identical, or their largest difference.
    """
    from dataclasses import asdict

    from splatbench.bench.ab import format_result, run_ab
    from splatbench.bench.raster import STANDARD_SYNTHETIC
    from splatbench.metrics.machine import machine_info
    from splatbench.workloads import parse_models, parse_synthetic, parse_workload

    specs = [parse_synthetic(count, size) for count, size in synthetic]
    specs += [parse_workload(w) for w in workloads]
    specs += parse_models(models, up, model_views, model_size)
    workloads = specs or [parse_synthetic(str(n), f"{w}x{h}") for n, w, h in STANDARD_SYNTHETIC]
    machine = machine_info("cpu")
    click.echo(f"bench ab: against {against}, {len(workloads)} workload(s), {repeats} runs per side, "
               f"{threads} threads, load average {machine.loadavg_start}", err=True)
    results = run_ab(Path(__file__).resolve().parents[2], against, workloads, repeats=repeats, warmup=warmup,
                     threads=threads, progress=lambda line: click.echo(line, err=True))
    _save_ab(out / "ab.json", {"machine": asdict(machine), "results": [asdict(r) for r in results]},
             [format_result(r) for r in results])


def _save_ab(path: Path, record: dict, lines: list[str]) -> None:
    """An A/B comparison's record as JSON in ``path`` (atomically), then its result lines and where it went."""
    from splatbench.report_files import write_json

    write_json(path, record, indent=2)
    for line in lines:
        click.echo(line)
    click.echo(f"wrote {path}")


@bench.command("ab-train")
@click.option("--against", required=True, metavar="COMMIT", help="The old commit to time against (e.g. c11f838).")
@click.option("--size", "sizes", multiple=True, type=int, metavar="PIXELS",
              help="Square image side (repeatable). Default: 128 and 256, as bench train.")
@click.option("--gaussians", default=20_000, show_default=True, type=int, help="Gaussians trained.")
@click.option("--block", default=10, show_default=True, type=int, help="Training steps per timed block.")
@click.option("--pairs", default=5, show_default=True, type=int, help="Timed blocks per side (median; >= 5).")
@click.option("--warmup", default=5, show_default=True, type=int, help="Untimed steps per side first.")
@click.option("--threads", default=2, show_default=True, type=int, help="Dr.Jit threads per side.")
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("out/bench"), show_default=True,
              help="Folder for ab_train.json.")
def ab_train(against: str, sizes: tuple[int, ...], gaussians: int, block: int, pairs: int, warmup: int,
             threads: int, out: Path) -> None:
    """Training it/s of this checkout against COMMIT, blocks of steps timed in alternation (CPU).

    Both sides train bench train's synthetic scene; the ratio is printed only when the
    load of other processes (the load average minus the workers' own share) stayed at
    or below half the cores, the rule of bench ab (docs/benchmarks.md, docs/training.md).
    """
    from dataclasses import asdict

    from splatbench.bench.ab_train import AbTrainSettings, format_train_result, run_ab_train
    from splatbench.bench.train import STANDARD_SIZES
    from splatbench.metrics.machine import machine_info

    settings = AbTrainSettings(sizes=tuple(sizes) or STANDARD_SIZES, gaussians=gaussians, block=block, pairs=pairs,
                               warmup=warmup, threads=threads)
    machine = machine_info("cpu")
    click.echo(f"bench ab-train: against {against}, sizes {list(settings.sizes)}, {gaussians} Gaussians, "
               f"{pairs} blocks of {block} steps per side, {threads} threads, load average "
               f"{machine.loadavg_start}", err=True)
    results = run_ab_train(Path(__file__).resolve().parents[2], against, settings,
                           progress=lambda line: click.echo(line, err=True))
    record = {"machine": asdict(machine), "settings": asdict(settings), "results": [asdict(r) for r in results]}
    _save_ab(out / "ab_train.json", record, [format_train_result(r) for r in results])


@bench.command("train")
@click.option("--size", "sizes", multiple=True, type=int, metavar="PIXELS",
              help="Square image side (repeatable). Default: 128 and 256.")
@click.option("--gaussians", default=20_000, show_default=True, type=int, help="Gaussians trained.")
@click.option("--iterations", default=30, show_default=True, type=int, help="Timed training steps per size.")
@click.option("--warmup", default=5, show_default=True, type=int, help="Untimed steps first (kernel compilation).")
@click.option("--seed", default=0, show_default=True, type=int, help="Scene and training seed.")
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("out/bench"), show_default=True,
              help="Folder for train.csv and train.json.")
@device_option
def train(sizes: tuple[int, ...], gaussians: int, iterations: int, warmup: int, seed: int, out: Path,
          device: str) -> None:
    """Training throughput: iterations/s and the share of rasterizer forward, backward,
    loss and optimizer in a step (see splatbench/bench/train.py)."""
    from splatbench.metrics.machine import load_average, machine_info
    from splatbench.bench.train import (STANDARD_SIZES, TrainBenchSettings, format_table, run_size, write_csv,
                                        write_json)

    settings = TrainBenchSettings(sizes=tuple(sizes) or STANDARD_SIZES, gaussians=gaussians, iterations=iterations,
                                  warmup=warmup, seed=seed, device=device)
    settings.validate()
    machine = machine_info(device)
    click.echo(f"bench train: sizes {list(settings.sizes)}, {gaussians} Gaussians, {warmup} + {iterations} steps, "
               f"device {machine.device}, {machine.cpu_count} CPUs, load average {machine.loadavg_start}", err=True)
    results = []
    for size in settings.sizes:
        results.append(run_size(size, settings))
        click.echo(f"  {size}x{size}: {results[-1].it_per_s:.2f} it/s", err=True)
        machine.loadavg_end = load_average()
        write_csv(results, out / "train.csv")
        write_json(results, machine, settings, out / "train.json")
    click.echo(format_table(results))
    click.echo(f"load average at the end: {machine.loadavg_end}")
    click.echo(f"wrote {out / 'train.csv'} and {out / 'train.json'}")
