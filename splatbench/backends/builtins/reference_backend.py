"""The ``reference`` backends, and `reference_render`: THE adapter from splatbench inputs to the oracle.

    reference_render(conventions, means, ..., sh, camera, *, mode=...)   float64 numpy render
    make_reference_backend(mode="matched", **conventions)                  a `Backend` (torch in/out)

``reference`` renders in ``mode="matched"`` with graphdeco's approximations (or the ones
given); ``reference-exact`` renders the exact Gaussian mixture (``mode="exact"``: no
cutoff, no alpha clamp, no skip, no early stop; the Jacobian clamp stays). Both differentiate by central finite
differences of the oracle (`reference.finite_difference_grad`): two renders per
parameter entry, so only for tiny scenes (``slow_gradients=True``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from splatbench.backends.base import AXES, AXIS, GRAPHDECO, GROUPS, Backend, BackendInfo, as_numpy
from splatbench.errors import InputError

MODES = ("matched", "exact")
#: `reference.render` keywords a conventions mapping may set (near/far default to the camera's).
REFERENCE_OPTIONS = ("alpha_min", "alpha_max", "transmittance_min", "eps2d", "radius", "antialiased", "near", "far")
#: The vocabulary's axes a conventions mapping may also set (`splatbench.backends.base.AXES`).
AXIS_OPTIONS = tuple(a.name for a in AXES if a.name not in REFERENCE_OPTIONS)
#: Rasterizer options with no counterpart in the reference (accelerations and placement only).
FAST_ONLY = ("tile_size", "pixel_block", "device")
#: Central-difference half step. In float64 the truncation error is O(eps^2) ~ 1e-12 and the
#: rounding error ~ 1e-16 / eps ~ 1e-10 relative, both far below float32 roundoff.
FD_EPS = 1e-6


def _options(conventions, camera) -> dict:
    """`reference.render` keywords from a BackendInfo, a Backend, a mapping or None (graphdeco)."""
    if conventions is None:
        opts = {k: GRAPHDECO[k] for k in ("alpha_min", "alpha_max", "transmittance_min", "eps2d", "radius",
                                          "antialiased")}
    elif isinstance(conventions, Backend):
        opts = conventions.info.reference_options()
    elif isinstance(conventions, BackendInfo):
        opts = conventions.reference_options()
    elif isinstance(conventions, Mapping):
        opts = {}
        for key, value in conventions.items():
            if key in FAST_ONLY:
                continue
            if key not in REFERENCE_OPTIONS + AXIS_OPTIONS:
                raise InputError(f"conventions: {key!r} has no counterpart in the reference "
                                 f"(known: {', '.join(REFERENCE_OPTIONS + AXIS_OPTIONS + FAST_ONLY)})")
            if value is not None:  # RasterOptions' near/far None means "the camera's"
                opts[key] = value
    else:
        raise InputError(f"conventions: expected a BackendInfo, a Backend, a mapping or None, "
                         f"got {type(conventions).__name__}")
    opts.setdefault("near", camera.near)
    opts.setdefault("far", camera.far)
    return _axes_to_keywords(opts)


def _axes_to_keywords(opts: dict) -> dict:
    """Replace the vocabulary's axes in ``opts`` by the `reference.render` keywords that follow them."""
    out = {k: v for k, v in opts.items() if k not in AXIS_OPTIONS}
    for name in AXIS_OPTIONS:
        value = opts.get(name, AXIS[name].graphdeco)
        if value != AXIS[name].graphdeco and value not in AXIS[name].alternatives:
            raise InputError(f"conventions: {name}={value!r} is not in the vocabulary "
                             f"(one of {[AXIS[name].graphdeco, *AXIS[name].alternatives]})")
        if name == "pixel_centre":
            out["pixel_offset"] = 0.5 if value == "half" else 0.0
        elif name == "sh_view_direction":  # "detached" renders alike; its gradients are conform's to fake
            out[name] = "camera_to_mean" if value == "detached" else value
        elif name == "sh_degree":
            out["sh_degree_arg"] = value != "ignored"
            out["sh_max_degree"] = 3 if value == "ignored" else value
        elif name == "background":
            out["background_mode"] = value
        elif name == "jacobian_clamp":
            out["jacobian_guard"] = None if value == "none" else float(value) - 1.0
        elif name == "near_plane":
            if value != "camera":
                out["near"] = float(value)
        elif name == "depth":
            out["depth_mode"] = value
        else:  # quat_order, scale_activation, opacity_activation, sort_key, sh_basis, colour_clamp
            out[name] = value
    return out


def reference_render(conventions, means, log_scales, quats, opacity_logits, sh, camera, *, mode="matched",
                     sh_degree=None, background=None, band=False):
    """Render with the float64 oracle, following ``conventions`` (in ``mode="matched"``).

    Args:
        conventions: whose approximations to reproduce: a `BackendInfo` or `Backend`
            (its declared ones, graphdeco's where undeclared), a mapping of
            `reference.render` keywords (alpha_min, alpha_max, transmittance_min, eps2d,
            radius, antialiased, near, far; `RasterOptions`' tile_size and device are
            ignored, a None near/far means the camera's), or None (graphdeco's).
            Ignored in ``mode="exact"`` except near/far.
        means [N, 3], log_scales [N, 3], quats [N, 4] (w, x, y, z), opacity_logits [N],
            sh [N, K, 3]: numpy arrays or torch tensors (cast to float64).
        camera: `splatbench.Camera` (intrinsics, pose, size; near/far unless given).
        mode: "matched" (the conventions above) or "exact" (the exact Gaussian mixture).
        sh_degree: bands evaluated (None = all in ``sh``). background: RGB (None = black).
        band: also the boundary band and tie slack (`reference.band`; matched mode).

    Returns:
        `reference.RenderOutput` (rgb [H, W, 3], alpha [H, W], depth [H, W], radii [N],
        visible [N], band [H, W] and tie_slack [H, W] or None), float64 numpy.
    """
    import reference

    kwargs = reference_kwargs(conventions, camera, mode, sh_degree, background)
    arrays = [as_numpy(x) for x in (means, log_scales, quats, opacity_logits, sh)]
    try:
        return reference.render(*arrays, band=band, **kwargs)
    except ValueError as exc:  # the oracle's own one-line messages name the field
        raise InputError(str(exc)) from None


