"""The per-Gaussian record layout of compositing, named once.

The compositing loops, the per-block lists and the work counts read each Gaussian's
screen-space attributes as one packed record (one packet gather instead of a scalar
gather per field). `GeoRecord` and `ColourRecord` fix the field order; code reads a
loaded record by field name (``geo.depth``), never by position. The per-pair gradient
buffers of the backward pass (`reduction.PAIR_GROUPS`) follow the same order, through
`GEO_GRAD_KEYS` and `COLOUR_GRAD_KEYS`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from splatbench.raster.device import dr


class GeoRecord(NamedTuple):
    """A Gaussian's geometry record, in packed order (each field a Float [N] when loaded)."""

    u: object          # screen-space mean x (pixels)
    v: object          # screen-space mean y (pixels)
    conic_a: object    # inverse 2D covariance (A, B, C) = (xx, xy, yy)
    conic_b: object
    conic_c: object
    opacity: object
    depth: object      # camera z
    cutoff_sq: object  # R^2 in Mahalanobis units (detached)


class ColourRecord(NamedTuple):
    """A Gaussian's colour record; packed with one padding slot (`COL`)."""

    r: object
    g: object
    b: object


GEO = len(GeoRecord._fields)  # 8 floats per geometry record
COL = 4  # colour record: r, g, b, padding (packet loads need a power of two)
#: The per-pair gradient term of each geometry field (None: the cutoff gets no gradient).
GEO_GRAD_KEYS = GeoRecord("mx", "my", "ca", "cb", "cc", "o", "z", None)
#: The per-pair gradient term of each colour field.
COLOUR_GRAD_KEYS = ColourRecord("r", "g", "b")


@dataclass(frozen=True)
class Splats:
    """Per-Gaussian screen-space attributes read by the compositing loop."""

    means2d: object    # Array2f [N]
    conics: object     # Array3f [N]
    opacities: object  # Float [N]
    colors: object     # Array3f [N]
    depths: object     # Float [N]
    cutoff_sq: object  # Float [N], detached


class Records(NamedTuple):
    """Per-Gaussian data packed for packet loads: ``geo`` [N * GEO], ``col`` [N * COL]
    (record g at g * GEO .. g * GEO + GEO - 1, fields in `GeoRecord` order)."""

    geo: object
    col: object


def pack_records(m, s: Splats) -> Records:
    """Interleave the splat attributes into `Records` (differentiable scatters)."""
    n = dr.width(s.opacities)
    idx = dr.arange(m.UInt32, n)
    geo = dr.zeros(m.Float, GEO * n)
    col = dr.zeros(m.Float, COL * n)
    fields = GeoRecord(u=s.means2d.x, v=s.means2d.y, conic_a=s.conics.x, conic_b=s.conics.y, conic_c=s.conics.z,
                       opacity=s.opacities, depth=s.depths, cutoff_sq=s.cutoff_sq)
    for k, value in enumerate(fields):
        dr.scatter(geo, value, idx * GEO + k, mode=dr.ReduceMode.Permute)
    for k, value in enumerate(ColourRecord(s.colors.x, s.colors.y, s.colors.z)):
        dr.scatter(col, value, idx * COL + k, mode=dr.ReduceMode.Permute)
    return Records(geo, col)


def load_records(m, rec: Records, gid, active=True) -> tuple[GeoRecord, ColourRecord]:
    """The geometry and colour records of Gaussians ``gid`` (one packet gather each)."""
    n = dr.width(gid)
    geo = dr.gather(m.ArrayXf, rec.geo, gid, active, shape=(GEO, n))
    col = dr.gather(m.ArrayXf, rec.col, gid, active, shape=(COL, n))
    return GeoRecord(*(geo[k] for k in range(GEO))), ColourRecord(*(col[k] for k in range(len(ColourRecord._fields))))
