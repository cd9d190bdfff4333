"""`splatbench train [DATASET] [--config FILE] [--set key=value ...] [--resume CKPT] [--json] [--quiet] [--out DIR]`."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("dataset", type=click.Path(path_type=Path), required=False)
@click.option("--config", "config_file", type=click.Path(path_type=Path), default=None,
              help="TOML config (TrainConfig's fields and its [data], [init], [sh], [optim], [loss], [strategy], "
                   "[eval], [raster] tables; see docs/training.md).")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Override a config field (repeatable): KEY a top-level field or GROUP.KEY, e.g. --set iterations=2000 "
                   "--set sh.degree=auto --set strategy=mcmc --set strategy.cap_max=50000 --set loss.ssim_lambda=0 "
                   "--set optim.lr_means=3e-4 --set background=1,1,1 --set data.downscale=8 (images / 8, or images_8/) "
                   "--set raster.tile_size=8 --set raster.alpha_min=0.005 (the rasterizer's options of every render; "
                   "the device is --set device=...) "
                   "--set checkpoint_every=500 (a checkpoint every 500 steps, for --resume) "
                   "--set protocol=graphdeco-30k (graphdeco's schedule unscaled, evaluated at 7,000 and 30,000); --set eval.before_refine=true (each evaluation before that step's refinement, graphdeco's order). "
                   "protocol: quick (the default: the schedule scaled to iterations), graphdeco-7k, graphdeco-30k. "
                   "init (init.method): auto (the default: the dataset's points, else SfM), surface (the dataset's "
                   "points), sfm (pycolmap), random; init.region (init=random): auto, convergence, camera_cube, "
                   "nerf_synthetic, depth_bounds (LLFF's near/far). --set data.masks=false ignores a capture's "
                   "masks/.")
@click.option("--out", "out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default: the config's `out`, runs/train). One holding another run is refused "
                   "unless --resume continues one of its checkpoints or --force replaces it.")
@click.option("--force", is_flag=True,
              help="Train into an --out folder that holds an earlier run: its result.json, config.toml, "
                   "point_cloud.ply/.png and checkpoints are removed first (nothing else).")
@click.option("--resume", type=click.Path(path_type=Path), default=None,
              help="Continue exactly from a checkpoint (checkpoints/iteration_<step>.pt; written every "
                   "checkpoint_every steps, and when a run is interrupted). Without --config the run continues "
                   "with the checkpoint's own config (DATASET and --set may be left out).")
@click.option("--json", "as_json", is_flag=True, help="Print the TrainResult as one JSON line at the end.")
@click.option("--quiet", is_flag=True, help="No progress bar (for sweeps).")
def train(dataset: Path, config_file: Path | None, overrides: tuple[str, ...], out: Path | None,
          resume: Path | None, force: bool, as_json: bool, quiet: bool) -> None:
    """Train 3D Gaussian Splatting on DATASET (a COLMAP, Blender / instant-ngp or LLFF folder;
    optional with --resume, or with a --config that names one).

    A capture whose cameras have lens distortion is undistorted by pycolmap first (cached
    by content); that, the test split chosen and ignored keys are said in notes
    (docs/training.md, "Real captures").

    Prints the test PSNR / SSIM, Gaussian count, SH degree, the device that rasterized
    (``cpu (Dr.Jit LLVM)`` or ``cuda (Dr.Jit CUDA)``: what device=auto resolved to) and the PLY path; writes
    config.toml, point_cloud.ply and result.json under the output folder. A resumed run
    says so in one line, ``resumed from CKPT at step N of M``; init=sfm says
    ``SfM: running pycolmap on N training views (cached in DIR)`` or ``SfM: reusing DIR``
    before SfM starts and its result as it ends; the start made (``init auto: sfm (...)``,
    ``init.region auto: convergence (...)``) is said once it is made, before the progress
    bar. These lines go to stderr as they happen,
    unless --quiet, and are always among the result's notes (so in --json and result.json; a
    warning among its warnings).

    An output folder that already holds a run (result.json, point_cloud.ply or
    checkpoints/) is refused in one line, exit 2, untouched, unless --resume names one of
    its own checkpoints or --force is given (splatbench.train.out_folder).
    """
    from splatbench.errors import InputError
    from splatbench.train.checkpoint import checkpoint_config
    from splatbench.train.config import TrainConfig, apply_overrides, load_config

    if config_file is not None:
        config = load_config(config_file)
        # paths in a config file are relative to the file (as an experiment file's are), not to
        # the folder the command runs in; made absolute below with the others
        written = _top_level_keys(config_file)  # a default `out` is the working folder's, not the file's
        paths = [f"{key}={_toml_str(str((Path(config_file).parent / value).resolve()))}"
                 for key, value in (("dataset", config.dataset), ("out", config.out))
                 if key in written and value and not Path(value).is_absolute()]
        config = apply_overrides(config, paths) if paths else config
    else:  # an interrupted run continues as it was set up (the checkpoint holds its config, as data)
        config = checkpoint_config(resume) if resume is not None else TrainConfig()
    if resume is not None and out is None and config_file is None:
        # it finishes where its checkpoint is (OUT/checkpoints/iteration_N.pt), wherever that run
        # folder has moved since, not in the folder the checkpoint's config names
        run_folder = Path(resume).resolve().parent
        out = run_folder.parent if run_folder.name == "checkpoints" else None
    # paths as absolute ones: a checkpoint's config is then valid from any working folder
    config = apply_overrides(config, ([f"dataset={_toml_str(str(dataset.resolve()))}"] if dataset is not None else [])
                             + [*overrides] + ([f"out={_toml_str(str(out.resolve()))}"] if out is not None
                                               else []))  # validated
    if not config.dataset:
        raise InputError("DATASET: give the dataset folder (splatbench train DATASET), or a --config naming one, "
                         "or --resume a checkpoint")

    from splatbench.train.checkpoint import resume_line
    from splatbench.train.loop import train as run
    from splatbench.train.out_folder import claim_out

    removed = claim_out(config.out, resume=resume, force=force)
    if removed:  # said even with --quiet: files were deleted
        click.echo(f"--force: removed {len(removed)} file(s) of the earlier run in {config.out}", err=True)

    bar = None
    shown: set[str] = set()  # notes already printed as they happened (SfM, the resume line)

    def say(line: str) -> None:
        shown.add(line)
        click.echo(line, err=True)

    def progress(status) -> None:
        nonlocal bar
        if bar is None:  # created at the first step: set-up errors print without a bar
            from tqdm import tqdm

            if resume is not None:  # status.step: the first step after the checkpoint's
                say(resume_line(resume, status.step, config.iterations))
            bar = tqdm(total=config.iterations, initial=status.step, desc="train", unit="it", dynamic_ncols=True,
                       leave=True)
        bar.update(1)
        if status.step % 10 == 0 or status.step + 1 == config.iterations:
            bar.set_postfix(loss=f"{status.loss:.4f}", psnr=f"{status.psnr:.2f}", n=status.num_gaussians,
                            sh=status.sh_degree, refresh=False)

    try:
        result = run(config, progress=None if quiet else progress, resume=resume, say=None if quiet else say)
    finally:
        if bar is not None:
            bar.close()
    if as_json:
        click.echo(result.to_json())
        return
    fmt = (lambda x, spec: "n/a" if x is None else format(x, spec))
    click.echo(f"test PSNR {fmt(result.test_psnr, '.2f')} dB, SSIM {fmt(result.test_ssim, '.4f')}, "
               f"LPIPS {fmt(result.test_lpips, '.4f')}{_lpips_how(result)} ({result.test_views} test views)")
    click.echo(f"{result.num_gaussians} Gaussians, SH degree {result.sh_degree} ({result.sh_degree_reason})")
    click.echo(f"{result.iterations} iterations{_timed_steps(result)} in {result.train_seconds:.1f} s"
               f"{'' if result.resumed_step is None else ' in all'} "
               f"({result.iterations / max(result.train_seconds, 1e-9):.2f} it/s), render "
               f"{fmt(result.render_ms_per_view, '.1f')} ms/view, peak RSS {result.peak_rss_mb:.0f} MB, "
               f"rasterized on {_DEVICE_NAMES.get(result.device, result.device)}")
    for e in result.step_evaluations:  # the protocol's columns (graphdeco-30k: 7,000 and 30,000 steps)
        click.echo(f"protocol {result.protocol}, step {e.step}: test PSNR {fmt(e.psnr, '.2f')} dB, SSIM "
                   f"{fmt(e.ssim, '.4f')}, LPIPS {e.lpips_net or 'n/a'} {fmt(e.lpips_scaled, '.4f')} (inputs in [-1, 1]) / "
                   f"{fmt(e.lpips_unscaled, '.4f')} ([0, 1] unscaled), {e.num_gaussians} Gaussians, "
                   f"{e.train_seconds:.1f} s")
    if _load_line(result):
        click.echo(_load_line(result))
    for note in (n for n in result.notes if n not in shown):
        click.echo(f"note: {note}")
    for warning in (w for w in result.warnings if w not in shown):
        click.echo(warning, err=True)
    click.echo(f"wrote {result.ply_path}")


#: TrainResult.device as the summary line says it.
_DEVICE_NAMES = {"cpu": "cpu (Dr.Jit LLVM)", "cuda": "cuda (Dr.Jit CUDA)"}


def _lpips_how(result) -> str:
    """`` (AlexNet, inputs in [-1, 1])``: which LPIPS the figure is."""
    if not result.lpips_net:
        return ""
    return f" ({'AlexNet' if result.lpips_net == 'alex' else 'VGG'}, inputs in " \
           f"{'[-1, 1]' if result.lpips_scale_inputs else '[0, 1] unscaled'})"


def _load_line(result) -> str:
    """The machine's load around the run and the CPU time of the loop (times are not
    trusted when others' load exceeded half the cores: `splatbench.metrics.load`)."""
    load = result.load
    if not load:
        return ""
    flag = "; LOADED: others' load exceeded half the cores, times not trusted" if load.get("loaded") else ""
    return (f"load average {load['load_before']:.2f} -> {load['load_after']:.2f} (others' {load['load_other']:.2f} "
            f"on {load['cores']} cores){flag}; loop CPU time {result.cpu_seconds:.1f} s")


def _timed_steps(result) -> str:
    """What ``train_seconds`` covers when it is more than this run, in counts: a resumed run's
    loop time includes the checkpoint's steps, timed by the run that wrote it
    (`` (297 before the checkpoint, 303 in this resumed run)``)."""
    k, n = result.resumed_step, result.iterations
    if k is None:
        return ""
    return f" ({k} before the checkpoint, {n - k} in this resumed run)"


def _toml_str(text: str) -> str:
    """A TOML basic string literal of ``text`` (for the override parser)."""
    import json

    return json.dumps(text)


def _top_level_keys(path: Path) -> set[str]:
    """The top-level keys a TOML config file sets (it was read and checked already)."""
    import tomllib

    return set(tomllib.loads(Path(path).read_text(encoding="utf-8")))
