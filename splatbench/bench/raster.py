"""Rasterizer benchmark: run time, stage split, throughput and peak memory per workload.

Laid out like pytorch3d's ``tests/benchmarks/bm_rasterize_points.py``: the timing
closures live in `splatbench.metrics.timing`, the machine description in
`splatbench.metrics.machine`; `run_one` warms the closures up and times them on
one workload; `run_isolated` runs `run_one` in a fresh interpreter
(``python -m splatbench.bench.raster --one ...``) so that the peak RSS it reports is
that workload's alone. `run_suite` runs a list of workloads that way.

Units: milliseconds (ms) and megabytes (MB = 10^6 bytes). docs/benchmarks.md
describes every field of `RasterBenchResult` and how throughput is defined.

Size (~430 lines, over the ~400 guideline on purpose): this is one benchmark from
command-line workload to table -- workloads, settings, the result row, `run_one` and
its subprocess entry, and the table and files; the timing closures and the machine
description already live apart (`bench.timing`, `bench.machine`).
"""

from __future__ import annotations

import argparse
import gc
import json
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Callable

from splatbench import report_files
from splatbench.metrics.machine import MachineInfo, resolve_device
from splatbench.metrics.memory import current_rss_mb, peak_rss_mb, reset_peak_rss
from splatbench.metrics.timing import (StageSplit, forward_backward_with_init, forward_with_init, milliseconds,
                                     staged_runs, time_runs, torch_params)
from splatbench.errors import InputError, SplatbenchError
from splatbench.workloads import GARDEN, WorkloadSpec, parse_synthetic, parse_workload


#: FP32 operations per pixel-Gaussian evaluation of the forward compositing loop, counted
#: from `splatbench.raster.compositing._forward_loop` (an FMA counts 2, a compare or
#: select 1, Dr.Jit's exp about 15): dx, dy 2; sigma 9; exp 15; alpha 2; cutoff and
#: alpha_min tests 3; transmittance 3; weight 1; r, g, b, depth 8; selects 2.
FLOPS_PER_EVALUATION = 45


class BenchError(SplatbenchError):
    """A benchmark subprocess failed for a reason other than bad input."""


# ----------------------------------------------------------------------------- workloads

@dataclass(frozen=True)
class Target:
    """What a standard workload should achieve on the 2-core CPU (Dr.Jit LLVM) machine."""

    fwd_bwd_ms: float                  # median forward+backward time
    peak_rss_mb: float | None = None   # peak RSS of build + one forward+backward
                                       # (see `RasterBenchResult.first_run_peak_rss_mb`)


#: The standard synthetic workloads (Gaussians, width, height) and their targets (issue 3 §5).
TARGETS: dict[tuple[int, int, int], Target] = {
    (10_000, 256, 256): Target(35.0),
    (100_000, 512, 512): Target(450.0),
    (1_000_000, 800, 800): Target(2000.0, 1500.0),
}
STANDARD_SYNTHETIC: tuple[tuple[int, int, int], ...] = tuple(TARGETS)


def target_of(spec: WorkloadSpec) -> Target | None:
    """The target of a standard synthetic workload (any seed); None for every other."""
    if spec.kind != "synthetic":
        return None
    return TARGETS.get((spec.n, spec.width, spec.height))


def standard_suite(seed: int = 0) -> list[WorkloadSpec]:
    """The default suite: every standard synthetic workload, then the garden view."""
    return [WorkloadSpec("synthetic", n=n, width=w, height=h, seed=seed) for n, w, h in STANDARD_SYNTHETIC] \
        + [parse_workload(GARDEN)]


@dataclass(frozen=True)
class BenchSettings:
    """How each workload is run."""

    repeats: int = 5                              # timed runs per measurement (the median is reported)
    device: str = "auto"                          # "cpu" (Dr.Jit LLVM), "cuda", or "auto"
    options: dict = field(default_factory=dict)   # other `RasterOptions` fields, e.g. {"tile_size": 8}

    def raster_options(self) -> dict:
        """Keyword arguments for `splatbench.rasterize` (options plus device)."""
        return {**self.options, "device": self.device}

    def validate(self) -> None:
        """Raise a one-line `InputError` for a bad repeat count or rasterizer option."""
        from splatbench.raster.options import RasterOptions

        if self.repeats < 1:
            raise InputError(f"--repeats: expected a count >= 1, got {self.repeats}")
        if "device" in self.options:
            raise InputError("--option device: use --device instead")
        RasterOptions.from_kwargs(**self.raster_options())


