"""The probes of `splatbench conform`, in the order they run: what each checks, how it is judged,
and the most likely cause of its failure.

Kinds:
  forward        outputs (rgb, alpha, depth) against the oracle with the backend's declared conventions
  gradient       a random-cotangent VJP per parameter group against central differences of the oracle
  direction      the same VJP along directions of (log_scales, quats) that move one conic term
                 (A, B or C) of each Gaussian and nothing else, to first order
  (the three basic probes, first, are forward probes of plain scenes that conform fingerprints first)
  approximation  a declared approximation (early stop, radius rule): "pass" when the backend does
                 what it declares, "warn" when every pixel matches one of the listed alternatives
                 (e.g. no early stop at all), "fail" otherwise
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from splatbench.conform.probe_scenes import (
    alpha_max, alpha_min, background, basic_centred, basic_offaxis, basic_overlap, colour_clamp, conic,
    depth_order, early_stop, eps2d, expected_depth, gradients, intrinsics, jacobian_clamp, near_plane,
    opacity_activation, pixel_centre, quat_norm, quat_order, radius, scale_activation, sh_degree1, sh_degree2,
    sh_degree3, sh_degree_arg, sh_viewdir, sh_viewdir_grad, tiles)
from splatbench.gaussians import GROUPS
from splatbench.render_inputs import RenderInput

KINDS = ("forward", "gradient", "direction", "approximation")


@dataclass(frozen=True)
class Probe:
    """One conformance probe.

    name: short id; checks: what it isolates (one line); kind: one of KINDS; cause: the
    most likely cause of a failure (one sentence); build: () -> RenderInput (deterministic).
    outputs: outputs compared (forward kinds). groups: parameter groups compared (gradient).
    conic_term: 0, 1, 2 for A, B, C (direction). alternatives: for approximation probes,
    convention overrides a backend may follow instead of its declared ones, with a warning.
    """

    name: str
    checks: str
    kind: str
    cause: str
    build: Callable[[], RenderInput]
    outputs: tuple[str, ...] = ("rgb", "alpha", "depth")
    groups: tuple[str, ...] = ()
    conic_term: int | None = None
    alternatives: tuple[dict, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind: expected one of {list(KINDS)}, got {self.kind!r}")


# ----------------------------------------------------------------------------
# The probes, in the order they run
# ----------------------------------------------------------------------------

#: The basic probes run (and are fingerprinted) first: they pin the conventions everything else depends on.
BASIC = ("basic_centred", "basic_overlap", "basic_offaxis")

PROBES: tuple[Probe, ...] = (
    Probe("basic_centred", "one anisotropic Gaussian near the centre, degree-1 SH", "forward",
          "a basic convention differs (pixel centre, activations, quaternion order, eps2d, SH): see the diagnosis",
          basic_centred),
    Probe("basic_overlap", "two overlapping translucent Gaussians, listed far first, over a background", "forward",
          "compositing differs (order, transmittance, background): see the diagnosis", basic_overlap),
    Probe("basic_offaxis", "a camera far from the world origin looking away from it, degree-1 SH", "forward",
          "the camera pose or the SH view direction is handled differently: see the diagnosis", basic_offaxis),
    Probe("depth_order", "overlapping Gaussians listed far to near, in an order that a sort on index, on world z "
          "or on a strided read of the camera coordinates gets wrong", "forward",
          "Gaussians are not composited in ascending camera depth (sorted on the wrong key: index, world z, "
          "or a strided view of the camera-space points read as contiguous)", depth_order),
    Probe("pixel_centre", "small Gaussians at sub-pixel positions: pixel (i, j) is sampled at (j + 0.5, i + 0.5)",
          "forward", "pixels are sampled at integer coordinates (or a half-pixel shift is applied twice), "
          "not at the pixel centres (j + 0.5, i + 0.5)", pixel_centre),
    Probe("quat_order", "anisotropic Gaussians with generic unit quaternions in (w, x, y, z) order", "forward",
          "quaternions are read in (x, y, z, w) order, or the rotation matrix is transposed", quat_order),
    Probe("quat_norm", "the same Gaussians with quaternions of length 2.7 and 0.45", "forward",
          "quaternions are not normalised before building the rotation", quat_norm),
    Probe("scale_activation", "log_scales below zero: scales = exp(log_scales)", "forward",
          "log_scales are used as scales (exp activation missing or applied twice)", scale_activation),
    Probe("opacity_activation", "opacity logits below zero: opacity = sigmoid(logit)", "forward",
          "opacity_logits are used as opacities (sigmoid activation missing)", opacity_activation),
    Probe("eps2d", "Gaussians far below a pixel, drawn by the eps2d = 0.3 px^2 low-pass alone", "forward",
          "the 2D covariance lacks the eps2d low-pass (or uses another value than declared)", eps2d),
    Probe("jacobian_clamp", "centres outside graphdeco's 1.3 x half field-of-view limit, footprints inside the "
          "image", "forward", "the EWA Jacobian is not evaluated at the point clamped to 1.3 x the half field "
          "of view (graphdeco's limit), or the clamp is applied to the 2D mean too", jacobian_clamp),
    Probe("near_plane", "a Gaussian between the camera and camera.near, and one behind the camera", "forward",
          "Gaussians nearer than camera.near (or behind the camera) are drawn: near-plane culling missing "
          "or camera.near ignored", near_plane),
    Probe("alpha_max", "an opaque wide Gaussian whose alpha exceeds the clamp (forward)", "forward",
          "alpha is not clamped at the declared alpha_max (graphdeco 0.99)", alpha_max),
    Probe("alpha_max_grad", "the same scene, every gradient: none flows through the clamped alpha", "gradient",
          "the backward clamps alpha at another value than the forward (or not at all), so gradients "
          "flow through pixels whose alpha the forward clamped", alpha_max, groups=GROUPS),
    Probe("alpha_min", "a Gaussian of opacity 0.003 < 1/255 and one whose alpha crosses 1/255", "forward",
          "contributions with alpha < alpha_min (1/255) are composited (declare alpha_min=0 if that is "
          "intended)", alpha_min),
    Probe("sh_degree1", "degree-1 SH only, at six view directions: band order and signs", "forward",
          "degree-1 SH basis order or signs differ from graphdeco's (-C1 y, +C1 z, -C1 x)", sh_degree1,
          outputs=("rgb",)),
    Probe("sh_degree2", "degree-2 SH only, at six view directions: band order and signs", "forward",
          "degree-2 SH basis order, signs or constants differ from graphdeco's utils/sh_utils.py", sh_degree2,
          outputs=("rgb",)),
    Probe("sh_degree3", "degree-3 SH only, at six view directions: band order and signs", "forward",
          "degree-3 SH basis order, signs or constants differ from graphdeco's utils/sh_utils.py", sh_degree3,
          outputs=("rgb",)),
    Probe("sh_degree_arg", "SH with 16 bases rendered with sh_degree=1", "forward",
          "the sh_degree argument is ignored: bands above it are evaluated", sh_degree_arg, outputs=("rgb",)),
    Probe("sh_viewdir", "degree-1 SH with the camera far from the world origin", "forward",
          "the SH view direction is not normalize(mean - camera centre) in world space (taken from the "
          "origin, in camera space, or reversed)", sh_viewdir, outputs=("rgb",)),
    Probe("sh_viewdir_grad", "strong degree-1 SH on wide Gaussians: d/dmeans through the view direction",
          "gradient", "the SH view direction is detached from the means, so d/dmeans misses the colour term",
          sh_viewdir_grad, groups=("means",)),
    Probe("colour_clamp", "SH colours below 0 and above 1 in some channels: colour = max(SH + 0.5, 0)", "forward",
          "the SH colour is not max(SH + 0.5, 0): the clamp at 0 is missing, or colours are also clamped at 1",
          colour_clamp, outputs=("rgb",)),
    Probe("background", "translucent Gaussians over the background (0.2, 0.5, 0.9)", "forward",
          "the background is not blended by the final transmittance (rgb + T_final * background)", background,
          outputs=("rgb", "alpha")),
    Probe("expected_depth", "translucent Gaussians at three depths, off the optical axis", "forward",
          "depth is not the expected camera z normalised by alpha (sum T a z / alpha): unnormalised, or ray "
          "distance instead of camera z", expected_depth, outputs=("depth",)),
    Probe("intrinsics", "a 24x16 image with fx != fy and an off-centre principal point", "forward",
          "fx/fy or cx/cy are mixed up, or width and height are swapped", intrinsics),
    Probe("tiles", "footprints centred on tile corners and edges (tiles of 8 and 16) of a 32x32 image",
          "forward", "a Gaussian is drawn only in some of the tiles its footprint overlaps (tile binning)", tiles),
    *(Probe(f"grad_{g}", f"d/d{g} of a random-cotangent loss over rgb, alpha and depth", "gradient",
            f"the backward pass into {g} is wrong", gradients, groups=(g,)) for g in GROUPS),
    *(Probe(f"conic_{t}", f"the gradient along a direction of (log_scales, quats) that moves only conic term "
                          f"{t} ({w}) of each Gaussian", "direction",
            f"the gradient of conic term {t} ({w}) is wrong: e.g. the off-diagonal term counted once instead of "
            f"twice in a symmetric matrix" if t == "B" else f"the gradient of conic term {t} ({w}) is wrong",
            conic, conic_term=i)
      for i, (t, w) in enumerate((("A", "xx"), ("B", "xy"), ("C", "yy")))),
    Probe("early_stop", "three near-opaque layers: transmittance falls below 1e-4 at the third", "approximation",
          "compositing does not stop where T would fall below the declared transmittance_min", early_stop,
          alternatives=({"transmittance_min": 0.0},)),
    Probe("radius", "an opacity-0.98 Gaussian: alpha > 1/255 beyond 3 sigma", "approximation",
          "the footprint is cut at another radius than declared (3 sigma in graphdeco)", radius,
          alternatives=({"radius": "3sigma"}, {"radius": "opacity"})),
)


#: Each axis of the convention vocabulary -> the probes that isolate it (a diagnosis names these).
AXIS_PROBES: dict[str, tuple[str, ...]] = {
    "pixel_centre": ("pixel_centre",), "opacity_activation": ("opacity_activation",),
    "scale_activation": ("scale_activation",), "quat_order": ("quat_order",), "eps2d": ("eps2d",),
    "background": ("background",), "sh_view_direction": ("sh_viewdir", "sh_viewdir_grad"), "sort_key": ("depth_order",),
    "sh_basis": ("sh_degree1", "sh_degree2", "sh_degree3"), "sh_degree": ("sh_degree_arg", "sh_degree3", "sh_degree2"),
    "colour_clamp": ("colour_clamp",), "jacobian_clamp": ("jacobian_clamp",), "alpha_max": ("alpha_max",),
    "alpha_min": ("alpha_min",), "near_plane": ("near_plane",), "depth": ("expected_depth",),
    "radius": ("radius",), "transmittance_min": ("early_stop",),
}


def probe_names() -> tuple[str, ...]:
    return tuple(p.name for p in PROBES)
