"""The ``train`` run kind: one `splatbench.train.train` run on a catalog scene, a dataset folder
or a teacher scene.

Config (the nested dict an experiment gives one run)::

    scene, seed          from the experiment's ``scenes`` / ``seeds`` (``seed`` is TrainConfig.seed)
    data.path            a dataset folder (a scene table ``{ name, path, downscale }``)
    data.model           a 3DGS PLY rendered as a teacher scene (``{ name, model, views,
                         resolution, up }``; splatbench.experiments.teacher), with data.views
                         (default 64), data.resolution (default 128) and data.up (default:
                         the PLY's hint, else -y)
    data.resolution      dataset image width in pixels (default: the scene rig's)
    data.views           views rendered, every 8th held out for testing (default: the rig's total)
    data.spp             Mitsuba samples per pixel (default: the rig's)
    data.test_spp        samples per pixel of the held-out views (default: data.spp); more
                         samples make cleaner test targets (their noise is a floor under
                         every run's test PSNR; docs/training.md)
    data.<DataConfig>    how the dataset is read (``data.downscale`` of a dataset folder,
                         ``data.masks``, ``data.layout``, ``data.test_every``)
    <any TrainConfig field or group> but ``dataset`` and ``out``, which are machine-specific:
                         the kind sets them (the dataset folder, the run's work folder);
                         groups as tables or dotted keys (``sh.degree``, ``strategy.name``,
                         ``strategy.cap_max``, ``raster.alpha_min``)

The ``data`` keys describe a scene: a key that does not apply to a run's scene type
(``spp`` for a teacher, ``resolution`` for a dataset folder, ``downscale`` for a rendered
scene) is left out of that run's resolved config, so a grid mixing the types can set
``data.resolution`` in its base; a scene table's own keys win over the base's.

How a config's keys are split and read into a `TrainConfig`, and what that config schedules
(`planned`, `opacity_reset_steps`), is `splatbench.experiments.train_config`, which the kind's
report hooks (`splatbench.experiments.train_report`) read too.

`resolve` fills every default in -- TrainConfig's (every group, ``raster`` included), the
rig's for ``data``, and the strategy's own fields in the ``strategy`` table -- so a field
written at its default is the same run as one left out, and a changed default makes new
runs. `identity` hashes a dataset folder's or a teacher model's content in place of its path
(`splatbench.data.content`), so the run ids of a grid over a user's data are the same in
every clone and change when the data does.

Datasets are rendered once, in the parent, by `prepare` (Mitsuba, cached by content
hash) into ``$SPLATBENCH_DATASETS`` (default ``./data/scenes``), read once there and
made absolute; `prepare` returns that folder (`Prepared`), which the runner hands every
worker with its run. Datasets are named ``<scene>-<W>-v<views>-s<spp>`` (``-t<test_spp>``
appended when the test views have their own spp). A worker calls
`splatbench.scenes.render_dataset` again, which finds the cache (or renders, on a
remote Dask worker that has no copy).

Metrics (`TrainRun`'s fields) and curves (`CURVE_KEYS`) are documented beside their names.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from pathlib import Path
from typing import Any

from splatbench.data.content import content_hash
from splatbench.errors import InputError
from splatbench.experiments.kind_report import Comparison, FindingRules, KindReport, LoadMarks, SettlingCurves, Tradeoff
from splatbench.experiments.kinds import KindProtocols, RunKind, RunResult, metric, metric_specs
from splatbench.experiments.train_config import (DATA_FIELDS, OWNED_FIELDS, opacity_reset_steps, planned, scene_type,
                                                 split, train_config)
from splatbench.experiments.train_report import (auto_sh_degree_note, how_read, lpips_conventions, lpips_note, memory_note,
                                                 model_bytes, model_size_note, outlier_view_finding, outlier_view_note,
                                                 check_schedule_note, protocol_lines, schedule_confound_note, smoke_test_line,
                                                 ssim_trained_note)
from splatbench.metrics.memory import reset_peak_rss
from splatbench.train.config import TrainConfig  # the kind's Config (loads torch: every use of the kind validates)

#: Environment variable naming the folder of rendered datasets.
DATASETS_ENV = "SPLATBENCH_DATASETS"
#: A teacher scene's ``data.views`` and ``data.resolution`` where its config sets none.
TEACHER_DEFAULTS = {"views": 64, "resolution": 128}

#: What a run records of what its strategy did besides its settings' names (`TopologyCounts`); None in
#: the metrics of a result written before they were recorded.
TOPOLOGY_METRICS = ("refinements", "opacity_resets", "cloned", "split", "pruned", "pruned_size", "relocated", "added")
#: LPIPS's minimum effect per convention (``(lpips_net, lpips_scale_inputs)`` as runs record them): the same
#: share (~6 %) of graphdeco's published 7K -> 30K gain as 0.1 dB is of its PSNR gain (3DGS paper Table 1,
#: mean over Mip-NeRF 360, Tanks&Temples, Deep Blending: +1.73 dB, -0.079 LPIPS), on each net's scale. The
#: published LPIPS is VGG fed [0, 1] unscaled (graphdeco's metrics.py): 0.079 x 0.1 / 1.73 = 0.0046 -> 0.005.
#: AlexNet with inputs scaled to [-1, 1] (the reports' default, ``eval.lpips_net = "alex"``) is on another
#: scale: between models on the same test views its differences are 0.974 [95 % CI 0.914, 1.118] times VGG's
#: (reduced major axis, scenes weighed equally; per scene 0.61 fox to 1.33 maryrose; on run means 0.88),
#: measured by tools/lpips_scale.py on sh_degree's 42 finished runs (docs/data/lpips_scale.json): 0.0046 x
#: 0.974 = 0.0045 -> 0.004. Both rounded to one significant figure (as SSIM's 0.0028 -> 0.003); 0.005 is at
#: the top of AlexNet's interval [0.0042, 0.0051], and every other estimate (run means, real captures alone:
#: 0.0039-0.0044) rounds to 0.004. The other two conventions have no measured scale: None, a difference is
#: judged by its interval alone (`lpips_min_effect`).
LPIPS_MIN_EFFECT: dict[tuple[str, bool], float] = {("alex", True): 0.004, ("vgg", False): 0.005}
#: The smallest differences that matter in practice (docs/reports.md, "Minimum effects"): a difference
#: whose interval lies within ± them reads "no practical difference". PSNR 0.1 dB; SSIM the same share
#: of graphdeco's published gain as LPIPS (+0.049 SSIM: 0.0028 -> 0.003); LPIPS the default convention's
#: (`LPIPS_MIN_EFFECT`; a report picks its runs' convention's, `lpips_min_effect`); times and Gaussian
#: counts as relative changes (10 %, 5 %). An experiment file's ``[report] min_effect`` overrides them.
MIN_EFFECT: dict[str, float] = {"test_psnr": 0.1, "test_ssim": 0.003, "test_lpips": LPIPS_MIN_EFFECT[("alex", True)],
                                "train_seconds": 0.10, "num_gaussians": 0.05}
#: Confound counts that count Gaussians (not events: refinements and opacity resets are always named).
GAUSSIAN_COUNTS = ("cloned", "split", "pruned", "pruned_size", "relocated", "added")
#: A Gaussian count is left out of "Also changed" where both cells' means are below this many per run: then
#: at most 20 Gaussians differ, under the 5 % minimum effect on the Gaussian count for any model of 400 or
#: more Gaussians and under 0.5 % of the smallest final model of any committed train report (4,757, the
#: fox's MCMC); e.g. "pruned for size 13.3 instead of 14.3" in a model of 25,000 (docs/reports.md,
#: "Confounds"). Event counts (refinements, opacity resets) have no floor: one reset more is a change.
CONFOUND_FLOOR = 20.0
#: Keys of the curves: the training history (every ``log_every`` steps) and the test evaluations; a run
#: with full step evaluations (a graphdeco protocol, or eval_steps) adds ``step_evaluations``, the list of
#: `splatbench.train.StepEvaluation` as objects.
CURVE_KEYS = ("step", "loss", "psnr", "num_gaussians", "eval_step", "eval_psnr", "eval_ssim", "eval_lpips")


@dataclasses.dataclass(frozen=True, kw_only=True)
class TrainRun(RunResult):
    """What one train run records (`TrainRun.of` a `splatbench.train.TrainResult`): each field a
    table column ``metric.<name>``, with how a report shows it and what it means."""

    # bounds: PSNR >= 0 (images in [0, 1]: MSE <= 1), SSIM in [-1, 1], LPIPS a distance >= 0, counts and times >= 0
    test_psnr: float | None = metric("test PSNR (dB)", ".2f", "dB", "higher",
                                     "mean PSNR (dB) of the final model on the test views", bounds=(0.0, math.inf))
    test_ssim: float | None = metric("SSIM", ".4f", "", "higher", "mean SSIM on the test views", bounds=(-1.0, 1.0))
    num_gaussians: int = metric("Gaussians", ".0f", meaning="Gaussians at the end", bounds=(0.0, math.inf))
    train_seconds: float = metric("train time (s)", ".1f", "s", "lower",
                                  "wall time of the optimisation loop (s; no evaluation, no I/O)", bounds=(0.0, math.inf))
    render_ms_per_view: float | None = metric("render (ms/view)", ".1f", "ms", "lower",
                                              "mean forward render time of a test view (ms)", bounds=(0.0, math.inf))
    sh_degree: int = metric(meaning="SH degree in use at the end (what 'auto' chose)")
    peak_rss_mb: float = metric(meaning="peak resident memory of the worker process over its life so far (MB): a "
                                        "worker runs several runs in turn, so it carries the peaks of the runs "
                                        "before this one (run_peak_rss_mb is the run's own)")
    iterations: int = metric(meaning="steps run")
    test_views: int = metric(meaning="views evaluated")
    dataset_hash: str | None = metric(meaning="content hash of the rendered dataset (scene files or teacher PLY, "
                                              "settings, renderer); None for a dataset folder")
    test_lpips: float | None = metric("LPIPS", ".4f", "", "lower",
                                      "mean LPIPS v0.1 on the test views (lower is better; net and inputs: "
                                      "`lpips_net`, `lpips_scale_inputs`, and the line below)", bounds=(0.0, math.inf))
    lpips_net: str = metric(meaning="LPIPS backbone of test_lpips: alex or vgg (empty: not computed)")
    lpips_scale_inputs: int = metric(meaning="1: LPIPS inputs scaled to [-1, 1] (the lpips package); 0: [0, 1] "
                                             "unscaled (graphdeco)")
    cpu_seconds: float = metric(meaning="CPU seconds of the worker process (all threads) over the optimisation loop")
    load_before: float | None = metric(meaning="1-minute load average when the run started (before warm-up)")
    load_after: float | None = metric(meaning="1-minute load average after the final evaluation")
    load_other: float | None = metric(meaning="estimated load of other processes (the largest sample less the "
                                              "run's own share; splatbench.metrics.load)")
    cores: int | None = metric(meaning="usable CPU cores")
    time_loaded: int = metric("timed under load (fraction of runs)", ".2f", interval=False,
                              meaning="1 when load_other exceeded cores / 2: the run's times are not trusted and "
                                      "are left out of the time comparisons and Pareto fronts of the findings "
                                      "(quality metrics are kept)")
    refinements: int | None = metric("refinements", ".0f", meaning="refinement steps the strategy made (densify / "
                                                                   "prune; MCMC: relocate / add)")
    opacity_resets: int | None = metric("opacity resets", ".0f", meaning="opacity resets the strategy made")
    cloned: int | None = metric("cloned", ".0f", meaning="Gaussians cloned, summed over the refinements")
    split: int | None = metric("split", ".0f", meaning="Gaussians split (each replaced by two children), summed "
                                                       "over the refinements")
    pruned: int | None = metric("pruned", ".0f", meaning="Gaussians pruned, summed over the refinements")
    pruned_size: int | None = metric("pruned for size", ".0f",
                                     meaning="of those pruned, the ones removed for their size (none while size "
                                             "pruning is off: reset_every = 0 turns it off)")
    relocated: int | None = metric("relocated", ".0f", meaning="MCMC: dead Gaussians relocated, summed over the "
                                                               "refinements")
    added: int | None = metric("added", ".0f", meaning="MCMC: Gaussians added, summed over the refinements")
    run_peak_rss_mb: float | None = metric("peak RSS (MB)", ".0f", "MB", "lower",
                                           "peak resident memory of the worker process during this run alone (MB; "
                                           "the high-water mark reset as the run starts: the whole process, Python, "
                                           "torch and the dataset included, not the model alone); unlike a time it "
                                           "does not depend on the machine's load, so a loaded run still measures "
                                           "it; None where the reset is unavailable and before it was recorded",
                                           default=None)
    init_method: str | None = metric(meaning="the initialisation that ran (what init = auto resolved to: surface, "
                                             "sfm or random); None before it was recorded", default=None)
    init_points: int | None = metric(meaning="Gaussians the run started from (its initial points); None before it "
                                             "was recorded", default=None)
    device: str | None = metric(meaning="where the rasterizer ran: 'cpu' (Dr.Jit's LLVM backend) or 'cuda' (what "
                                        "config.device, 'auto' by default, resolved to); None before it was "
                                        "recorded", default=None)
    background: str | None = metric(meaning="the RGB in [0, 1] behind the splats in every test render (and under "
                                            "the targets where the dataset has alphas or masks), 'r, g, b' (what "
                                            "background = 'auto' resolved to: TrainResult.background); None before "
                                            "it was recorded", default=None)
    background_source: str | None = metric(meaning="where the background came from: config, masks (a masked "
                                                   "capture: white), alpha / depth (the mean of the pixels the "
                                                   "dataset marks empty), none (black: it marks none); None before "
                                                   "it was recorded", default=None)
    train_views: int | None = metric(meaning="views trained on; None before it was recorded", default=None)
    image_width: int | None = metric(meaning="width of the test images in pixels, as trained and evaluated (after "
                                             "data.downscale); None before it was recorded", default=None)
    image_height: int | None = metric(meaning="height of the test images in pixels; None before it was recorded",
                                      default=None)
    worst_view_psnr: float | None = metric(meaning="the lowest PSNR (dB) of a test view in the final evaluation (each "
                                                   "view's in curves.test_view_psnr); None before it was recorded",
                                           default=None)
    resumed_step: int | None = metric(meaning="the step this run continued from: the checkpoint an earlier attempt "
                                              "of it left when its worker was killed (its train_seconds and "
                                              "cpu_seconds sum the attempts' loop times; its load marks and the "
                                              "record's seconds are the last attempt's; splatbench.experiments."
                                              "train_resume); None: run straight through, and before it was "
                                              "recorded", default=None)

    @classmethod
    def of(cls, result, dataset_hash: str | None, *, own_peak: bool = False) -> TrainRun:
        """The record of a `splatbench.train.TrainResult`: its own metrics by name, the load
        (`TrainResult.load`) and the strategy's counts (`TrainResult.topology`; None before
        they were recorded) flattened, its warnings, its notes (the loader's, the start's, the
        background's: `TrainResult.notes`) and its curves (`CURVE_KEYS`). ``own_peak``:
        the process's peak RSS was reset as the run started, so ``result.peak_rss_mb`` is the
        run's own (``run_peak_rss_mb``; None otherwise)."""
        names = {m.name for m in metric_specs(cls)}
        rows = result.to_dict()  # NaN / inf already None there (the one JSON-safety rule of a result)
        history, evaluations = rows["history"], rows["evaluations"]
        curves = {
            "step": [p["step"] for p in history], "loss": [p["loss"] for p in history],
            "psnr": [p["psnr"] for p in history], "num_gaussians": [p["num_gaussians"] for p in history],
            "eval_step": [p["step"] for p in evaluations], "eval_psnr": [p["psnr"] for p in evaluations],
            "eval_ssim": [p["ssim"] for p in evaluations], "eval_lpips": [p["lpips"] for p in evaluations],
        }
        if rows["step_evaluations"]:  # a protocol's 7K / 30K columns (only runs that make them)
            curves["step_evaluations"] = rows["step_evaluations"]
        if rows.get("test_view_psnr"):  # each test view's PSNR at the end (runs that recorded it)
            curves["test_view_psnr"] = rows["test_view_psnr"]
        topology = dataclasses.asdict(result.topology) if result.topology is not None else {}
        values = {**{name: getattr(result, name) for name in names if hasattr(result, name)},
                  **{k: v for k, v in result.load.items() if k in names},
                  **{name: topology.get(name) for name in TOPOLOGY_METRICS},
                  "lpips_scale_inputs": int(result.lpips_scale_inputs), "time_loaded": int(result.load["loaded"]),
                  "init_method": (result.init or {}).get("method"), "init_points": (result.init or {}).get("points"),
                  "run_peak_rss_mb": result.peak_rss_mb if own_peak else None,
                  "device": result.device or None, "dataset_hash": dataset_hash,
                  "background": ", ".join(f"{c:g}" for c in result.background) if result.background else None,
                  "background_source": result.background_source or None,
                  "train_views": result.train_views or None,
                  "image_width": result.image_size[0] if result.image_size else None,
                  "image_height": result.image_size[1] if result.image_size else None,
                  "worst_view_psnr": min(result.test_view_psnr) if result.test_view_psnr else None}
        return cls(**values, warnings=tuple(result.warnings), curves=curves, notes=tuple(result.notes))


# --------------------------------------------------------------------------- config
def validate(config: dict[str, Any]) -> None:
    """Raise a one-line `InputError` naming the first bad field (no data is touched)."""
    _, _, train = split(config)
    train_config(train)


def _strategy_table(cfg: TrainConfig) -> dict[str, Any]:
    """``name`` and every field of the configured strategy (preset and options applied, schedule
    fields as written, not scaled), JSON values; a step field written as a fraction of the run
    ("50%") stays that string, so the run scales it, once, as the file says."""
    from splatbench.train.schedule import parse_run_fraction

    strategy = cfg.make_strategy(scaled=False)
    out = {f.name: _json(getattr(strategy, f.name)) for f in dataclasses.fields(strategy)}
    for name, value in cfg.strategy.options.items():
        if name in strategy.run_fraction_fields and parse_run_fraction(value, f"strategy.{name}") is not None:
            out[name] = value
    return {"name": cfg.strategy.name, **out}


def _json(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_json(v) for v in value]
    return value


def resolve(config: dict[str, Any]) -> dict[str, Any]:
    """The config with every default filled in (module doc); what the run id hashes."""
    from splatbench.scenes.catalog import get_scene

    scene, data, train = split(config)
    kind = scene_type(data)
    cfg = train_config(train)
    out = {k: v for k, v in cfg.to_dict().items() if k not in OWNED_FIELDS}
    if not out["eval"]["before_refine"]:  # at its default (the order every run before it had): left out, same run id
        out["eval"] = {k: v for k, v in out["eval"].items() if k != "before_refine"}
    out["strategy"] = _strategy_table(cfg)
    out["scene"] = scene
    read = out["data"]  # DataConfig's keys; a rendered scene is not downscaled (its resolution is set)
    if kind == "folder":
        out["data"] = {**read, "path": data["path"]}
        return out
    read = {k: v for k, v in read.items() if k != "downscale"}
    if kind == "teacher":
        out["data"] = {**read, "model": data["model"], **{k: data.get(k) or v for k, v in TEACHER_DEFAULTS.items()}}
        if data.get("up") is not None:
            out["data"]["up"] = data["up"]
        return out
    rig = get_scene(scene).rig
    out["data"] = {
        **read,
        "resolution": data.get("resolution") or int(rig.resolution[0]),
        "views": data.get("views") or int(rig.train_views + rig.test_views),
        "spp": data.get("spp") or int(rig.spp),
    }
    test_spp = data.get("test_spp")
    if test_spp is not None and test_spp != out["data"]["spp"]:  # at its default (spp) it is left out: same run id
        out["data"]["test_spp"] = test_spp
    return out


def identity(config: dict[str, Any]) -> dict[str, Any]:
    """What the run id hashes of a resolved config: ``data.path`` / ``data.model`` replaced by
    ``data.content``, the hash of what the folder or file holds (module doc), so that a report's
    run ids hold in any clone and change when the data does."""
    data = config.get("data", {})
    key = "path" if "path" in data else "model" if "model" in data else None
    if key is None:
        return config
    rest = {k: v for k, v in data.items() if k != key}
    return {**config, "data": {**rest, "content": _content(str(Path(data[key]).absolute()))}}


def _content(path: str) -> str:
    if not Path(path).exists():
        raise InputError(f"data: {path} does not exist (a scene table's path or model, relative to the "
                         f"experiment file)")
    return content_hash(path)


def scenes() -> set[str]:
    """Every scene of the catalog (`splatbench.scenes.find_scenes`)."""
    from splatbench.scenes.catalog import find_scenes

    return set(find_scenes())


# --------------------------------------------------------------------------- datasets
def datasets_dir() -> Path:
    """``$SPLATBENCH_DATASETS``, else ``./data/scenes`` (absolute): the user's setting,
    read in the runner (`prepare`), never in a worker."""
    return Path(os.environ.get(DATASETS_ENV) or Path("data") / "scenes").absolute()


@dataclasses.dataclass(frozen=True)
class Prepared:
    """What `prepare` settles in the runner for every worker: ``datasets``, the absolute
    folder the rendered datasets are in."""

    datasets: Path


def dataset_folder(scene: str, data: dict[str, Any], root: Path | None = None) -> Path:
    """Where the dataset of ``scene`` rendered with ``data`` (a resolved ``data`` table)
    lives under ``root`` (None: `datasets_dir`)."""
    from splatbench.scenes.folders import dataset_name

    root = datasets_dir() if root is None else root
    return root / dataset_name(scene, data["resolution"], data["views"], data["spp"], data.get("test_spp"))


def ensure_dataset(scene: str, data: dict[str, Any], root: Path, *, progress: bool = False):
    """The dataset of one run (a resolved ``data`` table), rendered under ``root`` or found
    in the cache: `RenderedDataset` for a catalog scene, `TeacherDataset` for a teacher;
    a dataset folder is returned as it is (a `FolderDataset`)."""
    kind = scene_type(data)
    if kind == "folder":
        return FolderDataset(Path(data["path"]), True, None, 0.0)
    if kind == "teacher":
        from splatbench.experiments.teacher import render_teacher

        out = root / f"teacher-{scene}-{data['resolution']}-v{data['views']}"
        return render_teacher(data["model"], out, views=data["views"], resolution=data["resolution"],
                              up=data.get("up"), progress=progress)
    from splatbench.scenes.render import render_dataset

    return render_dataset(scene, dataset_folder(scene, data, root), resolution=data["resolution"], views=data["views"],
                          spp=data["spp"], test_spp=data.get("test_spp"), progress=progress)


@dataclasses.dataclass(frozen=True)
class FolderDataset:
    """A user's dataset folder in a grid (nothing is rendered; ``hash`` None)."""

    path: Path
    cached: bool
    hash: str | None
    seconds: float


def prepare(configs: list[dict[str, Any]]) -> Prepared:
    """Render every dataset the pending runs need, once, in the parent (cached), and load
    every dataset folder once (undistortion is cached then); return the datasets folder
    for the workers."""
    prepared = Prepared(datasets=datasets_dir())
    seen: set[str] = set()
    for config in configs:
        from splatbench.experiments.configs import canonical_json

        key = canonical_json([config["scene"], config["data"]])
        if key in seen:
            continue
        seen.add(key)
        data = config["data"]
        kind = scene_type(data)
        if kind == "folder":
            from splatbench.data import load_dataset

            ds = load_dataset(data["path"], layout=data["layout"], test_every=data["test_every"],
                              downscale=data["downscale"], masks=data["masks"], say=lambda line: print(line, file=sys.stderr, flush=True))
            print(f"dataset {config['scene']}: {data['path']} (downscale {data['downscale']}: "
                  f"{len(ds.train)} train, {len(ds.test)} test views)", file=sys.stderr, flush=True)
            path = Path(data["path"])
        else:
            result = ensure_dataset(config["scene"], data, prepared.datasets, progress=sys.stderr.isatty())
            how = "cached" if result.cached else f"rendered in {result.seconds:.1f} s"
            if kind == "teacher":
                what = f"teacher {data['model']} {data['resolution']}px, {data['views']} views, up {list(result.up)} " \
                       f"({result.up_source})"
            else:
                what = f"{data['resolution']}px, {data['views']} views, {data['spp']} spp" + \
                    (f" (test views {data['test_spp']})" if data.get("test_spp") else "")
            print(f"dataset {config['scene']} {what}: {how} ({result.path})", file=sys.stderr, flush=True)
            path = result.path
        no_points = kind == "folder" and ds.points is None  # init="auto" triangulates those (SfM, known poses)
        needs = sorted({(c["init"]["sfm_poses"], c["data"]["layout"], c["data"]["test_every"])
                        for c in configs if c["scene"] == config["scene"] and c["data"] == data
                        and (c["init"]["method"] == "sfm" or (c["init"]["method"] == "auto" and no_points))})
        for poses, layout, test_every in needs:
            _prepare_sfm(path, data.get("downscale") or 1, poses, layout, test_every)
    return prepared


def check_inputs(configs: list[dict[str, Any]]) -> list[str]:
    """Check each dataset folder the runs read (resolved configs), as each run reads it, from
    file names and image headers alone (`splatbench.data.check_dataset`: the loader's own
    checks; nothing decoded, undistorted or triangulated), and that its views are as large as
    the run's metrics need (`min_side`). One `InputError` line naming the scene
    (``scenes.NAME:``), the file or field, and the fix; else one line per folder and reading."""
    from splatbench.data import check_dataset
    from splatbench.experiments.configs import canonical_json

    found: dict[str, Any] = {}
    lines = []
    for config in configs:
        scene, data = config["scene"], config["data"]
        if scene_type(data) != "folder":
            continue
        key = canonical_json([scene, data])
        if key not in found:
            try:
                found[key] = check = check_dataset(data["path"], layout=data["layout"], test_every=data["test_every"],
                                                   downscale=data["downscale"], masks=data["masks"])
            except InputError as exc:
                raise InputError(f"scenes.{scene}: {exc}") from None
            read = how_read(check.notes)  # the images folder and its reduction, undistortion, masks
            lines.append(f"scene {scene}: {data['path']}: {check.layout}, {check.train_views} train and "
                         f"{check.test_views} test views of {check.width}x{check.height} px (data.downscale="
                         f"{data['downscale']}" + (f"; {read}" if read else "") + ")")
        check = found[key]
        need, why = min_side(config, check)
        if check.width and min(check.width, check.height) < need:
            n = data["downscale"]
            largest = max(1, n * min(check.width, check.height) // need)
            raise InputError(f"scenes.{scene}: data.downscale={n}: its views are {check.width}x{check.height} px, "
                             f"under the {need} px a side that {why} needs; set the scene's downscale to at most "
                             f"about {largest}" + (", or eval.lpips_net = \"none\"" if "LPIPS" in why else ""))
    return lines


def min_side(config: dict[str, Any], check) -> tuple[int, str]:
    """(The fewest pixels a side of a run's views may have, what needs them): the SSIM window of
    the loss and the evaluation (``loss.ssim_window``: more than half of it), and the LPIPS nets
    the run's settings ask for (`splatbench.train.loop.lpips_nets`; `splatbench.metrics.perceptual.MIN_SIDE`
    of each: AlexNet 31): a run would compute no LPIPS under them (`lpips_plan`'s note), so a grid
    is refused up front. ``check``: a `DatasetCheck`."""
    from splatbench.metrics.perceptual import MIN_SIDE
    from splatbench.train.loop import lpips_nets

    cfg = train_config(split(config)[2])
    need, why = cfg.loss.ssim_window // 2 + 1, f"SSIM's {cfg.loss.ssim_window}-px window (loss.ssim_window)"
    final, curves, _ = lpips_nets(cfg, check.test_views)
    nets = sorted({net for net, _ in (*final, *curves)}, key=lambda net: -MIN_SIDE[net])
    if nets and MIN_SIDE[nets[0]] > need:
        need, why = MIN_SIDE[nets[0]], (f"LPIPS with {' and '.join(nets)} (eval.lpips_net = "
                                        f"\"{cfg.eval.lpips_net}\"; the curves' LPIPS is AlexNet's)")
    return need, why


def _prepare_sfm(path: Path, downscale: int, poses: str, layout: str, test_every: int) -> None:
    """Run (or find cached) the SfM of a dataset that init="sfm" (or "auto" on a folder
    without points) runs need, once, before the workers start (so two workers never run it
    at once), on the training views as those runs load them. A failure is printed; each
    such run then fails with the same one line."""
    from splatbench.data import load_dataset
    from splatbench.sfm import cached_sfm

    try:
        ds = load_dataset(path, layout=layout, test_every=test_every, downscale=downscale)
        run, cached = cached_sfm(ds, poses=poses)
    except InputError as exc:
        print(f"SfM of {path}: {exc}", file=sys.stderr, flush=True)
        return
    print(f"SfM of {path} ({poses} poses): {len(run.xyz)} points, {run.registered}/{run.total} training views "
          f"({'cached' if cached else f'ran in {run.seconds:.1f} s'})", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- run
def run(config: dict[str, Any], workdir: Path, prepared: Prepared) -> TrainRun:
    """Train on the run's dataset (found, or rendered on a worker that has no copy, under
    ``prepared.datasets``), writing the run's files into ``workdir``; a long run writes
    checkpoints there, and continues from the latest one an earlier, killed attempt left
    (`splatbench.experiments.train_resume`)."""
    from splatbench.experiments.train_resume import train_resuming

    scene, data, fields = split(config)
    dataset = ensure_dataset(scene, data, prepared.datasets)
    cfg = TrainConfig.from_dict({**fields, "dataset": str(dataset.path), "out": str(workdir)}, source="")
    # a worker runs several runs in turn: reset its high-water mark so the peak recorded is this run's own
    own_peak = reset_peak_rss()
    result = train_resuming(cfg, say=lambda line: print(f"{workdir.name}: {line}", file=sys.stderr, flush=True))
    return TrainRun.of(result, dataset.hash[:16] if dataset.hash else None, own_peak=own_peak)


def with_protocol(config: dict[str, Any], name: str) -> dict[str, Any]:
    """``config`` (a run's nested, unresolved config) under protocol ``name``: what an experiment's
    ``[check]`` runs. ``protocol = name``; ``iterations`` left out, so the protocol brings its own
    length (7,000 for graphdeco-7k); ``eval.every`` the protocol's `curve_every` (700 for
    graphdeco-7k: no point on an opacity reset). Every other field as the cell has it. One-line
    `InputError` for an unknown name or one without a length of its own (``quick``: the grid's)."""
    from splatbench.train.protocol import get_protocol  # late: splatbench.train imports torch

    protocol = get_protocol(name)
    if protocol.curve_every is None:
        raise InputError(f"protocol: {name!r} is laid over the grid's own iterations; a check reruns the "
                         f"headline at a protocol of its own length (graphdeco-7k, graphdeco-30k)")
    out = {k: v for k, v in config.items() if k != "iterations"}
    evaluation = out.get("eval", {})
    evaluation = {**(evaluation if isinstance(evaluation, dict) else {}), "every": protocol.curve_every}
    return {**out, "protocol": name, "eval": evaluation}


def describe_protocol(name: str) -> str:
    """The protocol ``name`` in words, for a report (`splatbench.train.protocol`)."""
    from splatbench.train.protocol import GRAPHDECO_ITERATIONS, get_protocol  # late: torch

    p = get_protocol(name)
    if p.iterations is None:
        return f"graphdeco's step fields scaled to the run's iterations, learning rates not: {p.stands_beside}"
    return (f"graphdeco's {GRAPHDECO_ITERATIONS:,}-step schedule as written (step fields and the position "
            f"learning-rate decay unscaled), run {p.iterations:,} steps and evaluated there, the step(s) of "
            f"{p.stands_beside}; on another scene, resolution or metric convention its numbers are not "
            f"comparable to the paper's, only the schedule is")


def lpips_min_effect(runs) -> dict[str, float | None]:
    """``{"test_lpips": minimum effect}`` on the scale of the LPIPS convention the done runs of ``runs`` (a
    run table) recorded (`LPIPS_MIN_EFFECT`; None, no practical threshold, for a convention without a
    measured one); {} where they recorded none, or several (then the kind's default stays, and the
    "Metrics" section says the column mixes conventions: `lpips_note`)."""
    kinds = lpips_conventions(runs)
    return {"test_lpips": LPIPS_MIN_EFFECT.get(kinds[0])} if len(kinds) == 1 else {}


#: What the reports of train runs show (`splatbench.experiments.kind_report`).
REPORT = KindReport(
    metrics=("test_psnr", "test_ssim", "test_lpips", "num_gaussians", "run_peak_rss_mb", "train_seconds",
             "render_ms_per_view", "time_loaded"),
    rules=FindingRules("test_psnr", (Comparison("test_psnr", "diff", min_effect=MIN_EFFECT["test_psnr"]),
                                     Comparison("test_ssim", "diff", min_effect=MIN_EFFECT["test_ssim"]),
                                     Comparison("test_lpips", "diff", min_effect=MIN_EFFECT["test_lpips"]),
                                     Comparison("train_seconds", "ratio", min_effect=MIN_EFFECT["train_seconds"]),
                                     Comparison("num_gaussians", "ratio", min_effect=MIN_EFFECT["num_gaussians"])),
                       size="num_gaussians", quality=("test_ssim", "test_lpips")),
    tradeoffs=(Tradeoff("train_seconds", "test_psnr", "time_vs_error",
                        "Training time against test PSNR per cell (mean over seeds)"),
               Tradeoff("num_gaussians", "test_psnr", "gaussians_vs_error",
                        "Final number of Gaussians against test PSNR per cell (mean over seeds)",
                        cheaper="smaller (fewer Gaussians)", order="fewest Gaussians first")),
    timed=("train_seconds", "render_ms_per_view"),
    settling=SettlingCurves("test_psnr", "eval_step", "eval_psnr", "step", "psnr", resets=opacity_reset_steps),
    confounds=("opacity_resets", "refinements", "cloned", "split", "pruned", "pruned_size", "relocated", "added"),
    confound_floor=tuple((name, CONFOUND_FLOOR) for name in GAUSSIAN_COUNTS),
    load=LoadMarks("time_loaded", "timed"),
    header_notes=(protocol_lines,),
    title_notes=(smoke_test_line,),
    model_bytes=model_bytes,
    axis_notes=(model_size_note, ssim_trained_note, auto_sh_degree_note, schedule_confound_note),
    metric_notes=(lpips_note, memory_note),
    run_findings=(outlier_view_finding,),
    check_notes=(outlier_view_note, check_schedule_note),
    min_effects=lpips_min_effect,
)

#: The ``train`` kind (``kind = "train"``).
TRAIN = RunKind(name="train", validate=validate, run=run, config=TrainConfig, result=TrainRun, resolve=resolve,
                identity=identity, scenes=scenes, prepare=prepare, check_inputs=check_inputs, report=REPORT,
                planned=planned,
                description="train 3DGS on a catalog scene, a dataset folder or a teacher model (splatbench.train)",
                protocols=KindProtocols(with_protocol, describe_protocol), reusable=True)

__all__ = ["TRAIN", "TrainRun", "REPORT", "MIN_EFFECT", "LPIPS_MIN_EFFECT", "lpips_min_effect", "TOPOLOGY_METRICS", "CURVE_KEYS", "DATASETS_ENV", "DATA_FIELDS", "Prepared", "datasets_dir",
           "dataset_folder", "ensure_dataset"]