# ----------------------------------------------------------------------------- results

@dataclass
class RasterBenchResult:
    """One workload's measurements. Times are medians over ``repeats`` runs after warm-up."""

    name: str                         # workload name
    n: int                            # Gaussians
    width: int                        # image width (pixels)
    height: int                       # image height (pixels)
    sh_degree: int                    # SH degree evaluated
    device: str                       # "cpu" (Dr.Jit LLVM) or "cuda"
    tile_size: int                    # tile side (pixels)
    pixel_block: int                  # side of a compositing lane's pixel block (pixels; at most tile_size)
    repeats: int                      # timed runs per measurement
    fwd_ms: float                     # forward only (no gradients), median
    fwd_bwd_ms: float                 # forward + backward of rgb.sum() to all five groups, median
    stages: StageSplit                # per-stage split (separate runs, with the stage timer)
    pairs: int                        # Gaussian-tile pairs composited
    visible: int                      # Gaussians that survived culling
    evaluations: int                  # pixel-Gaussian evaluations compositing performs per pass (work_stats)
    mevals_per_s: float               # evaluations / forward compositing seconds / 10^6
    box_pairs: int                    # pairs of the support bounding boxes, before the ellipse-tile test
    block_evaluations: int            # B^2 x (B x B block, Gaussian) pairs whose block meets the support
    inside_cutoff_evaluations: int    # (pixel, Gaussian) with the pixel centre inside the cutoff ellipse
    useful_evaluations: int           # ... that also pass alpha >= alpha_min: inside the support
    useful_share: float               # useful_evaluations / evaluations
    cutoff_box_pairs: int             # pairs of the cutoff bounding boxes: before any culling
    cutoff_evaluations: int           # cutoff_box_pairs x tile_size^2: evaluations without culling
    cutoff_useful_share: float        # useful_evaluations / cutoff_evaluations: the share without culling
    peak_gflops: float                # measured FP32 FMA peak of the device (splatbench.bench.peak)
    share_of_peak: float              # mevals_per_s * FLOPS_PER_EVALUATION / peak (see docs/benchmarks.md)
    base_rss_mb: float                # peak RSS after imports (interpreter, torch, Dr.Jit)
    setup_rss_mb: float               # peak RSS after building the workload and parameters
    peak_rss_mb: float                # peak RSS over warm-up and timed runs (see `rss_reset`)
    first_run_peak_rss_mb: float      # whole-process peak RSS of building the workload and the first
                                      # forward+backward (max of setup and that run's peak)
    rss_reset: bool                   # True: the high-water mark was reset after setup (Linux),
                                      # so peak_rss_mb excludes setup; False: whole-process peak
    retained_mb_per_run: float        # RSS growth from after warm-up to the end, per timed run
                                      # (about 0 normally; steady growth means each run leaks)
    target_fwd_bwd_ms: float | None   # target for fwd_bwd_ms (standard synthetic workloads only)
    target_peak_rss_mb: float | None  # target for first_run_peak_rss_mb (1M workload only)
    meets_target: bool | None         # every target met; None without targets
    fwd_runs_ms: list[float] = field(default_factory=list)      # every forward run
    fwd_bwd_runs_ms: list[float] = field(default_factory=list)  # every forward+backward run

    @classmethod
    def from_dict(cls, data: dict) -> RasterBenchResult:
        """Inverse of ``dataclasses.asdict``."""
        return cls(**{**data, "stages": StageSplit(**data["stages"])})


#: CSV columns, in order: the scalar fields of `RasterBenchResult` with `StageSplit` inlined.
CSV_COLUMNS: tuple[str, ...] = tuple(
    name for f in fields(RasterBenchResult) if f.name not in ("fwd_runs_ms", "fwd_bwd_runs_ms")
    for name in ([s.name for s in fields(StageSplit)] if f.name == "stages" else [f.name]))


