"""How differences in AlexNet LPIPS between models scale to differences in LPIPS-VGG, measured on finished runs.

    python tools/lpips_scale.py RESULTS_DIR EXPERIMENT [--out FILE] [--boot N]
    python tools/lpips_scale.py --from FILE [--out FILE] [--boot N]     # re-estimate a written JSON's values

Why: the train reports' LPIPS is AlexNet with inputs scaled to [-1, 1] (``eval.lpips_net = "alex"``, the
lpips package's convention: gsplat, NerfBaselines); the published LPIPS the minimum effect is derived from
(3DGS paper Table 1) is graphdeco's: VGG-16 fed [0, 1] images unscaled. The two nets' scales differ, so a
threshold on one is not a threshold on the other (`splatbench.experiments.train_kind.MIN_EFFECT`).

What it does: for each done record of ``RESULTS_DIR/EXPERIMENT/`` whose work folder (``work/<run_id>/``:
``config.toml``, ``point_cloud.ply``, ``result.json``) holds the run's final model, renders its test views as
the run's final evaluation did (`splatbench.train.reevaluate.evaluate_saved_run`: `Trainer.evaluate` of the
saved PLY at the SH degree the run ended at) and computes each view's LPIPS in both conventions (`ALEX`,
`VGG`). A run is used only where the evaluation reproduces the record's test PSNR to within float32
rendering noise (`splatbench.train.reevaluate.tolerance_db`: the same renders). A run a runner holds
(``claims/<run_id>.claim``) or a record not "done" is left alone. Nothing is written there: the tool only reads.

The estimate (`estimate`): within each scene, each test view's values are centred on their mean over the
scene's runs (what is left is how the models differ on the same view: the view's own difficulty is gone),
and the slope of centred AlexNet on centred VGG is the **reduced major axis** (geometric-mean regression:
sign(r) · SD(AlexNet) / SD(VGG), the geometric mean of OLS AlexNet-on-VGG and the inverse of OLS
VGG-on-AlexNet, which bracket it and are given too). Why not OLS: neither net is the error-free variable
(they disagree view by view on which differences matter), and OLS of one on the other is attenuated by
that disagreement toward 0 (and the reverse regression away from it), so each would convert a difference
and its back-conversion inconsistently; the reduced major axis is symmetric and does not depend on either
net's units (plain total least squares would weigh both nets' residuals equally in raw units: what is
being measured is that their units differ). The **pooled** slope weighs every scene equally: each scene's
centred values (both nets alike, which keeps its slope) are divided by the RMS of its centred VGG values,
so a scene whose LPIPS varies more does not decide the pool. Intervals: percentile bootstrap over runs
(runs resampled with replacement within each scene, everything recomputed). Also given: the same slopes
on each run's mean over its views (what a report compares), centred per scene.

The implied AlexNet threshold is `PUBLISHED_LPIPS_GAIN` × slope × (`PSNR_MIN_EFFECT` / `PUBLISHED_PSNR_GAIN`):
the same share of graphdeco's 7K -> 30K gain as 0.1 dB is of its PSNR gain, on the AlexNet scale.

Writes ``--out`` (JSON: each run's per-view values, so anyone can re-estimate without rendering, with
``--from``; the per-scene and pooled slopes with intervals; the implied thresholds) and prints a markdown
summary. Use ``nice``: it renders each run's test views once and runs VGG-16 on each (seconds a run at
<= 160 px). The measurement behind the train kind's LPIPS minimum effects: docs/data/lpips_scale.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from splatbench.errors import InputError
from splatbench.experiments.store import RunRecord, experiment_dir, read_records

#: The reports' LPIPS (`splatbench.train.config.EvalConfig` defaults): AlexNet, inputs scaled to [-1, 1].
ALEX = ("alex", True)
#: graphdeco's (its metrics.py; the 3DGS paper's published numbers): VGG-16, [0, 1] fed unscaled.
VGG = ("vgg", False)
#: 3DGS paper Table 1, mean over Mip-NeRF 360, Tanks&Temples, Deep Blending of the 7K -> 30K change
#: (/work/shared/PROTOCOL.md): PSNR +1.61, +1.94, +1.63 dB; LPIPS-VGG -0.065, -0.097, -0.074.
PUBLISHED_PSNR_GAIN = 1.73
PUBLISHED_LPIPS_GAIN = 0.079
#: The train reports' PSNR minimum effect (dB): the share of the published gain the LPIPS threshold keeps.
PSNR_MIN_EFFECT = 0.1
#: Bootstrap resamples (a 95 % percentile interval's ends move by well under 1 % of the slope between reruns
#: at this count: the 2.5 % tail holds 50 resamples).
BOOT = 2000


@dataclass(frozen=True)
class RunViews:
    """One run's test views measured again: its record's identity, the record's test PSNR and LPIPS
    against the evaluation's (the check that these are the run's own renders), and each test view's
    LPIPS in both conventions (test-split order)."""

    run_id: str
    scene: str
    labels: dict
    seed: int
    record_psnr: float
    psnr: float
    record_lpips: float | None
    record_lpips_net: str
    alex: list[float]
    vgg: list[float]


def measure_run(folder: Path, record: RunRecord) -> RunViews:
    """`RunViews` of one done run of the experiment folder ``folder``; one-line `InputError` where its
    work folder lacks the final model or its evaluation does not reproduce its recorded test PSNR."""
    from splatbench.train.reevaluate import (CONFIG_FILE, MODEL_FILE, RESULT_FILE, evaluate_saved_run,  # late: torch
                                             tolerance_db)

    # a reused run's model is where it ran: its original experiment's folder (`reused_from`)
    work = folder.parent / (record.reused_from or folder.name) / "work" / record.run_id
    missing = [name for name in (CONFIG_FILE, MODEL_FILE, RESULT_FILE) if not (work / name).is_file()]
    if missing:
        raise InputError(f"{record.run_id}: {', '.join(missing)} missing in {work} (no final model to evaluate)")
    want = record.metrics.get("test_psnr")
    if not isinstance(want, (int, float)) or not math.isfinite(want):
        raise InputError(f"{record.run_id}: the record has no test PSNR to check the evaluation against")
    ev = evaluate_saved_run(work, lpips=[ALEX, VGG])
    got, tol = float(np.mean(ev.per_view_psnr)), tolerance_db(ev.per_view_psnr)
    if not abs(got - want) <= tol:
        raise InputError(f"{record.run_id}: the saved model evaluates to {got:.6f} dB, the record says {want:.6f} dB "
                         f"(beyond the {tol:.1e} dB of float32 rendering noise): not the run's own renders; left out")
    lp = record.metrics.get("test_lpips")
    return RunViews(record.run_id, record.scene, dict(record.labels), record.seed, float(want), got,
                    float(lp) if isinstance(lp, (int, float)) else None, str(record.metrics.get("lpips_net", "")),
                    [float(x) for x in ev.per_view_lpips[ALEX]], [float(x) for x in ev.per_view_lpips[VGG]])


# --------------------------------------------------------------------------- the estimate
@dataclass(frozen=True)
class Slopes:
    """Slopes of centred AlexNet LPIPS on centred VGG LPIPS over ``points`` points: ``rma`` (reduced
    major axis, the estimate), ``ols`` (OLS AlexNet on VGG) and ``ols_inverse`` (1 / OLS VGG on
    AlexNet), which bracket it; ``r`` the correlation."""

    rma: float
    ols: float
    ols_inverse: float
    r: float
    points: int


def centred(values: np.ndarray) -> np.ndarray:
    """[R, V] (runs x views of one scene) -> [R, V]: each view's column minus its mean over the runs."""
    return values - values.mean(axis=0, keepdims=True)


