"""What "a rasterizer" is to splatbench: a callable plus a small frozen record of metadata.

A backend function has the signature::

    fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None)
        -> (rgb [H, W, 3], alpha [H, W], depth [H, W])

on float32 torch tensors: means [N, 3], log_scales [N, 3], quats [N, 4] (w, x, y, z,
not necessarily unit), opacity_logits [N], sh [N, K, 3] with K = (d + 1)^2; camera a
`splatbench.Camera` (OpenCV axes, pixel centres at j + 0.5, i + 0.5); background an
RGB triple (None = black); depth is the expected camera z normalised by alpha, 0 where
alpha is 0. Outputs are differentiable by torch autograd when ``info.gradients``.

The conventions are graphdeco-inria 3DGS's (docs/conventions.md). A backend declares
where it departs from the exact Gaussian mixture in `BackendInfo`; a field left None
means "not declared" and is taken to be graphdeco's value.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Protocol

import numpy as np

from splatbench.cameras import Camera
from splatbench.gaussians import GROUPS  # noqa: F401 - the backend signature's parameter groups, in its order
from splatbench.raster.options import RasterOptions

if TYPE_CHECKING:
    import torch

    from splatbench.cameras import Camera

# graphdeco-inria 3DGS's approximations, the defaults a backend with no metadata follows: the
# rasterizer's own defaults (`RasterOptions`, whose field comments give graphdeco's sources).
GRAPHDECO = {name: getattr(RasterOptions(), name) for name in ("alpha_min", "alpha_max", "transmittance_min",
                                                               "eps2d", "radius", "tile_size", "antialiased")}
OUTPUTS = ("rgb", "alpha", "depth")

if TYPE_CHECKING:  # the signatures' tensor type; a backend module loads torch itself when it renders
    import torch


def as_numpy(x) -> np.ndarray:
    """A backend's input or output (a torch tensor, on any device, or an array) as a float64
    numpy array on the host."""
    if hasattr(x, "detach"):  # a torch tensor
        x = x.detach().cpu().double().numpy()
    return np.asarray(x, dtype=np.float64)


@dataclass(frozen=True)
class Axis:
    """One axis of the convention vocabulary: graphdeco's value and the alternatives found in real code."""

    name: str
    graphdeco: Any
    alternatives: tuple
    meaning: str


#: The convention vocabulary (docs/backends.md, "Conventions"): every axis `BackendInfo` can declare
#: besides the approximations above, in the order conform searches them (the most basic first).
AXES: tuple[Axis, ...] = (
    Axis("pixel_centre", "half", ("integer",), "pixel (i, j) sampled at (j + 0.5, i + 0.5), or at (j, i)"),
    Axis("opacity_activation", "sigmoid", ("raw",), "opacity = sigmoid(logit), or the logit clamped to [0, 1]"),
    Axis("scale_activation", "exp", ("raw",), "scales = exp(log_scales), or log_scales themselves"),
    Axis("quat_order", "wxyz", ("xyzw",), "quaternion component order"),
    Axis("eps2d", 0.3, (0.0, 0.1), "low-pass added to the 2D covariance (pixel^2)"),
    Axis("background", "weighted", ("added", "ignored"),
         "rgb + T_final * background, rgb + background, or no background"),
    Axis("sh_view_direction", "camera_to_mean", ("mean_to_camera", "world_origin", "detached"),
         "SH direction normalize(mean - camera centre), reversed, normalize(mean), or detached from the means "
         "(same forward, no d/dmeans through the colour)"),
    Axis("sort_key", "view_z", ("distance", "world_z", "index"),
         "compositing order: camera z, distance to the camera, world z, input order"),
    Axis("sh_basis", "graphdeco", ("no_condon_shortley",),
         "SH band signs: graphdeco's (Condon-Shortley phase), or every constant positive"),
    Axis("sh_degree", 3, (2, 1, 0, "ignored"),
         "highest SH band evaluated; 'ignored': every band given, whatever the sh_degree argument says"),
    Axis("colour_clamp", "min0", ("none", "0_1"), "colour = max(SH + 0.5, 0), unclamped, or clipped to [0, 1]"),
    Axis("jacobian_clamp", 1.3, ("none",), "EWA Jacobian taken at the point clamped to 1.3 x the half FoV, or not"),
    Axis("alpha_max", GRAPHDECO["alpha_max"], (0.999, 1.0), "alpha clamp"),
    Axis("alpha_min", GRAPHDECO["alpha_min"], (0.0,), "contributions below it are skipped"),
    Axis("near_plane", "camera", (0.2, 0.01), "culling plane: camera.near, graphdeco's fixed 0.2, or 0.01"),
    Axis("depth", "normalised", ("unnormalised", "distance"),
         "expected camera z / alpha, sum T a z, or the expected distance to the camera / alpha"),
    Axis("radius", GRAPHDECO["radius"], ("opacity",),
         "footprint cutoff: 3 sigma, or where alpha falls below alpha_min ('none' declares the same)"),
    Axis("transmittance_min", GRAPHDECO["transmittance_min"], (0.0,), "early termination threshold (0: none)"),
)
AXIS = {a.name: a for a in AXES}
#: Every declarable convention (the approximations and the vocabulary) -> graphdeco's value.
CONVENTIONS = {**GRAPHDECO, **{a.name: a.graphdeco for a in AXES}}


class RasterFn(Protocol):
    """A backend function: the signature of this module's docstring (`Backend.__call__`'s)."""

    def __call__(self, means: torch.Tensor, log_scales: torch.Tensor, quats: torch.Tensor,
                 opacity_logits: torch.Tensor, sh: torch.Tensor, camera: Camera, *, sh_degree: int | None = None,
                 background: tuple[float, float, float] | None = None,
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]: ...