def csv_row(result: RasterBenchResult) -> dict:
    """One CSV row (None as an empty cell)."""
    flat = asdict(result)
    flat.update(flat.pop("stages"))
    return {k: ("" if flat[k] is None else flat[k]) for k in CSV_COLUMNS}


# ----------------------------------------------------------------------------- running

def run_one(spec: WorkloadSpec, settings: BenchSettings) -> RasterBenchResult:
    """Benchmark one workload in this process.

    Setup (untimed): build the workload and the parameter tensors. Warm-up (untimed,
    kernels compile or load from Dr.Jit's cache): one forward+backward, one forward,
    one forward+backward with the stage timer. Then ``repeats`` forward runs,
    ``repeats`` forward+backward runs, and ``repeats`` forward+backward runs with the
    stage timer. The RSS fields describe this process: run it in a fresh one
    (`run_isolated`) for them to be this workload's.
    """
    from splatbench.gaussians import Gaussians
    from splatbench.bench.peak import fp32_peak
    from splatbench.raster.options import RasterOptions
    from splatbench.raster.torch_bridge import parameter_device
    from splatbench.raster.work import work_stats

    options = settings.raster_options()
    opts = RasterOptions.from_kwargs(**options)
    device = resolve_device(opts.device)
    base_rss = peak_rss_mb()

    workload = spec.build()
    name, camera = spec.label or workload.name, workload.camera
    # the parameters live where a training loop keeps them: torch's CUDA device on CUDA
    params = tuple(p.to(parameter_device(device)) for p in torch_params(workload.gaussians))
    n = len(workload.gaussians)
    del workload
    gc.collect()
    setup_rss = peak_rss_mb()
    rss_reset = reset_peak_rss()

    forward = forward_with_init(params, camera, opts)
    forward_backward = forward_backward_with_init(params, camera, opts)
    forward_backward()
    first_run_peak = max(setup_rss, peak_rss_mb())
    forward()
    staged_runs(forward_backward, 1)
    gc.collect()
    rss_warm = current_rss_mb()

    fwd_s, stats = time_runs(forward, settings.repeats)
    fwd_bwd_s, _ = time_runs(forward_backward, settings.repeats)
    stages = staged_runs(forward_backward, settings.repeats)
    peak_rss = peak_rss_mb()
    gc.collect()
    retained = (current_rss_mb() - rss_warm) / (3 * settings.repeats)

    work = work_stats(Gaussians(*(p.cpu().numpy() for p in params)), camera, opts)
    evaluations = work.performed
    comp_s = stages.compositing_ms / 1e3
    peak = fp32_peak(device)
    mevals = round(evaluations / comp_s / 1e6, 3) if comp_s > 0 else 0.0
    fwd_bwd_ms = milliseconds(statistics.median(fwd_bwd_s))
    target = target_of(spec)
    meets = None
    if target is not None:
        meets = fwd_bwd_ms <= target.fwd_bwd_ms and (target.peak_rss_mb is None
                                                     or first_run_peak <= target.peak_rss_mb)
    return RasterBenchResult(
        name=name, n=n, width=camera.width, height=camera.height, sh_degree=stats.sh_degree, device=device,
        tile_size=opts.tile_size, pixel_block=opts.pixel_block, repeats=settings.repeats,
        fwd_ms=milliseconds(statistics.median(fwd_s)),
        fwd_bwd_ms=fwd_bwd_ms, stages=stages, pairs=stats.num_pairs, visible=int(stats.visible.sum()),
        evaluations=evaluations, mevals_per_s=mevals, box_pairs=work.box_pairs,
        block_evaluations=work.block_evaluations, inside_cutoff_evaluations=work.inside_cutoff,
        useful_evaluations=work.useful, useful_share=round(work.useful_share, 4),
        cutoff_box_pairs=work.cutoff_box_pairs, cutoff_evaluations=work.cutoff_evaluations,
        cutoff_useful_share=round(work.useful / work.cutoff_evaluations, 4) if work.cutoff_evaluations else 0.0,
        peak_gflops=peak.gflops,
        share_of_peak=round(mevals * 1e6 * FLOPS_PER_EVALUATION / (peak.gflops * 1e9), 4),
        base_rss_mb=round(base_rss, 1), setup_rss_mb=round(setup_rss, 1), peak_rss_mb=round(peak_rss, 1),
        first_run_peak_rss_mb=round(first_run_peak, 1),
        rss_reset=rss_reset, retained_mb_per_run=round(retained, 1),
        target_fwd_bwd_ms=target.fwd_bwd_ms if target else None,
        target_peak_rss_mb=target.peak_rss_mb if target else None, meets_target=meets,
        fwd_runs_ms=[milliseconds(s) for s in fwd_s], fwd_bwd_runs_ms=[milliseconds(s) for s in fwd_bwd_s])


