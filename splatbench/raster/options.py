"""Rasterizer options: one typed record, validated at the boundary."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from splatbench.guards import check_keys, dataclass_from_mapping
from splatbench.devices import check_device
from splatbench.errors import InputError

RADIUS_RULES = ("3sigma", "opacity")
#: Largest side of a compositing lane's pixel block: a lane carries the state of its
#: block's pixels through the loops, and traces their code once each.
MAX_PIXEL_BLOCK = 8
#: The side of a lane's pixel block when none is given (the layout measured fastest,
#: docs/benchmarks.md), or the tile's side where the tile is smaller.
DEFAULT_PIXEL_BLOCK = 4
#: Most blocks along a tile's side: binning's per-pair block mask holds (side)^2 bits.
MAX_BLOCKS_PER_SIDE = 32


@dataclass(frozen=True)
class RasterOptions:
    """Options of the tile rasterizer; defaults are graphdeco-inria 3DGS's.

    See docs/conventions.md for the exact meaning of each threshold. ``pixel_block`` left
    out (None) is resolved on construction to the value that runs, so ``to_dict`` and every
    record hold that int; one given is never changed (larger than ``tile_size``: an error).
    """

    tile_size: int = 16            # pixels per tile side; an acceleration only, never changes the image
    pixel_block: int | None = None  # pixels per side of a compositing lane's block, at most tile_size; None:
                                    # DEFAULT_PIXEL_BLOCK (4), or tile_size where smaller, stored as that int;
                                    # an acceleration only: the image is the same (docs/benchmarks.md)
    alpha_min: float = 1.0 / 255.0  # contributions with alpha below this are skipped
    alpha_max: float = 0.99        # alpha is clamped to this (keeps 1 - alpha invertible)
    transmittance_min: float = 1e-4  # a pixel stops before transmittance would drop below this
    eps2d: float = 0.3             # added to the 2D covariance's diagonal (pixel^2)
    near: float | None = None      # near plane; None uses the camera's
    far: float | None = None       # far plane; None uses the camera's
    radius: str = "3sigma"         # "3sigma", or "opacity": extent where o*G falls below alpha_min
    antialiased: bool = False      # Mip-Splatting opacity compensation sqrt(det S2D / det(S2D + eps2d I))
    device: str = "auto"           # "cpu" (LLVM), "cuda", or "auto" (CUDA when available)

    def __post_init__(self) -> None:
        ts = self.tile_size
        if not isinstance(ts, int) or isinstance(ts, bool) or ts < 1 or ts > 64 or ts & (ts - 1):
            raise InputError(f"tile_size: expected a power of two in [1, 64], got {ts!r}")
        pb = self.pixel_block
        if pb is None:  # the default, as the value that runs (so a record says what ran)
            pb = min(DEFAULT_PIXEL_BLOCK, ts)
            object.__setattr__(self, "pixel_block", pb)
        if not isinstance(pb, int) or isinstance(pb, bool) or pb < 1 or pb > MAX_PIXEL_BLOCK or pb & (pb - 1):
            raise InputError(f"pixel_block: expected a power of two in [1, {MAX_PIXEL_BLOCK}], got {pb!r}")
        if pb > ts:  # a lane's block lies inside one tile
            raise InputError(f"pixel_block: at most tile_size ({ts}), got {pb}; use pixel_block <= {ts}, or leave "
                             f"it out (the default follows a smaller tile)")
        if ts // pb > MAX_BLOCKS_PER_SIDE:
            raise InputError(f"pixel_block: at most {MAX_BLOCKS_PER_SIDE} blocks per tile side, got tile_size "
                             f"{ts} / pixel_block {pb}; use pixel_block >= {ts // MAX_BLOCKS_PER_SIDE}")
        if not (0.0 < float(self.alpha_max) <= 1.0 - 1e-6):
            raise InputError(f"alpha_max: expected a value in (0, 1), got {self.alpha_max!r}")
        if not (0.0 < float(self.alpha_min) < float(self.alpha_max)):
            raise InputError(f"alpha_min: expected a value in (0, alpha_max), got {self.alpha_min!r}")
        if not (0.0 <= float(self.transmittance_min) < 1.0):
            raise InputError(f"transmittance_min: expected a value in [0, 1), got {self.transmittance_min!r}")
        if not (math.isfinite(float(self.eps2d)) and float(self.eps2d) >= 0.0):
            raise InputError(f"eps2d: expected a finite value >= 0, got {self.eps2d!r}")
        if self.near is not None and not (math.isfinite(self.near) and self.near > 0):
            raise InputError(f"near: expected a finite value > 0, got {self.near!r}")
        if self.far is not None and not (self.far > 0):
            raise InputError(f"far: expected a value > 0, got {self.far!r}")
        if self.near is not None and self.far is not None and not self.near < self.far:
            raise InputError(f"near: expected a value below far ({self.far!r}), got {self.near!r}")
        if self.radius not in RADIUS_RULES:
            raise InputError(f"radius: expected one of {RADIUS_RULES}, got {self.radius!r}")
        check_device(self.device)

    @classmethod
    def from_kwargs(cls, base: RasterOptions | None = None, **kwargs) -> RasterOptions:
        """Build options from keyword arguments, naming any unknown one; ``base``'s values
        (all given, its resolved ``pixel_block`` too) for the rest, else the defaults."""
        check_keys(kwargs, (f.name for f in fields(cls)))
        return cls(**kwargs) if base is None else replace(base, **kwargs)

    @classmethod
    def from_dict(cls, table: Mapping[str, Any], *, base: RasterOptions | None = None, prefix: str = "",
                  source: str = "") -> RasterOptions:
        """Options from a table of field values as a user writes them (a TOML table, ``--set
        raster.KEY=VALUE``, an experiment's config), ``base``'s (default: the defaults) for the
        rest. Every key names a field, every value has its field's type (an int where a float is
        expected is that float), then the ranges above; each mistake is one `InputError` line
        naming ``PREFIXKEY`` (``raster.alpha_min``) as the user wrote it, an unknown key with the
        field it is close to or the list of fields (`splatbench.guards.dataclass_from_mapping`)."""
        return dataclass_from_mapping(cls, table, base=None if base is None else asdict(base), prefix=prefix,
                                      source=source)

    def to_dict(self) -> dict[str, Any]:
        """Every field as a plain TOML value; ``near`` / ``far`` left out while None (the
        camera's: TOML has no null), so ``from_dict(o.to_dict()) == o``."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}