@dataclass(frozen=True)
class BackendInfo:
    """Metadata of one rasterizer.

    name, version: how reports name it. devices: subset of ("cpu", "cuda").
    gradients: differentiable by torch autograd. slow_gradients: gradients exist but
    are expensive (finite differences): compare/conform use them only on small probes.
    outputs: which of rgb, alpha, depth are real (others are returned as zeros).
    dtype: "float32" or "float64" (a float64 backend casts its float32 inputs).
    Declared approximations (None = graphdeco's value, see GRAPHDECO):
      alpha_min: contributions below it are skipped (0 = none skipped);
      alpha_max: alpha clamp (1 = no clamp); transmittance_min: early termination
      threshold (0 = none); eps2d: low-pass added to the 2D covariance (pixel^2);
      radius: "3sigma", "opacity", or "none" (dense: no cutoff); tile_size: 0 = no tiles;
      antialiased: Mip-Splatting opacity compensation.
    Declared conventions (None = graphdeco's; the values each takes: `AXES`, docs/backends.md):
      pixel_centre, opacity_activation, scale_activation, quat_order, background,
      sh_view_direction, sort_key, sh_basis, sh_degree, colour_clamp, jacobian_clamp,
      near_plane, depth (and eps2d, alpha_max, alpha_min above).
    exact: True for a backend that renders the exact Gaussian mixture (no skip, no
      clamp, no cutoff, no early stop): its errors are compared in "exact" mode.
    """

    name: str
    version: str = "unknown"
    devices: tuple[str, ...] = ("cpu",)
    gradients: bool = True
    slow_gradients: bool = False
    outputs: tuple[str, ...] = OUTPUTS
    dtype: str = "float32"
    alpha_min: float | None = None
    alpha_max: float | None = None
    transmittance_min: float | None = None
    eps2d: float | None = None
    radius: str | None = None
    tile_size: int | None = None
    antialiased: bool | None = None
    pixel_centre: str | None = None
    opacity_activation: str | None = None
    scale_activation: str | None = None
    quat_order: str | None = None
    background: str | None = None
    sh_view_direction: str | None = None
    sort_key: str | None = None
    sh_basis: str | None = None
    sh_degree: int | str | None = None
    colour_clamp: str | None = None
    jacobian_clamp: float | str | None = None
    near_plane: float | str | None = None
    depth: str | None = None
    exact: bool = False
    description: str = ""
    declared: tuple[str, ...] = field(default=(), repr=False)

    def __post_init__(self) -> None:
        for axis in AXES:
            if axis.name in GRAPHDECO:  # numeric approximations: any value may be declared
                continue
            value = getattr(self, axis.name)
            if value is not None and value != axis.graphdeco and value not in axis.alternatives:
                raise ValueError(f"BackendInfo.{axis.name}: {value!r} is not in the convention vocabulary "
                                 f"(one of {[axis.graphdeco, *axis.alternatives]}; docs/backends.md)")
        given = tuple(k for k in CONVENTIONS if getattr(self, k) is not None)
        object.__setattr__(self, "declared", given)

    def convention(self, key: str):
        """The value of a convention or approximation this backend follows (declared, else graphdeco's)."""
        value = getattr(self, key)
        return CONVENTIONS[key] if value is None else value

    def reference_options(self) -> dict:
        """The conventions mapping of `reference_render` (approximations and vocabulary axes) that
        reproduces this backend."""
        radius = self.convention("radius")
        if radius == "none":
            # No cutoff renders as the "opacity" rule: it cuts exactly where o·exp(-sigma) falls
            # below alpha_min, where the alpha_min skip drops the contribution anyway.
            radius = "opacity"
        return {"alpha_min": self.convention("alpha_min"), "alpha_max": self.convention("alpha_max"),
                "transmittance_min": self.convention("transmittance_min"), "eps2d": self.convention("eps2d"),
                "radius": radius, "antialiased": self.convention("antialiased"),
                **{a.name: self.convention(a.name) for a in AXES if a.name not in GRAPHDECO}}


@dataclass(frozen=True)
class Backend:
    """A rasterizer: ``fn`` with the signature in this module's docstring, and its ``info``."""

    fn: RasterFn
    info: BackendInfo

    @property
    def name(self) -> str:
        return self.info.name

    def __call__(
        self,
        means: torch.Tensor,           # [N, 3] float32, world positions
        log_scales: torch.Tensor,      # [N, 3] float32
        quats: torch.Tensor,           # [N, 4] float32 (w, x, y, z), not necessarily unit
        opacity_logits: torch.Tensor,  # [N] float32
        sh: torch.Tensor,              # [N, K, 3] float32, K = (d + 1)^2
        camera: Camera,                # width W, height H
        *,
        sh_degree: int | None = None,  # SH bands to evaluate (default: all in ``sh``)
        background: tuple[float, float, float] | None = None,  # RGB in [0, 1] (default black)
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # rgb [H, W, 3], alpha [H, W], depth [H, W]
        """Render one view with ``fn`` (the signature of this module's docstring).

        Returns:
            rgb [H, W, 3], alpha [H, W], depth [H, W] torch tensors of ``info.dtype`` (float32, or
            float64 for a float64 backend such as the oracle); depth is the expected camera z, 0
            where alpha is 0. Differentiable by torch autograd when ``info.gradients``; an output
            not in ``info.outputs`` is zeros.
        """
        return self.fn(means, log_scales, quats, opacity_logits, sh, camera, sh_degree=sh_degree,
                       background=background)