def run_isolated(spec: WorkloadSpec, settings: BenchSettings) -> RasterBenchResult:
    """`run_one` in a fresh interpreter (``python -m splatbench.bench.raster --one``), so
    its RSS figures are this workload's. Bad input there comes back as `InputError`."""
    job = json.dumps({"spec": asdict(spec), "settings": asdict(settings)})
    with tempfile.TemporaryDirectory(prefix="splatbench-bench-") as tmp:
        result_path = Path(tmp) / "result.json"
        proc = subprocess.run([sys.executable, "-m", "splatbench.bench.raster", "--one", job,
                               "--result", str(result_path)], capture_output=True, text=True)
        payload = json.loads(result_path.read_text()) if result_path.is_file() else {}
    if "error" in payload:
        error = InputError if payload.get("type") == "InputError" else BenchError
        raise error(payload["error"])
    if proc.returncode != 0 or "result" not in payload:
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        tail = lines[-1] if lines else "no output"
        raise BenchError(f"{spec.label or spec.kind}: benchmark subprocess exited with {proc.returncode}: {tail}")
    return RasterBenchResult.from_dict(payload["result"])


def describe(spec: WorkloadSpec) -> str:
    if spec.kind == "synthetic":
        return f"synthetic {spec.n} {spec.width}x{spec.height} (seed {spec.seed}{', posed' if spec.posed else ''})"
    if spec.kind == "model":
        return spec.label or f"{Path(spec.path).stem} view {spec.view} of {spec.views} at {spec.width}x{spec.height}"
    return spec.label or Path(spec.path).name


def run_suite(specs: list[WorkloadSpec], settings: BenchSettings,
              progress: Callable[[str], None] | None = None,
              on_result: Callable[[list[RasterBenchResult]], None] | None = None) -> list[RasterBenchResult]:
    """`run_isolated` for each spec in turn; ``on_result`` sees the results so far after each."""
    results: list[RasterBenchResult] = []
    for i, spec in enumerate(specs, 1):
        if progress:
            progress(f"[{i}/{len(specs)}] {describe(spec)} ...")
        t0 = time.perf_counter()
        results.append(run_isolated(spec, settings))
        if progress:
            progress(f"[{i}/{len(specs)}] done in {time.perf_counter() - t0:.1f} s")
        if on_result:
            on_result(results)
    return results


# ----------------------------------------------------------------------------- reporting

TABLE_HEADER = ("workload", "N", "WxH", "fwd ms", "fwd+bwd ms",
                "stages ms pre/bin(cull+sort)/comp/bcomp/bpre/other", "pairs cutoff box/support box/kept",
                "Mevals uncull./performed/useful (useful share)", "Mevals/s", "share of FP32 peak",
                "peak RSS MB 1st/all", "target", "met")


def _fmt_ms(x: float) -> str:
    return f"{x:.1f}" if x < 1000 else f"{x:.0f}"


