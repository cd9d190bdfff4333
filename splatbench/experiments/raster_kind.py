"""The ``raster`` run kind: time the rasterizer under a set of options against the
default options, and measure the error those options trade in against the exact
Gaussian mixture.

Scene names are workloads (`splatbench.workloads.parse_workload_name`)::

    synthetic-N-S        `splatbench.workloads.synthetic(N, S, S, seed)` (seed = the run's seed)
    synthetic-N-WxH      the same at W x H
    garden               the bundled Mip-NeRF 360 garden SfM capture, view 0 (648x420,
    garden-vK              138,766 Gaussians), or view K; the run's seed changes nothing

Config (`RasterConfig`, flat): the rasterizer options, every `RasterOptions` field but
``near`` and ``far`` (the workload's camera sets those), written at the top level
(``tile_size``, ``pixel_block``, ``alpha_min``, ``alpha_max``, ``transmittance_min``, ``eps2d``, ``radius``,
``antialiased``, ``device``: the config embeds a `RasterOptions`, so a new option is a
config field here without an edit); ``sh_degree`` (0..3, the bands evaluated); and how to
measure: ``repeats`` (timed pairs, at least 7) and ``error_scale`` (the resolution factor
of the error measurement, so that the float64 reference stays affordable).

One run:

1. Timing, at the workload's full resolution: `splatbench.metrics.timing`'s closures
   (forward under ``no_grad``; forward + backward of ``rgb.sum()`` to all five
   groups) with the run's options and with the default options, each warmed up first
   (kernels compile or load from Dr.Jit's cache outside the timed part). Then
   ``repeats`` **pairs** in one process, alternating A B A B ...: each pair times one
   call with the run's options and one with the defaults, back to back, so both see
   the same load. Per pair, the ratio option / default; ``fwd_rel`` and
   ``fwd_bwd_rel`` are the **median ratio** over pairs with a 95 % percentile-bootstrap
   interval (``*_low``, ``*_high``; `splatbench.metrics.stats.bootstrap_median_ratio`).
   SH is sliced to the evaluated degree, as the trainer does.
2. Load: the 1-minute load average is read before and after the timed pairs, and the
   process's own share of it (its CPU use over them, CPU seconds / wall seconds, in
   cores, damped as the load average damps it) is subtracted: ``load_other`` estimates
   the load of *other* processes (`splatbench.metrics.load`, the rule ``splatbench bench
   ab`` uses too). ``loaded`` is 1 when it exceeded half the usable cores (``cores``):
   such a run is marked in the table and left out of the findings (docs/reports.md: how
   to get quiet numbers).
3. Work done: ``pairs`` (Gaussian-tile pairs), ``evaluations`` (the pixel-Gaussian
   evaluations compositing performs per view, early stop ignored) and
   ``useful_evaluations`` (those inside the support), from
   `splatbench.raster.work_stats`, so an option's effect on work stands beside its
   effect on time.
4. Error, at ``error_scale`` times the resolution, of the Dr.Jit render with the
   run's options against two float64 renders of `reference.render`:

   * ``exact_*``: against the **exact** model (``mode="exact"``: every Gaussian in
     front of the camera on every pixel, every SH band of the workload; no
     ``alpha_min``, no alpha clamp, no radius cut-off, no early stop; the Jacobian clamp,
     part of the projection model, stays). This is the error an
     option trades for its speed; an option that brings the render closer to the
     Gaussian mixture (a lower ``alpha_min``) lowers it. It depends only on the
     workload and the scale, so it is computed once (in `prepare`, in the parent) and
     cached by content hash under ``$SPLATBENCH_CACHE/reference`` (default
     ``~/.cache/splatbench/reference``).
   * ``parity_max_abs``: against the reference with the **same** options
     (``mode="matched"``) -- the implementation's own float32 error (about 1e-6 when
     the rasterizer is right).

Metrics: `RasterRun`'s fields, with how reports show them; what reports show: `REPORT`. Curves: every timed call
(``fwd_runs_ms``, ``fwd_bwd_runs_ms``, ``default_fwd_runs_ms``,
``default_fwd_bwd_runs_ms``, pair i at index i).

Length: a little over 400 lines because a kind keeps its whole contract (config,
workloads, reference cache, run, metrics and their report) in one file, so that
adding or changing a kind touches one file (`splatbench.experiments.kinds`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import statistics
import sys
from pathlib import Path
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from splatbench.guards import check_sh_degree
from splatbench.errors import InputError
from splatbench.experiments.kind_report import (Claim, Comparison, Finding, FindingRules, KindReport, LoadMarks,
                                               Tradeoff, done_runs)
from splatbench.fsutil import cache_root
from splatbench.experiments.kinds import INLINE, RunKind, RunResult, metric, read_config
from splatbench.metrics.load import Load, own_share
from splatbench.raster.options import RasterOptions
from splatbench.report_files import write_binary
from splatbench.workloads import build_workload, parse_workload_name

#: `RasterOptions` fields a workload's camera sets (never in a raster run's config).
CAMERA_FIELDS = ("near", "far")
#: The SH degree of every workload: the bands the default options' side of a pair evaluates.
FULL_SH_DEGREE = 3
#: Options added after runs were recorded, with the value those runs had implicitly: at that
#: value an option is left out of the run id (`identity`), so those runs keep their ids.
IMPLICIT_BEFORE = {"pixel_block": 4}
#: What a run measures, in the resolved config (so in the run id): 2 = error against the
#: exact model and the median of per-pair time ratios (1, unnamed: error against the
#: default-option reference, ratio of medians). Results measured otherwise are never reused.
PROTOCOL = 2
#: Fewest timed pairs a run may use (a bootstrap interval of a median needs several).
MIN_PAIRS = 7

@dataclasses.dataclass(frozen=True, kw_only=True)
class RasterRun(RunResult):
    """What one raster run measures (module doc): each field a table column ``metric.<name>``,
    with how a report shows it and what it means. Curves: every timed call."""

    fwd_ms: float = metric("forward (ms)", ".1f", "ms", "lower", "median forward time at full resolution (ms)",
                           bounds=(0.0, math.inf))
    fwd_bwd_ms: float = metric("fwd+bwd (ms)", ".1f", "ms", "lower",
                               "median forward + backward time at full resolution (ms)", bounds=(0.0, math.inf))
    fwd_rel: float = metric(meaning="median over timed pairs of forward time / the default options' (same process, "
                                    "alternately; < 1: faster)")
    fwd_rel_low: float = metric(meaning="low end of the 95 % bootstrap interval of fwd_rel")
    fwd_rel_high: float = metric(meaning="high end of the 95 % bootstrap interval of fwd_rel")
    fwd_bwd_rel: float = metric("fwd+bwd / default (median of pairs)", ".3f", "", "lower",
                                "median over timed pairs of forward + backward time / the default options' "
                                "(< 1: faster)", bounds=(0.0, math.inf))
    fwd_bwd_rel_low: float = metric("bootstrap low", ".3f", interval=False,
                                    meaning="low end of the 95 % bootstrap interval of fwd_bwd_rel")
    fwd_bwd_rel_high: float = metric("bootstrap high", ".3f", interval=False,
                                     meaning="high end of the 95 % bootstrap interval of fwd_bwd_rel")
    timed_pairs: int = metric(meaning="timed A B pairs (the run's options, then the defaults)")
    default_fwd_ms: float = metric(meaning="median forward time with the default options, in the same run (ms)")
    default_fwd_bwd_ms: float = metric(meaning="median forward + backward time with the default options, in the "
                                               "same run (ms)")
    load_before: float = metric(meaning="1-minute load average before the timed pairs")
    load_after: float = metric(meaning="1-minute load average after them")
    own_cpu: float = metric(meaning="this process's CPU use during the timed pairs (CPU seconds / wall seconds, "
                                    "in cores)")
    own_before: float = metric(meaning="this process's own share of the load average when the timed pairs started "
                                       "(its earlier CPU use: warm-up, the previous run's error renders), an "
                                       "exponential moving average")
    load_other: float = metric(meaning="estimated load of other processes: the largest of load(t) - own_before * "
                                       "exp(-t / 60 s) - own_cpu * (1 - exp(-t / 60 s)) over the section's samples "
                                       "(splatbench.metrics.load)")
    cores: int = metric(meaning="CPU cores this process may use")
    loaded: int = metric("loaded (fraction of runs)", ".2f", interval=False,
                         meaning="1 when load_other exceeded cores / 2: timings not trusted, left out of the "
                                 "findings")
    exact_psnr: float = metric("PSNR to exact (dB)", ".2f", "dB", "higher",
                               "PSNR (dB) of the render against the exact Gaussian mixture (reference mode "
                               "'exact', every SH band; capped at 200)")
    exact_max_abs: float = metric("max abs error to exact", ".2e", "", "lower",
                                  "largest |render - exact| over pixels and channels")
    exact_mean_abs: float = metric(meaning="mean |render - exact|")
    parity_max_abs: float = metric("parity max abs", ".1e", "", "lower",
                                   "largest |render - float64 reference with the same options| (implementation "
                                   "error)")
    pairs: int = metric("pairs", ".0f", meaning="Gaussian-tile pairs composited (full resolution)")
    evaluations: int = metric("evaluations performed", ".3g",
                              meaning="pixel-Gaussian evaluations compositing performs per view "
                                      "(`splatbench.raster.work_stats`: per SIMD packet of a tile's lanes, its "
                                      "lanes' blocks x the longest block list; early stop ignored; full resolution)")
    useful_evaluations: int = metric("evaluations useful", ".3g",
                                     meaning="of those, the evaluations inside the Gaussian's support (within the "
                                             "cutoff and alpha >= alpha_min), where it can change the pixel")
    visible: int = metric(meaning="Gaussians that survived culling (full resolution)")
    n: int = metric(meaning="Gaussians in the workload")
    width: int = metric(meaning="image width (pixels)")
    height: int = metric(meaning="image height (pixels)")
    error_width: int = metric(meaning="width of the error measurement (pixels)")
    error_height: int = metric(meaning="its height")
    device: str = metric(meaning="where the rasterizer ran ('cpu' or 'cuda')")


# --------------------------------------------------------------------------- config
@dataclasses.dataclass(frozen=True)
class RasterConfig:
    """One raster run (module doc): a workload, the rasterizer's options and how to measure them.

    scene, seed: the workload (`splatbench.workloads.parse_workload_name`) and its seed;
    options: the rasterizer's options, written at the config's top level (``alpha_min = 0.01``;
    every `RasterOptions` field but ``near`` and ``far``, which the workload's camera sets);
    sh_degree: the SH bands evaluated (the workloads hold `FULL_SH_DEGREE`); repeats: the timed A B
    pairs (the run's options, then the defaults), at least `MIN_PAIRS`; error_scale: the resolution
    factor of the error measurement (0 < s <= 1), so that the float64 reference stays affordable;
    protocol: what a run measures (`PROTOCOL`; set by the kind, never in a file).
    """

    scene: str = ""
    seed: int = 0
    options: RasterOptions = dataclasses.field(default_factory=RasterOptions, metadata={INLINE: True})
    sh_degree: int = FULL_SH_DEGREE
    repeats: int = MIN_PAIRS
    error_scale: float = 0.5
    protocol: int = PROTOCOL

    def __post_init__(self) -> None:
        parse_workload_name(self.scene)
        for name in CAMERA_FIELDS:
            if getattr(self.options, name) is not None:
                raise InputError(f"{name}: set by the workload's camera, not by a raster run")
        check_sh_degree("sh_degree", self.sh_degree)
        if self.repeats < MIN_PAIRS:
            raise InputError(f"repeats: expected at least {MIN_PAIRS} timed pairs (a bootstrap interval of the "
                             f"median ratio needs several), got {self.repeats}")
        if not 0 < self.error_scale <= 1:
            raise InputError(f"error_scale: expected a factor in (0, 1], got {self.error_scale!r}")
        if self.protocol != PROTOCOL:
            raise InputError(f"protocol: set by the raster kind (what a run measures: {PROTOCOL}), "
                             f"got {self.protocol!r}")

    def to_dict(self) -> dict[str, Any]:
        """The resolved config, flat as a file writes it: every option, the measurement's fields, the
        workload and `PROTOCOL`; what the run id hashes."""
        return {**self.options.to_dict(), "sh_degree": self.sh_degree, "repeats": self.repeats,
                "error_scale": self.error_scale, "scene": self.scene, "seed": self.seed, "protocol": self.protocol}


def validate(config: dict[str, Any]) -> None:
    """One-line `InputError` naming the first bad field (`RasterConfig`; the SH degree by the one
    check of every SH degree, `check_sh_degree`, before its type is read)."""
    check_sh_degree("sh_degree", config.get("sh_degree", FULL_SH_DEGREE))
    read_config(RasterConfig, config)


def resolve(config: dict[str, Any]) -> dict[str, Any]:
    """Every field filled in (`RasterConfig.to_dict`); numbers normalised (``alpha_min = 1`` and
    ``1.0`` are one run); ``protocol`` (`PROTOCOL`) added."""
    return read_config(RasterConfig, config).to_dict()


def identity(config: dict[str, Any]) -> dict[str, Any]:
    """What the run id hashes of a resolved config: the config without the `IMPLICIT_BEFORE`
    options at the values runs had before those options existed."""
    return {k: v for k, v in config.items() if not (k in IMPLICIT_BEFORE and v == IMPLICIT_BEFORE[k])}


# --------------------------------------------------------------------------- reference
def cache_dir() -> Path:
    """``$SPLATBENCH_CACHE/reference``, else ``~/.cache/splatbench/reference``."""
    return cache_root() / "reference"


def _reference_sources() -> str:
    import reference

    folder = Path(reference.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(folder.glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def reference_render(workload, scale: float, *, sh_degree: int | None = None, **options) -> np.ndarray:
    """[H', W', 3] float64 `reference.render` (mode "matched") of ``workload`` at ``scale``
    times its resolution, with ``options`` (reference names; the camera's near/far)."""
    from splatbench.backends import reference_render as oracle

    g = workload.gaussians
    cam = workload.camera if scale == 1 else workload.camera.scaled(scale)
    out = oracle(options, g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, cam, mode="matched",
                 sh_degree=sh_degree)
    return np.asarray(out.rgb, dtype=np.float64)


def exact_model(scene: str, seed: int, scale: float) -> np.ndarray:
    """[H', W', 3] float64 render of the exact Gaussian mixture (`reference.render` with
    ``mode="exact"``, every SH band) of a workload at ``scale``, cached by content
    (workload, seed, scale, reference sources); computed on a miss."""
    kind, _ = parse_workload_name(scene)
    key = {"scene": scene, "seed": seed if kind == "synthetic" else 0, "scale": scale, "mode": "exact",
           "reference": _reference_sources()}
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]
    path = cache_dir() / f"{scene}-s{key['seed']}-exact-{digest}.npy"
    if path.is_file():
        try:
            from splatbench.safeio import read_npy

            return read_npy(path, what=str(path))  # header checked against the file; no pickle
        except (OSError, ValueError):  # InputError is a ValueError
            pass  # a damaged file: compute again
    from splatbench.backends import reference_render as oracle

    w = build_workload(scene, seed)
    g, cam = w.gaussians, (w.camera if scale == 1 else w.camera.scaled(scale))
    out = oracle(None, g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, cam, mode="exact")
    rgb = np.asarray(out.rgb, dtype=np.float64)

    write_binary(path, lambda stream: np.save(stream, rgb))
    return rgb


def prepare(configs: list[dict[str, Any]]) -> None:
    """Compute (or find cached) every exact-model render the pending runs need, once, in the parent."""
    seen: set[tuple] = set()
    for cfg in (read_config(RasterConfig, c) for c in configs):
        kind, _ = parse_workload_name(cfg.scene)
        key = (cfg.scene, cfg.seed if kind == "synthetic" else 0, cfg.error_scale)
        if key not in seen:
            seen.add(key)
            exact_model(*key)
    if seen:
        print(f"reference: {len(seen)} exact-model render(s) ready in {cache_dir()}", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- run
def run(config: dict[str, Any], workdir: Path, prepared: None) -> RasterRun:
    """Time the rasterizer on the workload with the run's options; measure its error
    (``prepared``: None; `prepare` leaves the exact-model renders in the cache)."""
    import torch

    from splatbench.metrics.machine import resolve_device
    from splatbench.metrics.timing import forward_backward_with_init, forward_with_init, time_runs, torch_params
    from splatbench.metrics.stats import bootstrap_median_ratio
    from splatbench.metrics.image import psnr
    from splatbench.raster import render, work_stats

    own_share()  # a checkpoint of the own-load tracker: what ran before this run, then the warm-up
    cfg = read_config(RasterConfig, config)
    workload = build_workload(cfg.scene, cfg.seed)
    degree = cfg.sh_degree
    options = cfg.options
    defaults = RasterOptions(device=cfg.options.device)
    full = torch_params(workload.gaussians)
    params = (*full[:4], full[4][:, : (degree + 1) ** 2].contiguous())
    closures = {}
    for name, p, opts, d in (("run", params, options, degree), ("default", full, defaults, FULL_SH_DEGREE)):
        closures[name] = (forward_with_init(p, workload.camera, opts, d),
                          forward_backward_with_init(p, workload.camera, opts, d))
        closures[name][1]()
        closures[name][0]()  # warm-up: kernels compile or load from Dr.Jit's cache
    times: dict[str, list[float]] = {k: [] for k in ("fwd", "fwd_bwd", "default_fwd", "default_fwd_bwd")}
    stats = None
    load = Load.start()
    for _ in range(cfg.repeats):  # A B A B ...: both sides of a pair see the same load
        for name, prefix in (("run", ""), ("default", "default_")):
            s, st = time_runs(closures[name][0], 1)
            times[prefix + "fwd"] += s
            stats = st if name == "run" else stats
            times[prefix + "fwd_bwd"] += time_runs(closures[name][1], 1)[0]
    load = load.stop()
    med = {k: statistics.median(v) for k, v in times.items()}
    fwd_rel = bootstrap_median_ratio(times["fwd"], times["default_fwd"])
    fwd_bwd_rel = bootstrap_median_ratio(times["fwd_bwd"], times["default_fwd_bwd"])

    work = work_stats(workload.gaussians, workload.camera, options)
    scale = cfg.error_scale
    small = workload.camera if scale == 1 else workload.camera.scaled(scale)
    fast = render(workload.gaussians, small, sh_degree=degree, options=options).rgb.astype(np.float64)
    exact = exact_model(cfg.scene, cfg.seed, scale)
    matched = reference_render(workload, scale, sh_degree=degree, **options.to_dict())
    err = np.abs(fast - exact)
    return RasterRun(
        fwd_ms=round(1e3 * med["fwd"], 3), fwd_bwd_ms=round(1e3 * med["fwd_bwd"], 3),
        fwd_rel=round(fwd_rel.estimate, 4), fwd_rel_low=_r4(fwd_rel.low), fwd_rel_high=_r4(fwd_rel.high),
        fwd_bwd_rel=round(fwd_bwd_rel.estimate, 4), fwd_bwd_rel_low=_r4(fwd_bwd_rel.low),
        fwd_bwd_rel_high=_r4(fwd_bwd_rel.high), timed_pairs=cfg.repeats,
        default_fwd_ms=round(1e3 * med["default_fwd"], 3), default_fwd_bwd_ms=round(1e3 * med["default_fwd_bwd"], 3),
        **load.metrics(),
        exact_psnr=round(min(psnr(fast, exact, clamp=False), 200.0), 4), exact_max_abs=float(err.max()),
        exact_mean_abs=float(err.mean()), parity_max_abs=float(np.abs(fast - matched).max()),
        pairs=int(stats.num_pairs), evaluations=work.performed, useful_evaluations=work.useful,
        visible=int(torch.as_tensor(stats.visible).sum()),
        n=len(workload.gaussians), width=workload.camera.width, height=workload.camera.height,
        error_width=small.width, error_height=small.height, device=resolve_device(options.device),
        curves={f"{k}_runs_ms": [round(1e3 * s, 3) for s in v] for k, v in times.items()})


def _r4(x: float) -> float:
    return round(x, 4) if math.isfinite(x) else math.nan


# --------------------------------------------------------------------------- report
def parity_finding(runs: pd.DataFrame, min_effect: Mapping[str, float] | None = None) -> Finding | None:
    """The largest implementation error against the matched reference (`KindReport.run_findings`)."""
    col = "metric.parity_max_abs"
    done = done_runs(runs)
    if col not in done.columns or done[col].dropna().empty:
        return None
    values = pd.to_numeric(done[col])
    worst = float(values.max())
    row = done.loc[values.idxmax()]
    # the worst run's cell: the axes where it differs from the most common value (the base, one at a time)
    axes = [c for c in done.columns if c.startswith("axis.")]
    cell = ", ".join(f"{c[5:]}={row[c]}" for c in axes if row[c] != done[c].mode().iloc[0]) or "the base"
    text = f"{worst:.1e}"
    claim = Claim("parity", "", "", "parity_max_abs", "max", worst, text)
    return Finding("parity", [f"- Against the float64 reference with the *same* options, the largest difference "
                              f"over all {len(done)} runs is {text} ({row['scene']}, {cell}). Most of a pixel's "
                              f"difference is float32 rounding (~1e-6); a pixel where float32 and float64 fall on "
                              f"different sides of a threshold (alpha_min, the cutoff, the early stop) differs by a "
                              f"whole contribution, up to about alpha_min x its colour, which is why the largest "
                              f"difference grows with alpha_min. The exact-error columns above are what each option "
                              f"trades in against the exact Gaussian mixture."],
                   [claim])


#: What the reports of raster runs show (`splatbench.experiments.kind_report`).
REPORT = KindReport(
    metrics=("fwd_ms", "fwd_bwd_ms", "fwd_bwd_rel", "fwd_bwd_rel_low", "fwd_bwd_rel_high", "exact_psnr",
             "exact_max_abs", "parity_max_abs", "pairs", "evaluations", "useful_evaluations", "loaded"),
    # minimum effects (docs/reports.md): a 5 % speed change, 0.1 dB of error to the exact model, 5 % pairs
    rules=FindingRules("fwd_bwd_rel", (Comparison("fwd_bwd_rel", "mean", 1.0, min_effect=0.05),
                                       Comparison("exact_psnr", "diff", min_effect=0.1),
                                       Comparison("pairs", "ratio", min_effect=0.05))),
    tradeoffs=(Tradeoff("fwd_bwd_rel", "exact_psnr", "speed_vs_error",
                        "Rasterizer speed against error to the exact Gaussian mixture (mean over seeds)"),),
    load=LoadMarks("loaded", "all"),
    run_findings=(parity_finding,),
)

#: The ``raster`` kind (``kind = "raster"``).
RASTER = RunKind(name="raster", validate=validate, run=run, config=RasterConfig, result=RasterRun, resolve=resolve,
                 identity=identity, prepare=prepare,
                 description="time the rasterizer under options against the defaults; error against the exact model",
                 report=REPORT)

__all__ = ["RASTER", "RasterConfig", "RasterRun", "REPORT", "FULL_SH_DEGREE", "reference_render",
           "exact_model", "cache_dir", "MIN_PAIRS", "PROTOCOL"]