def reference_kwargs(conventions, camera, mode, sh_degree, background) -> dict:
    """Every keyword of `reference.render` but the five parameter groups (used by `reference_render`,
    the FD backward and compare's sampled finite differences)."""
    if mode not in MODES:
        raise InputError(f"mode: expected one of {list(MODES)}, got {mode!r}")
    opts = _options(conventions, camera)
    if mode == "exact":  # the exact mixture: no approximation, graphdeco's conventions
        opts = {k: opts[k] for k in ("near", "far")}
    bg = (0.0, 0.0, 0.0) if background is None else tuple(float(b) for b in as_numpy(background).reshape(3))
    return dict(K=camera.K, world_to_camera=camera.world_to_camera, width=camera.width, height=camera.height,
                mode=mode, background=bg, sh_degree=sh_degree, **opts)


def _fd_vjp(params: dict, grad_outputs, which, render_kwargs: dict) -> list:
    """sum(v . outputs) differentiated by central differences, for the groups in ``which``."""
    import reference

    v_rgb, v_alpha, v_depth = (np.zeros(()) if g is None else as_numpy(g) for g in grad_outputs)

    def loss(out):
        return float((out.rgb * v_rgb).sum() + (out.alpha * v_alpha).sum() + (out.depth * v_depth).sum())

    return [reference.finite_difference_grad(loss, *params.values(), wrt=k, eps=FD_EPS, **render_kwargs)
            if k in which else None for k in GROUPS]


def _render_fn(mode: str, conventions: dict):
    import torch

    class _ReferenceRender(torch.autograd.Function):
        @staticmethod
        def forward(ctx, means, log_scales, quats, opacity_logits, sh, camera, sh_degree, background):
            out = reference_render(conventions, means, log_scales, quats, opacity_logits, sh, camera, mode=mode,
                                   sh_degree=sh_degree, background=background)
            inputs = (means, log_scales, quats, opacity_logits, sh)
            ctx.params = {k: as_numpy(x) for k, x in zip(GROUPS, inputs)}
            ctx.dtypes = [getattr(x, "dtype", torch.float32) for x in inputs]
            ctx.camera, ctx.sh_degree, ctx.background = camera, sh_degree, background
            return tuple(torch.from_numpy(np.ascontiguousarray(x)) for x in (out.rgb, out.alpha, out.depth))

        @staticmethod
        def backward(ctx, v_rgb, v_alpha, v_depth):
            which = {k for k, need in zip(GROUPS, ctx.needs_input_grad[:5]) if need}
            kwargs = reference_kwargs(conventions, ctx.camera, mode, ctx.sh_degree, ctx.background)
            grads = _fd_vjp(ctx.params, (v_rgb, v_alpha, v_depth), which, kwargs)
            return (*(None if g is None else torch.from_numpy(g).to(dtype) for g, dtype in zip(grads, ctx.dtypes)),
                    None, None, None)

    def fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        return _ReferenceRender.apply(means, log_scales, quats, opacity_logits, sh, camera, sh_degree, background)

    return fn


def make_reference_backend(mode: str = "matched", **conventions) -> Backend:
    """The float64 oracle as a backend: ``reference`` (matched) or ``reference-exact``.

    ``conventions``: `reference.render` keywords (see `reference_render`) overriding
    graphdeco's in matched mode. Outputs are float64 torch tensors; gradients (in the
    inputs' dtype) are central differences of the oracle, two renders per entry.
    """
    if mode not in MODES:
        raise InputError(f"mode: expected one of {list(MODES)}, got {mode!r}")
    import reference  # noqa: F401  (fails early if the package is missing)
    from splatbench.versions import SPLATBENCH_VERSION

    unknown = sorted(set(conventions) - set(REFERENCE_OPTIONS))
    if unknown:
        raise InputError(f"{unknown[0]}: not a reference option (known: {', '.join(REFERENCE_OPTIONS)})")
    if mode == "exact":
        info = BackendInfo(name="reference-exact", version=SPLATBENCH_VERSION, dtype="float64",
                           slow_gradients=True, alpha_min=0.0, alpha_max=1.0, transmittance_min=0.0, eps2d=0.3,
                           radius="none", tile_size=0, antialiased=False, exact=True,
                           description="float64 NumPy oracle, exact Gaussian mixture (eps2d 0.3 low-pass kept; "
                                       "no cutoff, clamp, skip or early stop); gradients by finite differences")
    else:
        merged = {k: conventions.get(k, GRAPHDECO[k]) for k in ("alpha_min", "alpha_max", "transmittance_min",
                                                                "eps2d", "radius", "antialiased")}
        info = BackendInfo(name="reference", version=SPLATBENCH_VERSION, dtype="float64",
                           slow_gradients=True, tile_size=0, **merged,
                           description="float64 NumPy oracle (reference/), matched to graphdeco's conventions, "
                                       "one pixel at a time; gradients by central finite differences")
    return Backend(_render_fn(mode, dict(conventions)), info)


def make_reference_exact_backend() -> Backend:
    """``reference-exact``: the oracle in ``mode="exact"``."""
    return make_reference_backend("exact")