def slopes(a: np.ndarray, v: np.ndarray) -> Slopes:
    """`Slopes` of ``a`` (centred AlexNet) on ``v`` (centred VGG), flat arrays of one length, through
    the origin (both are centred). NaN where either has no spread."""
    saa, svv, sav = float(a @ a), float(v @ v), float(a @ v)
    if saa <= 0 or svv <= 0:
        return Slopes(math.nan, math.nan, math.nan, math.nan, a.size)
    r = sav / math.sqrt(saa * svv)
    return Slopes(math.copysign(math.sqrt(saa / svv), sav), sav / svv, saa / sav if sav else math.nan, r, a.size)


def scene_slopes(alex: np.ndarray, vgg: np.ndarray, per_view: bool = True) -> Slopes:
    """`Slopes` of one scene's [R, V] values: per view centred over runs (``per_view``), or each run's
    mean over its views centred over runs."""
    if not per_view:
        alex, vgg = alex.mean(axis=1, keepdims=True), vgg.mean(axis=1, keepdims=True)
    return slopes(centred(alex).ravel(), centred(vgg).ravel())


def pooled_slopes(scenes: dict[str, tuple[np.ndarray, np.ndarray]], per_view: bool = True) -> Slopes:
    """`Slopes` over every scene's centred values, each scene weighed equally: both nets' centred values
    divided by the RMS of the scene's centred VGG values (one factor for both: the scene's slope is kept)."""
    a_all, v_all = [], []
    for alex, vgg in scenes.values():
        if not per_view:
            alex, vgg = alex.mean(axis=1, keepdims=True), vgg.mean(axis=1, keepdims=True)
        a, v = centred(alex).ravel(), centred(vgg).ravel()
        rms = math.sqrt(float(v @ v) / v.size)
        if rms > 0:
            a_all.append(a / rms)
            v_all.append(v / rms)
    if not a_all:
        return Slopes(math.nan, math.nan, math.nan, math.nan, 0)
    return slopes(np.concatenate(a_all), np.concatenate(v_all))


