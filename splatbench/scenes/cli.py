"""`splatbench scenes list` and `splatbench scenes render NAME`."""

from __future__ import annotations

from pathlib import Path

import click

_SCENES_DIR = click.option(
    "--scenes-dir", "scenes_dirs", multiple=True, type=click.Path(path_type=Path),
    help="Extra folder of scene folders (repeatable; also $SPLATBENCH_SCENES). Shadows built-in scenes.")


@click.group()
def scenes() -> None:
    """Mitsuba scene catalog: list the scenes, render one into a dataset."""


@scenes.command("list")
@_SCENES_DIR
def list_(scenes_dirs: tuple[Path, ...]) -> None:
    """List the scenes: rig, views, resolution, spp and folder."""
    from splatbench.scenes.catalog import find_scenes

    found = find_scenes(scenes_dirs)
    if not found:
        click.echo("no scenes found")
        return
    rows = [("name", "rig", "train+test", "resolution", "spp", "description", "folder")]
    for name, spec in found.items():
        r = spec.rig
        rows.append((name, r.kind, f"{r.train_views}+{r.test_views}", f"{r.resolution[0]}x{r.resolution[1]}",
                     str(r.spp), r.description, str(spec.folder)))
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]) - 1)]
    for row in rows:
        click.echo("  ".join(cell.ljust(w) for cell, w in zip(row, widths)) + "  " + row[-1])


@scenes.command("render")
@click.argument("name")
@click.option("--resolution", default=None, help="Width W (height keeps the rig's aspect) or WxH. Default: the rig's.")
@click.option("--views", type=int, default=None,
              help="Total number of views; every 8th (i % 8 == 0) is a test view. Default: the rig's train + test.")
@click.option("--spp", type=int, default=None, help="Samples per pixel (training views). Default: the rig's.")
@click.option("--test-spp", type=int, default=None,
              help="Samples per pixel of the test views (cleaner evaluation targets: their Monte Carlo noise is "
                   "a floor under every model's test PSNR). Default: --spp.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Dataset folder. Default, in the current folder: data/scenes/<NAME>-<W> at the rig's views and "
                   "spp, else data/scenes/<NAME>-<W>-v<VIEWS>-s<SPP>[-t<TEST_SPP>] (as experiments name them).")
@click.option("--force", is_flag=True, help="Render even when the cached dataset matches.")
@_SCENES_DIR
def render(name: str, resolution: str | None, views: int | None, spp: int | None, test_spp: int | None,
           out: Path | None, force: bool, scenes_dirs: tuple[Path, ...]) -> None:
    """Render scene NAME (a catalog name or a scene folder path) into a dataset folder.

    Writes images/ (8-bit sRGB), depth/ (camera z, .npy), transforms_{train,test}.json,
    sparse/0/ (COLMAP), points3D.ply, split.json and manifest.json. Skipped when the
    folder already holds a render with the same content hash.
    """
    from splatbench.scenes.render import render_dataset

    result = render_dataset(name, out, resolution=resolution, views=views, spp=spp, test_spp=test_spp, force=force,
                            extra_dirs=scenes_dirs)
    if result.cached:
        click.echo(f"cached: {result.path}")
        return
    if result.replaced:
        click.echo(result.replaced)
    click.echo(f"dataset: {result.path} ({result.train} train + {result.test} test views, "
               f"rendered in {result.seconds:.1f} s)")
