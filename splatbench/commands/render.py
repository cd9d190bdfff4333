"""`splatbench render`: render a 3DGS PLY or a workload npz to a PNG."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from splatbench.guards import check_image_size, check_sh_degree, parse_size
from splatbench.errors import InputError
from splatbench.framing import AXES, DEFAULT_UP, KNOWN_UP_ELEVATION, framing_camera, parse_up
from splatbench.overrides import parse_overrides
from splatbench.workloads import BUNDLED_MODELS

def parse_background(text: str) -> tuple[float, float, float]:
    """``--background``: ``R,G,B`` in [0, 1]."""
    from splatbench.ply import ViewHints

    try:
        return ViewHints(background=text.split(",")).background
    except InputError:
        raise InputError(f"--background: expected R,G,B, 3 numbers in [0, 1], got {text!r}") from None


def dataset_camera(spec: str, downscale: int = 1):
    """``--camera DATASET[:VIEW]``: test view VIEW (default 0) of a dataset folder, loaded at
    ``downscale`` as `splatbench train --set data.downscale=N` loads it (`Camera`)."""
    from splatbench.data import load_dataset

    folder, sep, view = spec.rpartition(":")
    if not sep or not folder or Path(spec).is_dir():   # no VIEW (or a folder whose name holds ':')
        folder, view = spec, "0"
    test = load_dataset(folder, downscale=downscale).test
    if not len(test):
        raise InputError(f"--camera: {folder} has no test views")
    if not (view.isdigit() and int(view) < len(test)):
        raise InputError(f"--camera: view {view!r} is not a view index (0..{len(test) - 1}) of {folder}; "
                         f"give DATASET:VIEW")
    return test.cameras[int(view)]


def _axis_name(up) -> str:
    """``+y`` for (0, 1, 0), else the vector rounded to 3 decimals."""
    for name, vector in AXES.items():
        if np.allclose(up, vector, atol=1e-9):
            return name
    return ",".join(f"{v:.3g}" for v in up)


@click.command()
@click.argument("source", type=click.Path(path_type=Path))
@click.option("--out", "out", type=click.Path(path_type=Path), default=None, help="PNG to write (default: beside SOURCE).")
@click.option("--view", default=0, show_default=True, help="Camera index of a workload with several views.")
@click.option("--size", default=None, metavar="WxH", help="WxH of the framing camera used for a PLY (default 640x480).")
@click.option("--up", "up", default=None, metavar="AXIS|X,Y,Z",
              help="World up of a PLY (+y, -y, +z, -z, +x, -x or X,Y,Z). Default: the up the PLY records "
                   "(splatbench train writes it: +y for the Mitsuba scenes), else -y (COLMAP's y-down world).")
@click.option("--elevation", type=click.FloatRange(-89, 89), default=None, metavar="DEG",
              help="Degrees above the horizontal the framing camera looks down from. Default: "
                   f"{KNOWN_UP_ELEVATION:g} when the up is known (recorded or --up), else 0.")
@click.option("--camera", "camera_spec", default=None, metavar="DATASET[:VIEW]",
              help="Render a PLY from test view VIEW (default 0) of a dataset folder, at its size, instead of "
                   "the framing camera (--size, --up and --elevation then do not apply).")
@click.option("--downscale", type=click.IntRange(min=1), default=None, metavar="N",
              help="With --camera: load the dataset at 1/N of its image size, as `train --set data.downscale=N` "
                   "does (default 1: full size).")
@click.option("--background", "background", default=None, metavar="R,G,B",
              help="RGB in [0, 1] behind the splats. Default: the background the PLY records "
                   "(the one it was trained on), else black.")
@click.option("--sh-degree", type=int, default=None, help="SH bands to evaluate (default: all).")
@click.option("--option", "options", multiple=True, help="Rasterizer option key=value (repeatable), e.g. tile_size=8.")
def render(source: Path, out: Path | None, view: int, size: str | None, up: str | None, elevation: float | None,
           camera_spec: str | None, downscale: int | None, background: str | None, sh_degree: int | None, options: tuple[str, ...]) -> None:
    """Render SOURCE (a 3DGS .ply, a bundled model: guitar or biker, or a workload .npz) to a PNG and print its path.

    A PLY is framed by a camera looking at the middle of its Gaussians, with the world's
    up (--up, or the one the PLY records) up in the image."""
    import splatbench
    from splatbench.images import save_png
    from splatbench.raster.options import RasterOptions
    from splatbench.ply import read_view_hints
    from splatbench.workloads import load_npz

    if sh_degree is not None:
        check_sh_degree("--sh-degree", sh_degree)
    if camera_spec is not None and (up is not None or elevation is not None or size is not None):
        given = "--up" if up is not None else "--elevation" if elevation is not None else "--size"
        raise InputError(f"{given}: does not apply with --camera (the dataset's camera is placed and sized "
                         f"already; --downscale N sizes it); leave it out")
    if downscale is not None and camera_spec is None:
        raise InputError("--downscale: only with --camera DATASET[:VIEW] (it sizes the dataset's camera); leave it out")
    up_vector = parse_up(up) if up is not None else None
    rgb = parse_background(background) if background is not None else None
    if not source.exists() and str(source).lower() in BUNDLED_MODELS:  # `render guitar`, as `compare --model`
        out = out or Path(f"{str(source).lower()}.png")
        source = BUNDLED_MODELS[str(source).lower()]
    out = out or source.with_suffix(".png")
    if out.is_dir():
        raise InputError(f"--out: {str(out)!r} is a folder; give the path of the PNG to write")
    notes: list[str] = []
    if source.suffix == ".ply":
        width, height = parse_size(size or "640x480", "--size")
        check_image_size(width, height, field="--size")
        gaussians = splatbench.Gaussians.from_ply(source)
        if len(gaussians) == 0:
            raise InputError(f"source: {str(source)!r} holds 0 Gaussians (an empty vertex element); nothing to render")
        hints = read_view_hints(source)
        if rgb is None and hints.background is not None:
            rgb = hints.background
            notes.append(f"background {[round(c, 4) for c in rgb]} (recorded in the PLY)")
        if camera_spec is not None:
            camera = dataset_camera(camera_spec, downscale or 1)
            notes.append(f"camera: test view of {camera_spec} at downscale {downscale or 1} "
                         f"({camera.width}x{camera.height})")
        else:
            camera, note = _framing(gaussians, width, height, up_vector, hints.up, elevation)
            notes = [note, *notes] if note else notes
    elif source.suffix == ".npz":
        given = [o for o, v in (("--up", up), ("--elevation", elevation), ("--camera", camera_spec), ("--size", size),
                                ("--downscale", downscale)) if v is not None]
        if given:
            raise InputError(f"{given[0]}: only for a .ply (a workload .npz brings its own camera); leave it out")
        workload = load_npz(source, view=view)
        gaussians, camera = workload.gaussians, workload.camera
    else:
        raise InputError(f"source: expected a .ply or .npz file, got {str(source)!r}")
    result = splatbench.render(gaussians, camera, sh_degree=sh_degree, background=rgb or (0.0, 0.0, 0.0),
                               options=RasterOptions.from_dict(parse_overrides(options, "--option")))
    path = save_png(result.rgb, out)
    for note in notes:
        click.echo(f"note: {note}", err=True)
    click.echo(f"rendered {len(gaussians)} Gaussians at {camera.width}x{camera.height}: {path.resolve()}")


def _framing(gaussians, width: int, height: int, up, recorded_up, elevation: float | None):
    """The framing camera for ``--up`` (``up``), else the PLY's ``recorded_up``, else
    `DEFAULT_UP` (level: the up is a guess), and a note saying where the up came from."""
    if up is not None:
        note = ""
    elif recorded_up is not None:
        up, note = recorded_up, f"up {_axis_name(recorded_up)} (recorded in the PLY)"
    else:
        up, note = DEFAULT_UP, (f"up {_axis_name(DEFAULT_UP)} (COLMAP's y-down world; the PLY records none: "
                                f"pass --up +y if the picture is upside down)")
        elevation = 0.0 if elevation is None else elevation
    elevation = KNOWN_UP_ELEVATION if elevation is None else elevation
    return framing_camera(gaussians, width, height, up=up, elevation_deg=elevation), note
