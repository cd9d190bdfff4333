"""`splatbench render`: render a 3DGS PLY or a workload npz to a PNG."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from splatbench.checks import check_image_size, check_sh_degree
from splatbench.errors import InputError
from splatbench.overrides import parse_overrides


def framing_camera(gaussians, width: int, height: int, fov_x_deg: float = 50.0):
    """A look-at camera that frames the central 98 % of the Gaussians from -z.

    The framed radius is at least 3 standard deviations of the largest of those
    Gaussians (so one Gaussian, or several at one point, fill the view rather than
    vanish), and the near plane is 1 % of the camera's distance (so a small scene is
    not clipped by the default near plane)."""
    from splatbench import Camera

    if len(gaussians) == 0:
        raise InputError("gaussians: 0 Gaussians, nothing to frame or render")
    lo, hi = np.percentile(gaussians.means, [1, 99], axis=0)
    center = (lo + hi) / 2
    sigma = float(np.percentile(np.exp(np.clip(gaussians.log_scales, -20, 20)).max(axis=1), 99))
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 3 * sigma, 1e-6)
    distance = radius / np.tan(np.radians(fov_x_deg) / 2) * 1.2
    return Camera.look_at(center - np.array([0.0, 0.0, distance]), center, np.array([0.0, -1.0, 0.0]),
                          width, height, fov_x_deg, near=min(0.01, distance / 100))


@click.command()
@click.argument("source", type=click.Path(path_type=Path))
@click.option("--out", "out", type=click.Path(path_type=Path), default=None, help="PNG to write (default: beside SOURCE).")
@click.option("--view", default=0, show_default=True, help="Camera index of a workload with several views.")
@click.option("--size", default="640x480", show_default=True, help="WxH of the framing camera used for a PLY.")
@click.option("--sh-degree", type=int, default=None, help="SH bands to evaluate (default: all).")
@click.option("--option", "options", multiple=True, help="Rasterizer option key=value (repeatable), e.g. tile_size=8.")
def render(source: Path, out: Path | None, view: int, size: str, sh_degree: int | None, options: tuple[str, ...]) -> None:
    """Render SOURCE (a 3DGS .ply or a workload .npz) to a PNG and print its path."""
    import splatbench
    from splatbench.images import save_png
    from splatbench.workloads import load_npz

    if sh_degree is not None:
        check_sh_degree("--sh-degree", sh_degree)
    out = out or source.with_suffix(".png")
    if out.is_dir():
        raise InputError(f"--out: {str(out)!r} is a folder; give the path of the PNG to write")
    if source.suffix == ".ply":
        try:
            width, height = (int(v) for v in size.lower().split("x"))
        except ValueError:
            raise InputError(f"--size: expected WxH, got {size!r}") from None
        check_image_size(width, height, field="--size")
        gaussians = splatbench.Gaussians.from_ply(source)
        if len(gaussians) == 0:
            raise InputError(f"source: {str(source)!r} holds 0 Gaussians (an empty vertex element); nothing to render")
        camera = framing_camera(gaussians, width, height)
    elif source.suffix == ".npz":
        workload = load_npz(source, view=view)
        gaussians, camera = workload.gaussians, workload.camera
    else:
        raise InputError(f"source: expected a .ply or .npz file, got {str(source)!r}")
    result = splatbench.render(gaussians, camera, sh_degree=sh_degree, **parse_overrides(options, "--option"))
    path = save_png(result.rgb, out)
    click.echo(f"rendered {len(gaussians)} Gaussians at {camera.width}x{camera.height}: {path.resolve()}")
