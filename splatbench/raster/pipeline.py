"""The rasterizer pipeline: project -> SH colour -> bin -> composite -> expected depth."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from splatbench.guards import check_image_size, check_sh_degree
from splatbench.errors import InputError
from splatbench.gaussians import SH_BASES_OF_DEGREE
from splatbench.raster.device import dr
from splatbench.raster.binning import Bins, TileGrid, bin_gaussians
from splatbench.raster.compositing import Composite, CompositeState, composite, composite_loop_ad
from splatbench.raster.hooks import NO_HOOKS, Hooks
from splatbench.raster.options import RasterOptions
from splatbench.raster.projection import Projection, array_namespace, clip_planes, columns, normalize, project
from splatbench.raster.sh import eval_sh

# Input domain (docs/conventions.md): larger SH coefficients make the true gradients
# exceed float32, so they are rejected at the boundary rather than turned into Inf.
SH_ABS_MAX = 1e6


def check_sh_range(largest: float, where) -> None:
    """Raise `InputError` when the largest |sh| coefficient exceeds `SH_ABS_MAX`."""
    if largest > SH_ABS_MAX:
        raise InputError(f"sh: |value| {largest:.3g} at index {[int(i) for i in where]} exceeds the supported "
                         f"range {SH_ABS_MAX:g}")


class Frame(NamedTuple):
    """One rendered view as Dr.Jit arrays (row-major pixels, width H*W).

    rgb: Array3f; alpha: Float; depth: Float (expected camera z, 0 where alpha is 0);
    projection: the per-Gaussian `Projection`; state: binning and backward buffers.
    """

    rgb: object
    alpha: object
    depth: object
    projection: Projection
    state: CompositeState


def resolve_sh_degree(num_bases: int, sh_degree: int | None) -> int:
    """The SH degree to evaluate, validated against the K bases that ``sh`` holds."""
    if num_bases not in SH_BASES_OF_DEGREE:
        raise InputError(f"sh: expected K in {SH_BASES_OF_DEGREE} bases, got K={num_bases}")
    available = SH_BASES_OF_DEGREE.index(num_bases)
    if sh_degree is None:
        return available
    sh_degree = check_sh_degree("sh_degree", sh_degree)
    if sh_degree > available:
        raise InputError(f"sh_degree: {sh_degree} needs {(sh_degree + 1) ** 2} SH bases, but sh has K={num_bases}")
    return int(sh_degree)


def check_background(background) -> tuple[float, float, float]:
    """An RGB background: 3 values in [0, 1] (colours are not clamped, so a value
    outside would shine through every translucent splat)."""
    try:
        bg = np.asarray(background if background is not None else (0.0, 0.0, 0.0), dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"background: expected 3 values in [0, 1], got {background!r}") from None
    if bg.shape != (3,) or not np.isfinite(bg).all() or (bg < 0).any() or (bg > 1).any():
        raise InputError(f"background: expected 3 values in [0, 1], got {np.asarray(background).tolist()!r}")
    return tuple(float(c) for c in bg)


def check_options(options) -> RasterOptions:
    """The ``options`` argument of `render` and `rasterize`: a `RasterOptions` as it is, None for
    the defaults; anything else (a dict of options, say) is one `InputError` line naming the fix."""
    if options is None:
        return RasterOptions()
    if not isinstance(options, RasterOptions):
        raise InputError(f"options: expected splatbench.RasterOptions or None, got {type(options).__name__} "
                         f"(build one: RasterOptions(tile_size=8), or RasterOptions.from_dict(table))")
    return options


def check_view(camera, options: RasterOptions) -> None:
    """The one camera check of `render` and `rasterize`, before any work: ``camera`` is a
    `splatbench.Camera` (whose fields were checked when it was built, and whose matrix is
    read-only since), its image size fits Dr.Jit and the memory available now, and the
    clip planes in effect have near < far. One-line `InputError` otherwise."""
    from splatbench.cameras import Camera

    if not isinstance(camera, Camera):
        raise InputError(f"camera: expected splatbench.Camera, got {type(camera).__name__}")
    check_image_size(camera.width, camera.height, field="camera width, height")
    check_clip_planes(camera, options)


def check_clip_planes(camera, options: RasterOptions) -> None:
    """The planes in effect must have 0 < near < far; otherwise every Gaussian is culled
    and the image is blank."""
    near, far = clip_planes(camera, options)
    if not near < far:
        raise InputError(f"near, far: expected near < far, got near={near!r}, far={far!r} "
                         f"(options, else the camera's)")


def render_frame(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree: int,
                 background: tuple[float, float, float], options: RasterOptions,
                 absgrad: bool = False, hooks: Hooks = NO_HOOKS) -> Frame:
    """Render one view from Dr.Jit tensors (AD flows to whichever inputs have it enabled):
    `project` -> `view_colors` -> `bin_gaussians` -> `composite`, each stage handing its
    typed result to the next and reading its options from ``options`` (`RasterOptions`).

    Args:
        means: [N, 3], log_scales: [N, 3], quats: [N, 4], opacity_logits: [N],
        sh: [N, K, 3] Dr.Jit tensors (TensorXf). camera: `splatbench.Camera`.
        sh_degree: validated degree (see `resolve_sh_degree`).
        absgrad: accumulate the AbsGS screen-space gradient in the backward pass.
        hooks: test and benchmark `Hooks` (none from the public entry points).
    """
    if means.shape[0] == 0:
        return _empty_frame(means, camera, background, options)
    timer = hooks.timer
    proj = project(means, log_scales, quats, opacity_logits, camera, options)
    colors = view_colors(means, sh, camera, sh_degree)
    # One kernel for every per-Gaussian quantity (the compositing loop gathers from
    # them, which would otherwise evaluate each array in a kernel of its own).
    # Unpacked: Dr.Jit traverses tuples and dataclasses, but not NamedTuples.
    dr.eval(*proj, colors)
    if timer is not None:
        timer.mark("preprocess")
    bins = bin_gaussians(proj, camera, options, timer)
    if timer is not None:
        timer.mark("binning_sort")
    if hooks.loop_ad:
        out, state = composite_loop_ad(proj, colors, bins, options, background)
    else:
        out, state = composite(proj, colors, bins, options, background, absgrad=absgrad)
        state.timer = timer  # the backward pass marks "backward_compositing" on it
    covered = out.alpha > 0
    depth = dr.select(covered, out.depth_sum / dr.select(covered, out.alpha, 1.0), 0.0)
    if timer is not None:
        dr.eval(out.rgb, out.alpha, depth)
        timer.mark("compositing")
    return Frame(out.rgb, out.alpha, depth, proj, state)


def view_colors(means, sh, camera, sh_degree: int):
    """[N, 3] Array3f: each Gaussian's SH colour seen from the camera centre."""
    m = array_namespace(means.array)
    # the camera centre enters as opaque values, like the projection's camera constants:
    # as literals, every view compiled SH kernels of its own (degree >= 1)
    cx, cy, cz = (dr.opaque(m.Float, float(c)) for c in camera.center)
    mx, my, mz = columns(means, 3)
    dirs = m.Array3f(*normalize(mx - cx, my - cy, mz - cz))  # overflow-safe, like the oracle's
    return eval_sh(sh, dirs, sh_degree)


