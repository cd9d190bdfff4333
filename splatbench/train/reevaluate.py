"""`evaluate_saved_run`: a finished run's final evaluation, made again from its output folder.

A train run writes ``config.toml`` (its resolved config), ``point_cloud.ply`` (the final model,
SH truncated to the degree it ended at) and ``result.json`` (`TrainResult`, whose ``sh_degree``
is that degree) into its output folder. This rebuilds the run's `Trainer` from that config and
dataset, puts the PLY's Gaussians into it at that degree, and calls `Trainer.evaluate`: the one
evaluation (the same test split, background, compositing of masked or alpha targets over it,
clamping and PSNR), not a second one. The PLY holds the float32 parameters bit for bit
(`splatbench.ply`), so on the machine and environment the run had, the numbers are the run's
own; elsewhere they differ by float32 rounding only.

What it is for: runs finished before `TrainResult.test_view_psnr` was recorded
(``tools/backfill_view_psnr.py``); each test view's LPIPS in any convention, beside the one the run
recorded (``tools/lpips_scale.py``). Nothing is trained and nothing is written.

Example::

    ev = evaluate_saved_run("results/sh_degree/work/8f323452d4d1f2bc")
    ev.psnr, ev.per_view_psnr          # the run's test PSNR (dB) and each test view's
    ev = evaluate_saved_run("results/sh_degree/work/8f323452d4d1f2bc", lpips=[("alex", True), ("vgg", False)])
    ev.per_view_lpips[("vgg", False)]  # each test view's LPIPS-VGG on [0, 1] inputs (graphdeco's)
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from splatbench.errors import InputError
from splatbench.gaussians import Gaussians
from splatbench.fsutil import read_text
from splatbench.train.config import TrainConfig
from splatbench.train.loop import Evaluation, Trainer, torch_threads
from splatbench.train.params import params_from_gaussians

#: The largest change of a rendered value in [0, 1] that float32 rounding alone makes between two
#: executions of the same render (another summation order: packet width, threads, machine): 16 units in the
#: last place of 1.0 (2^-23 each), a pixel's front-to-back blend rounding once per Gaussian it blends and the
#: errors adding up over a dozen or so. Not measured here: on the machine that ran them, every run checked
#: so far (42 of 42, sh_degree and quick_protocol) evaluates again bit for bit (tools/backfill_view_psnr.py,
#: tools/lpips_scale.py: each checks a saved run's evaluation against its record by it).
RENDER_ULPS = 16 * 2.0 ** -23


def tolerance_db(view_psnrs: list[float]) -> float:
    """How far the mean of ``view_psnrs`` (dB) may be from the recorded test PSNR by float32
    rendering noise alone: each rendered value off by at most ``d`` = `RENDER_ULPS` changes a
    view's mean square error e² by at most 2 d mean|e| <= 2 d rms(e), so its PSNR by at most
    (10 / ln 10) 2 d / rms(e) = (20 / ln 10) d 10^(PSNR / 20) dB (first order); the mean of the
    views' bounds bounds their mean's change. E.g. 1.7e-3 dB at 46 dB, 1.5e-4 dB at 25 dB:
    rendering at another SH degree, over another background or from another model moves it by
    tenths of a dB and more."""
    bounds = [20 / math.log(10) * RENDER_ULPS * 10 ** (p / 20) for p in view_psnrs if math.isfinite(p)]
    return float(np.mean(bounds)) if bounds else 0.0


#: The files of a run's output folder that `evaluate_saved_run` reads.
CONFIG_FILE, MODEL_FILE, RESULT_FILE = "config.toml", "point_cloud.ply", "result.json"


def final_sh_degree(run_dir: str | Path) -> int:
    """The SH degree the run ended at (``result.json``'s ``sh_degree``): the degree its final
    evaluation rendered at. One-line `InputError` for a missing or unreadable file."""
    path = Path(run_dir) / RESULT_FILE
    try:
        degree = json.loads(read_text(path, "result"))["sh_degree"]
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{path}: not a train result with an sh_degree (rerun the run)") from None
    if not isinstance(degree, int) or not 0 <= degree <= 3:
        raise InputError(f"{path}: sh_degree {degree!r} is not a degree 0..3")
    return degree


def evaluate_saved_run(run_dir: str | Path, *, dataset=None, lpips: Sequence[tuple[str, bool]] = ()) -> Evaluation:
    """The final evaluation of the run whose output folder is ``run_dir`` (module doc), from its
    ``config.toml``, ``point_cloud.ply`` and ``result.json``: PSNR and SSIM over its test views and
    ``per_view_psnr`` (test-split order); LPIPS in each ``(net, scale_inputs)`` of ``lpips``
    (``Evaluation.lpips``, ``per_view_lpips``; none by default). ``dataset``: the loaded dataset,
    instead of reading the config's ``dataset`` folder. One-line `InputError` for a missing file, a model whose
    SH degree is not the one the run ended at, or a config or dataset that no longer loads."""
    from splatbench.train.config import load_config

    run = Path(run_dir)
    config = load_config(run / CONFIG_FILE)
    degree = final_sh_degree(run)
    model = Gaussians.from_ply(run / MODEL_FILE)
    if model.sh_degree != degree:
        raise InputError(f"{run / MODEL_FILE}: SH degree {model.sh_degree}, but {run / RESULT_FILE} says the run "
                         f"ended at {degree}: not this run's final model")
    return evaluate_model(config, model, degree, dataset=dataset, lpips=lpips)


def evaluate_model(config: TrainConfig, model: Gaussians, degree: int, *, dataset=None,
                   lpips: Sequence[tuple[str, bool]] = ()) -> Evaluation:
    """`Trainer.evaluate` of ``model`` at SH degree ``degree`` for a run of ``config`` (its dataset,
    background, raster options), on the config's torch threads; see `evaluate_saved_run`."""
    with torch_threads(config.torch_threads):
        trainer = Trainer(config, dataset=dataset, resuming=True)  # the initial model is replaced below
        if degree > config.sh.max_degree:
            raise InputError(f"model: SH degree {degree} is above the config's sh.degree {config.sh.degree}")
        # as a checkpoint's parameters go in (`splatbench.train.checkpoint`); SH beyond the model's degree is
        # never read: `Trainer._render` slices the degree's bands
        trainer.params = params_from_gaussians(model, trainer.lrs, trainer.device)
        trainer.sh.degree = degree
        with torch.no_grad():
            return trainer.evaluate(lpips)


__all__ = ["evaluate_saved_run", "evaluate_model", "final_sh_degree", "tolerance_db", "RENDER_ULPS", "CONFIG_FILE", "MODEL_FILE",
           "RESULT_FILE"]