def _interval(values: list[float]) -> list[float] | None:
    finite = np.asarray([x for x in values if math.isfinite(x)])
    return [float(np.percentile(finite, 2.5)), float(np.percentile(finite, 97.5))] if finite.size else None


def estimate(scenes: dict[str, tuple[np.ndarray, np.ndarray]], boot: int = BOOT, seed: int = 0) -> dict:
    """Per-scene and pooled `Slopes` of ``scenes`` (name -> ([R, V] AlexNet, [R, V] VGG), the same R runs
    and V test views in both), per view and on run means, each reduced-major-axis slope with a 95 %
    percentile bootstrap interval over runs (``boot`` resamples of each scene's runs with replacement,
    seeded by ``seed``). A scene needs 2 runs or more (one has nothing to centre)."""
    for name, (alex, vgg) in scenes.items():
        if alex.shape != vgg.shape or alex.ndim != 2 or alex.shape[0] < 2:
            raise InputError(f"{name}: expected [runs >= 2, views] values of one shape for both nets, "
                             f"got {alex.shape} and {vgg.shape}")
    rng = np.random.default_rng(seed)
    draws = [{name: rng.integers(0, alex.shape[0], alex.shape[0]) for name, (alex, _) in scenes.items()}
             for _ in range(boot)]

    def resampled(d):
        return {name: (alex[d[name]], vgg[d[name]]) for name, (alex, vgg) in scenes.items()}

    out: dict = {"scenes": {}, "pooled": {}}
    for per_view, key in ((True, "per_view"), (False, "run_means")):
        for name, (alex, vgg) in scenes.items():
            s = scene_slopes(alex, vgg, per_view)
            ci = _interval([scene_slopes(alex[d[name]], vgg[d[name]], per_view).rma for d in draws])
            out["scenes"].setdefault(name, {"runs": alex.shape[0], "views": alex.shape[1]})[key] = {**asdict(s), "rma_ci": ci}
        s = pooled_slopes(scenes, per_view)
        out["pooled"][key] = {**asdict(s), "rma_ci": _interval([pooled_slopes(resampled(d), per_view).rma
                                                                for d in draws])}
    out["pooled"]["runs"] = sum(alex.shape[0] for alex, _ in scenes.values())
    return out


