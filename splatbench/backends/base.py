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
from typing import Any, Callable, Protocol

from splatbench.raster.options import RasterOptions

# graphdeco-inria 3DGS's approximations, the defaults a backend with no metadata follows: the
# rasterizer's own defaults (`RasterOptions`, whose field comments give graphdeco's sources).
GRAPHDECO = {name: getattr(RasterOptions(), name) for name in ("alpha_min", "alpha_max", "transmittance_min",
                                                               "eps2d", "radius", "tile_size", "antialiased")}
OUTPUTS = ("rgb", "alpha", "depth")


class RasterFn(Protocol):
    def __call__(self, means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree: int | None = None,
                 background=None) -> tuple[Any, Any, Any]: ...


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
    exact: bool = False
    description: str = ""
    declared: tuple[str, ...] = field(default=(), repr=False)

    def __post_init__(self) -> None:
        given = tuple(k for k in GRAPHDECO if getattr(self, k) is not None)
        object.__setattr__(self, "declared", given)

    def convention(self, key: str):
        """The value of an approximation this backend follows (declared, else graphdeco's)."""
        value = getattr(self, key)
        return GRAPHDECO[key] if value is None else value

    def reference_options(self) -> dict:
        """Keyword arguments of `reference.render(mode="matched")` that reproduce these conventions."""
        radius = self.convention("radius")
        if radius == "none":
            # No cutoff renders as the "opacity" rule: it cuts exactly where o·exp(-sigma) falls
            # below alpha_min, where the alpha_min skip drops the contribution anyway.
            radius = "opacity"
        return {"alpha_min": self.convention("alpha_min"), "alpha_max": self.convention("alpha_max"),
                "transmittance_min": self.convention("transmittance_min"), "eps2d": self.convention("eps2d"),
                "radius": radius, "antialiased": self.convention("antialiased")}


@dataclass(frozen=True)
class Backend:
    """A rasterizer: ``fn`` with the signature in this module's docstring, and its ``info``."""

    fn: Callable[..., tuple[Any, Any, Any]]
    info: BackendInfo

    @property
    def name(self) -> str:
        return self.info.name

    def __call__(self, means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        return self.fn(means, log_scales, quats, opacity_logits, sh, camera, sh_degree=sh_degree,
                       background=background)
