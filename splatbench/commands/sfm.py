"""`splatbench sfm DATASET`: pycolmap SfM on a dataset's training views, aligned to its true frame."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("dataset", type=click.Path(path_type=Path))
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="pycolmap's random seed.")
@click.option("--threads", type=click.Choice(["one", "all"]), default="one", show_default=True,
              help="'one': single-threaded and deterministic; 'all': every core.")
@click.option("--estimate-intrinsics", is_flag=True,
              help="Let COLMAP estimate the (shared PINHOLE) intrinsics instead of using the dataset's.")
@click.option("--poses", type=click.Choice(["estimated", "known"]), default="estimated", show_default=True,
              help="'estimated': incremental mapping, aligned to the dataset's cameras; 'known': triangulate with "
                   "the dataset's poses held fixed (what init=sfm does).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Folder for the model (replaced). Default: the content cache ($SPLATBENCH_CACHE/sfm, reused while "
                   "the training views and options are unchanged); --threads all needs --out.")
@click.option("--verbose", is_flag=True, help="Show COLMAP's log.")
def sfm(dataset: Path, seed: int, threads: str, estimate_intrinsics: bool, poses: str, out: Path | None,
        verbose: bool) -> None:
    """SIFT, exhaustive matching and incremental mapping (or, --poses known, triangulation with
    the dataset's poses) on DATASET's training views as the dataset serves them (undistorted).

    Keeps the largest model, aligns it to the dataset's cameras with a similarity
    transform on the camera centres, writes it to --out/0/*.bin (default: the content cache,
    never into DATASET, which may be read-only), and prints the registered views, the
    camera-centre RMSE (absolute and over the rig radius) and where the model is.
    """
    from splatbench.errors import InputError
    from splatbench.sfm import run_sfm

    if out is None and threads == "all":  # run_sfm refuses it too; this names the command's options
        raise InputError("--threads all: give --out DIR (a multi-threaded run is not deterministic, so it is not "
                         "cached; nothing is written into the dataset folder)")
    run = run_sfm(dataset, seed=seed, single_thread=threads == "one", known_intrinsics=not estimate_intrinsics,
                  poses=poses, out=out, verbose=verbose, say=lambda line: click.echo(line, err=True))
    click.echo(f"registered: {run.registered}/{run.total} training views ({run.registered / run.total:.1%}; "
               f"largest of {run.models} model{'s' if run.models != 1 else ''})")
    click.echo(f"camera-centre RMSE: {run.center_rmse:.4g} ({run.center_rmse_rel:.3%} of the rig radius "
               f"{run.rig_radius:.4g}); alignment scale {run.alignment.scale:.4g}")
    click.echo(f"points: {len(run.xyz)}; {run.seconds:.1f} s")
    click.echo(f"model: {run.model_path}")