def _empty_frame(means, camera, background, options: RasterOptions) -> Frame:
    """No Gaussians: every pixel shows the background (zero-width arrays trip Dr.Jit's
    size checks, so the pipeline is not run at all)."""
    m = array_namespace(means.array)
    size = camera.width * camera.height
    zero = dr.zeros(m.Float, size)
    empty = m.Float()
    proj = Projection(m.Array2f(empty, empty), m.Array3f(empty, empty, empty), empty, empty, empty,
                      m.Array2f(empty, empty), m.Int32(), m.Bool())
    bins = Bins(TileGrid(camera.width, camera.height, options.tile_size), m.UInt32(),
                dr.zeros(m.UInt32, 1), dr.zeros(m.UInt32, 1), 0)
    rgb = m.Array3f(*(dr.full(m.Float, c, size) for c in background))
    return Frame(rgb, m.Float(zero), zero, proj, CompositeState(bins))


def frame_to_numpy(frame: Frame, height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rgb [H, W, 3], alpha [H, W], depth [H, W]) as float32 numpy copies."""
    rgb = np.array(frame.rgb.numpy(), dtype=np.float32).T.reshape(height, width, 3)
    alpha = np.array(frame.alpha.numpy(), dtype=np.float32).reshape(height, width)
    depth = np.array(frame.depth.numpy(), dtype=np.float32).reshape(height, width)
    return rgb, alpha, depth


__all__ = ["Frame", "render_frame", "frame_to_numpy", "resolve_sh_degree", "check_background",
           "check_clip_planes", "check_view", "Composite"]