def table_rows(results: list[RasterBenchResult]) -> list[tuple[str, ...]]:
    rows = []
    for r in results:
        s = r.stages
        binning = f"{_fmt_ms(s.binning_ms)}({_fmt_ms(s.binning_cull_ms)}+{_fmt_ms(s.binning_sort_ms)})"
        split = "/".join([_fmt_ms(s.preprocess_ms), binning] + [_fmt_ms(v) for v in (
            s.compositing_ms, s.backward_compositing_ms, s.backward_preprocess_ms, s.other_ms)])
        target = "-"
        if r.target_fwd_bwd_ms is not None:
            target = f"{r.target_fwd_bwd_ms:.0f} ms"
            if r.target_peak_rss_mb is not None:
                target += f", {r.target_peak_rss_mb:.0f} MB"
        met = "-" if r.meets_target is None else ("yes" if r.meets_target else "NO")
        rows.append((r.name, f"{r.n:,}", f"{r.width}x{r.height}", _fmt_ms(r.fwd_ms), _fmt_ms(r.fwd_bwd_ms), split,
                     f"{r.cutoff_box_pairs:,}/{r.box_pairs:,}/{r.pairs:,}",
                     f"{r.cutoff_evaluations / 1e6:.1f}/{r.evaluations / 1e6:.1f}/{r.useful_evaluations / 1e6:.1f}"
                     f" ({100 * r.useful_share:.1f} %)",
                     f"{r.mevals_per_s:.0f}", f"{100 * r.share_of_peak:.1f} % of {r.peak_gflops:.1f} GFLOP/s",
                     f"{r.first_run_peak_rss_mb:.0f}/{r.peak_rss_mb:.0f}", target, met))
    return rows


def format_table(results: list[RasterBenchResult]) -> str:
    """A fixed-width text table, one row per workload."""
    rows = [TABLE_HEADER, *table_rows(results)]
    widths = [max(len(row[i]) for row in rows) for i in range(len(TABLE_HEADER))]
    lines = []
    for k, row in enumerate(rows):
        cells = [c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))]
        lines.append("  ".join(cells).rstrip())
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def leak_warnings(results: list[RasterBenchResult], threshold_mb: float = 1.0) -> list[str]:
    """One line per workload whose RSS grew by more than ``threshold_mb`` per timed run."""
    return [f"warning: {r.name}: RSS grew {r.retained_mb_per_run:.1f} MB per run (memory kept alive across runs; "
            f"peak_rss_mb includes it)" for r in results if r.retained_mb_per_run > threshold_mb]


def write_csv(results: list[RasterBenchResult], path: Path) -> Path:
    """One CSV line per result under the header `CSV_COLUMNS`, atomically."""
    return report_files.write_csv(path, CSV_COLUMNS, ({c: row[c] for c in CSV_COLUMNS}
                                                      for row in (csv_row(r) for r in results)))


def write_json(results: list[RasterBenchResult], machine: MachineInfo, settings: BenchSettings,
               path: Path) -> Path:
    """``{"machine": MachineInfo, "settings": BenchSettings, "results": [RasterBenchResult]}``."""
    return report_files.write_json(path, {"machine": asdict(machine), "settings": asdict(settings),
                                         "results": [asdict(r) for r in results]}, indent=2)


# ----------------------------------------------------------------------------- subprocess entry

def main(argv: list[str] | None = None) -> int:
    """``python -m splatbench.bench.raster --one JOB --result PATH``: run one workload
    (JOB: JSON with "spec" and "settings") and write ``{"result": ...}`` or
    ``{"error": ..., "type": ...}`` to PATH. Used by `run_isolated`."""
    parser = argparse.ArgumentParser(prog="python -m splatbench.bench.raster")
    parser.add_argument("--one", required=True, help="JSON: {'spec': WorkloadSpec, 'settings': BenchSettings}")
    parser.add_argument("--result", required=True, type=Path, help="where to write the result JSON")
    args = parser.parse_args(argv)
    job = json.loads(args.one)
    try:
        result = run_one(WorkloadSpec(**job["spec"]), BenchSettings(**job["settings"]))
        payload, code = {"result": asdict(result)}, 0
    except SplatbenchError as exc:
        payload, code = {"error": str(exc), "type": type(exc).__name__}, 2
    report_files.write_json(args.result, payload)
    return code


if __name__ == "__main__":
    sys.exit(main())