def threshold(slope: float) -> float:
    """The AlexNet minimum effect a VGG-to-AlexNet slope implies (module doc)."""
    return PUBLISHED_LPIPS_GAIN * slope * PSNR_MIN_EFFECT / PUBLISHED_PSNR_GAIN


# --------------------------------------------------------------------------- the tool
def scene_arrays(runs: list[RunViews]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """scene -> ([R, V] AlexNet, [R, V] VGG) of ``runs``; a scene whose runs have different view counts is
    a one-line `InputError` (its dataset changed between runs)."""
    out = {}
    for scene in sorted({r.scene for r in runs}):
        mine = [r for r in runs if r.scene == scene]
        if len({len(r.alex) for r in mine}) != 1:
            raise InputError(f"{scene}: its runs have {sorted({len(r.alex) for r in mine})} test views: the dataset changed")
        out[scene] = (np.array([r.alex for r in mine]), np.array([r.vgg for r in mine]))
    return out


def summary(result: dict) -> str:
    """The markdown table of ``result`` (`main`'s JSON)."""
    def row(name, entry, runs, views):
        pv, rm = entry["per_view"], entry["run_means"]
        ci = pv["rma_ci"] or [math.nan, math.nan]
        rci = rm["rma_ci"] or [math.nan, math.nan]
        return (f"| {name} | {runs} | {views} | {pv['rma']:.3f} [{ci[0]:.3f}, {ci[1]:.3f}] | {pv['ols']:.3f} – "
                f"{pv['ols_inverse']:.3f} | {pv['r']:.2f} | {rm['rma']:.3f} [{rci[0]:.3f}, {rci[1]:.3f}] |")
    lines = [f"# LPIPS scale: AlexNet (scaled) against VGG (unscaled), {result['experiment']}", "",
             "| scene | runs | views | slope (RMA, per view) [95 % CI] | OLS – 1/OLS reverse | r | slope (run means) [95 % CI] |",
             "|---|---|---|---|---|---|---|"]
    for name, entry in result["scenes"].items():
        lines.append(row(name, entry, entry["runs"], entry["views"]))
    lines.append(row("pooled (scenes weighed equally)", result["pooled"], result["pooled"]["runs"], ""))
    t = result["threshold"]
    lines += ["", f"VGG threshold {t['vgg']:.5f} (= {PUBLISHED_LPIPS_GAIN} x {PSNR_MIN_EFFECT} / {PUBLISHED_PSNR_GAIN}); "
              f"implied AlexNet threshold {t['alex']:.5f} [95 % CI {t['alex_ci'][0]:.5f}, {t['alex_ci'][1]:.5f}] "
              f"(pooled per-view slope)."]
    return "\n".join(lines)


def measure(results: Path, experiment: str) -> tuple[list[RunViews], list[str]]:
    """(`RunViews` of each run measured, a line for each left out) of ``results/experiment`` (module doc)."""
    folder = experiment_dir(results, experiment)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such experiment folder")
    runs: list[RunViews] = []
    skipped: list[str] = []
    for record in read_records(folder).values():
        if record.status != "done":
            skipped.append(f"{record.run_id}: status {record.status!r}")
        elif (folder / "claims" / f"{record.run_id}.claim").exists():
            skipped.append(f"{record.run_id}: held by a runner (claims/{record.run_id}.claim)")
        else:
            try:
                run = measure_run(folder, record)
            except InputError as exc:
                skipped.append(str(exc))
            else:
                runs.append(run)
                print(f"{run.run_id} {run.scene} {run.labels} seed {run.seed}: {len(run.alex)} views, AlexNet "
                      f"{np.mean(run.alex):.5f} (record {run.record_lpips}), VGG {np.mean(run.vgg):.5f}", flush=True)
                continue
        print(f"skipped {skipped[-1]}", flush=True)
    return runs, skipped


def read_runs(path: Path) -> tuple[str, list[RunViews], list[str]]:
    """(experiment, runs, lines left out) of a JSON this tool wrote; one-line `InputError` otherwise."""
    from splatbench.fsutil import read_text

    try:
        data = json.loads(read_text(path, "lpips scale"))
        runs = [RunViews(**r) for r in data["runs"]]
        if not all(len(r.alex) == len(r.vgg) and all(math.isfinite(x) for x in (*r.alex, *r.vgg)) for r in runs):
            raise ValueError("a run's values are not finite pairs")
        return str(data["experiment"]), runs, list(data.get("skipped", []))
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: not a tools/lpips_scale.py output ({exc}); rerun it on the results") from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path, nargs="?", help="the results folder (e.g. ~/.cache/splatbench/results)")
    parser.add_argument("experiment", nargs="?", help="the experiment's name (its folder under RESULTS_DIR)")
    parser.add_argument("--from", dest="source", type=Path, help="re-estimate the per-view values of a JSON this tool wrote")
    parser.add_argument("--out", type=Path, help="write the JSON here (default: print the summary only)")
    parser.add_argument("--boot", type=int, default=BOOT, help=f"bootstrap resamples (default {BOOT})")
    args = parser.parse_args(argv)
    if (args.source is None) == (args.experiment is None):
        print("error: give RESULTS_DIR EXPERIMENT (measure) or --from FILE (re-estimate), one of them", file=sys.stderr)
        return 2
    if args.boot < 100:
        print(f"error: --boot {args.boot}: at least 100 resamples for a 95 % interval", file=sys.stderr)
        return 2
    from splatbench.metrics.perceptual import convention
    from splatbench.versions import code_version

    code = code_version()  # read before measuring: the code that measures
    try:
        if args.source is not None:
            experiment, runs, skipped = read_runs(args.source)
        else:
            experiment, (runs, skipped) = args.experiment, measure(args.results, args.experiment)
        scenes = {name: arrays for name, arrays in scene_arrays(runs).items() if arrays[0].shape[0] >= 2}
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not scenes:
        print(f"error: {experiment}: no scene with 2 or more runs to measure", file=sys.stderr)
        return 1
    result = {"experiment": experiment, "tool": "tools/lpips_scale.py", "code": code,
              "conventions": {"alex": convention(*ALEX), "vgg": convention(*VGG)},
              "estimator": "reduced major axis of within-(scene, view) centred AlexNet on centred VGG; pooled with "
                           "scenes weighed equally; 95 % percentile bootstrap over runs within scenes",
              "boot": args.boot, **estimate(scenes, args.boot)}
    slope = result["pooled"]["per_view"]["rma"]
    ci = result["pooled"]["per_view"]["rma_ci"]
    result["threshold"] = {"vgg": threshold(1.0), "alex": threshold(slope), "alex_ci": [threshold(x) for x in ci],
                           "published": {"psnr_gain_db": PUBLISHED_PSNR_GAIN, "lpips_vgg_gain": PUBLISHED_LPIPS_GAIN,
                                         "psnr_min_effect_db": PSNR_MIN_EFFECT}}
    result["recheck"] = {"max_abs_psnr_db": max(abs(r.psnr - r.record_psnr) for r in runs),
                         "max_abs_alex_vs_record": max((abs(float(np.mean(r.alex)) - r.record_lpips) for r in runs
                                                        if r.record_lpips is not None and r.record_lpips_net == "alex"),
                                                       default=None)}
    result["runs"] = [asdict(r) for r in runs]
    result["skipped"] = skipped
    print(summary(result))
    if args.out:
        args.out.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
