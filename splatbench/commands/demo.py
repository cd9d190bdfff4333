"""`splatbench demo`: the main job.

Until the experiment runner exists, it renders the bundled real capture (the
Mip-NeRF 360 "garden" SfM points, seeded as 3DGS does) with both the Dr.Jit
rasterizer and the float64 reference, and writes the image and their difference.
"""

from __future__ import annotations

import time
from pathlib import Path

import click
import numpy as np


@click.command()
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("out/demo"), show_default=True,
              help="Folder for the images.")
@click.option("--scale", default=0.25, show_default=True, help="Resolution factor for the reference check.")
def demo(out: Path, scale: float) -> None:
    """Render the bundled garden capture and check it against the reference."""
    import reference
    import splatbench
    from splatbench.images import save_png
    from splatbench.workloads import GARDEN_SFM, load_npz

    workload = load_npz(GARDEN_SFM, view=0)
    g, camera = workload.gaussians, workload.camera
    splatbench.render(g, camera)  # compile (kernels are cached in ~/.drjit)
    t0 = time.perf_counter()
    full = splatbench.render(g, camera)
    seconds = time.perf_counter() - t0
    image = save_png(full.rgb, out / "garden.png")
    click.echo(f"Dr.Jit rasterizer: {len(g)} Gaussians at {camera.width}x{camera.height} in {seconds * 1e3:.0f} ms")

    small = camera.scaled(scale)
    fast = splatbench.render(g, small)
    ref = reference.render(g.means, g.log_scales, g.quats, g.opacity_logits, g.sh, small.K,
                           small.world_to_camera, small.width, small.height, mode="matched")
    err = np.abs(fast.rgb - ref.rgb)
    save_png(np.clip(err / max(float(err.max()), 1e-12), 0, 1), out / "garden_difference.png")
    click.echo(f"reference check at {small.width}x{small.height}: max |fast - reference| = {err.max():.2e}")
    click.echo(f"image: {image.resolve()}")
