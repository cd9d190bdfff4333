"""The sweeps: scenes that vary one factor of the splatting approximation at a time.

Each ``*_cases`` builder returns `Case` objects (Gaussians + camera); `run_sweeps`
renders them with both renderers (`renderers.compare`) into `SweepRow` lines.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, fields

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.gaussians import Gaussians
from splatbench.render_inputs import logit, point_at, sh_dc, to_world, world_sigma
from splatbench.workloads import random_unit_quats
from splatbench.validate.mitsuba.renderers import OPTION_SETS, SWEEP_OPACITY, ComparisonMetrics, compare


@dataclass(frozen=True)
class Case:
    """One scene of a sweep: the factor, its value, and what to render."""

    sweep: str              # "size", "anisotropy", "angle", "overlap" or "sh"
    parameter: str          # what ``value`` measures, e.g. "sigma_px"
    value: float
    gaussians: Gaussians
    camera: Camera
    options: str = "matched"  # key of OPTION_SETS used for the rasterizer


@dataclass(frozen=True)
class SweepRow:
    """One line of the report table: the case, then its `ComparisonMetrics` (`columns`)."""

    sweep: str
    parameter: str
    value: float
    options: str
    gaussians: int
    metrics: ComparisonMetrics

    @staticmethod
    def column_names() -> list[str]:
        """The CSV and markdown columns, in order: the case's fields, then the metrics'."""
        return [f.name for f in fields(SweepRow) if f.name != "metrics"] + [f.name for f in fields(ComparisonMetrics)]

    def columns(self) -> dict[str, object]:
        """{column name: value} in `column_names` order."""
        case = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "metrics"}
        return {**case, **asdict(self.metrics)}


_DISTANCE = 400.0  # camera distance to the target (world units; see "Scale" in docs/validation.md)


def _camera(width: int, fov_x_deg: float = 50.0) -> Camera:
    return Camera.look_at(eye=[0.0, 0.0, -_DISTANCE], target=[0.0, 0.0, 0.0], up=[0.0, -1.0, 0.0],
                          width=width, height=width, fov_x_deg=fov_x_deg)


def _colours(n: int, rng: np.random.Generator) -> np.ndarray:
    """[n, 3] saturated colours in [0.15, 0.95] (degree-0 SH values, not clipped)."""
    base = rng.uniform(0.15, 0.95, size=(n, 3))
    base[np.arange(n), rng.integers(0, 3, n)] = 0.95  # one strong channel each
    return base


def _gaussians(means, sigmas, colours, *, quats=None, sh_rest=None) -> Gaussians:
    """Gaussians with given means [N, 3], per-axis sigmas [N, 3], degree-0 colours [N, 3]."""
    means = np.asarray(means, np.float64)
    n = len(means)
    sh = sh_dc(colours) if sh_rest is None else np.concatenate([sh_dc(colours), sh_rest], axis=1)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) if quats is None else quats
    return Gaussians(means, np.log(np.asarray(sigmas, np.float64)), q, np.full(n, logit(SWEEP_OPACITY)), sh)


def _grid(camera: Camera, rng: np.random.Generator, count: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``count`` x ``count`` world points at pixel positions spaced W/count, at distinct camera
    depths near the target, in no particular screen order: (means [count², 3], depths [count²])."""
    w = camera.width
    offsets = (np.arange(count) - (count - 1) / 2) * (w / count)
    uu, vv = np.meshgrid(camera.cx + offsets, camera.cy + offsets)
    depths = _DISTANCE * (1.0 + np.linspace(-0.075, 0.075, count * count))
    rng.shuffle(depths)  # depth-separated, in no particular screen order
    means = point_at(camera, uu.ravel(), vv.ravel(), depths)
    return means, depths


def size_cases(width: int = 128, sizes_px: Sequence[float] | None = None, *, seed: int = 0,
               options: str = "matched") -> list[Case]:
    """Isotropic Gaussians on a 3x3 grid (field angles up to ~24 degrees), screen sigma in pixels.

    ``sizes_px`` default ``width/128 * (0.5, 1, 2, 4, 6)``: 6 px at 128 is the largest
    that keeps the 3-sigma footprints (spacing W/3) apart.
    """
    cam = _camera(width)
    sizes = [width / 128 * s for s in (0.5, 1.0, 2.0, 4.0, 6.0)] if sizes_px is None else list(sizes_px)
    out = []
    for s in sizes:
        rng = np.random.default_rng(seed)
        means, depths = _grid(cam, rng)
        sig = world_sigma(cam, s, depths)
        out.append(Case("size", "sigma_px", float(s), _gaussians(means, np.repeat(sig[:, None], 3, 1),
                                                                 _colours(len(means), rng)), cam, options))
    return out


def anisotropy_cases(width: int = 128, ratios: Sequence[float] = (1, 2, 4, 8, 16, 32), *, seed: int = 0) -> list[Case]:
    """Flat Gaussians (sigma, sigma, sigma/ratio), random orientations, largest axis 4 px at 128."""
    cam = _camera(width)
    out = []
    for ratio in ratios:
        rng = np.random.default_rng(seed)
        means, depths = _grid(cam, rng)
        s = world_sigma(cam, width / 32, depths)
        sig = np.stack([s, s, s / ratio], axis=1)
        out.append(Case("anisotropy", "ratio", float(ratio),
                        _gaussians(means, sig, _colours(len(means), rng), quats=random_unit_quats(rng, len(means))), cam))
    return out


def angle_cases(width: int = 128, angles_deg: Sequence[float] = (0, 10, 20, 30, 40, 50), *, seed: int = 0) -> list[Case]:
    """One isotropic Gaussian at a field angle off the optical axis (120-degree camera).

    Its angular size is fixed (sigma = 0.04 x distance: 1.5 px at the image centre at
    128), so only the position in the field changes.
    """
    cam = _camera(width, fov_x_deg=120.0)
    out = []
    for angle in angles_deg:
        rng = np.random.default_rng(seed)
        t = math.radians(angle)
        direction = np.array([math.sin(t) / math.sqrt(2), math.sin(t) / math.sqrt(2), math.cos(t)])
        mean_cam = direction * _DISTANCE
        mean = to_world(cam, mean_cam)
        sig = 0.04 * _DISTANCE
        out.append(Case("angle", "field_angle_deg", float(angle),
                        _gaussians(mean[None], np.full((1, 3), sig), _colours(1, rng)), cam))
    return out


def overlap_cases(width: int = 128, gaps: Sequence[float] = (12, 6, 3, 1.5, 0.75, 0), *, seed: int = 0) -> list[Case]:
    """Four stacks of three Gaussians (sigma s, 1.5 s, 2 s in random order) at one screen position each.

    ``gap``: depth between consecutive centres of a stack, in units of s (s = 3 px on
    screen at 128). Every member keeps its screen position (lateral jitter up to 0.5 s)
    and its screen size whatever the gap, so only the depth overlap changes: at 12 s the
    3-sigma shells are apart in depth; at 0 the centres share a depth and only the
    sort's tie-break orders them.
    """
    cam = _camera(width)
    out = []
    for gap in gaps:
        rng = np.random.default_rng(seed)
        s = world_sigma(cam, (width / 128) * 3.0, _DISTANCE)  # world sigma of 3 px (at 128) at the target depth
        means, sigs = [], []
        for u, v in ((0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7)):
            for k, factor in enumerate(rng.permutation([1.0, 1.5, 2.0])):
                jitter = rng.uniform(-0.5, 0.5, 2) * s * cam.fx / _DISTANCE  # pixels
                depth = _DISTANCE + (k - 1) * gap * s
                means.append(point_at(cam, u * width + jitter[0], v * width + jitter[1], depth))
                sigs.append(factor * s * depth / _DISTANCE)
        sigs_ = np.repeat(np.asarray(sigs)[:, None], 3, 1)
        out.append(Case("overlap", "gap_sigma", float(gap),
                        _gaussians(np.asarray(means), sigs_, _colours(len(means), rng)), cam))
    return out


def sh_cases(width: int = 128, degrees: Sequence[int] = (0, 1, 2, 3), *, seed: int = 0) -> list[Case]:
    """The 3x3 grid at 4 px (at 128) with SH of degree d: random bands above 0, N(0, 0.2)."""
    cam = _camera(width)
    out = []
    for degree in degrees:
        rng = np.random.default_rng(seed)
        means, depths = _grid(cam, rng)
        sig = world_sigma(cam, width / 32, depths)
        colours = _colours(len(means), rng)
        rest = rng.normal(0.0, 0.2, size=(len(means), 15, 3))[:, : (degree + 1) ** 2 - 1]
        out.append(Case("sh", "sh_degree", float(degree),
                        _gaussians(means, np.repeat(sig[:, None], 3, 1), colours,
                                   sh_rest=rest if degree else None), cam))
    return out


#: Every sweep: name -> case factory ``f(width) -> list[Case]``.
SWEEPS: dict[str, Callable[[int], list[Case]]] = {
    "size": lambda w: size_cases(w) + size_cases(w, options="3dgs"),
    "anisotropy": anisotropy_cases,
    "angle": angle_cases,
    "overlap": overlap_cases,
    "sh": sh_cases,
}


def run_case(case: Case) -> SweepRow:
    """Render one `Case` with both renderers and summarise it."""
    c = compare(case.gaussians, case.camera, OPTION_SETS[case.options])
    return SweepRow(case.sweep, case.parameter, case.value, case.options, len(case.gaussians), c.metrics)


def run_sweeps(width: int = 128, sweeps: Iterable[str] | None = None, *, progress: bool = False) -> list[SweepRow]:
    """Run the named sweeps (default all of `SWEEPS`) at ``width`` x ``width`` pixels."""
    names = list(SWEEPS) if sweeps is None else list(sweeps)
    for name in names:
        if name not in SWEEPS:
            raise InputError(f"sweep: expected one of {', '.join(SWEEPS)}, got {name!r}")
    if not (isinstance(width, int) and width >= 16):
        raise InputError(f"width: expected an int >= 16, got {width!r}")
    cases = [case for name in names for case in SWEEPS[name](width)]
    from tqdm import tqdm

    return [run_case(case) for case in tqdm(cases, desc="validate mitsuba", unit="case", disable=not progress,
                                            leave=False)]
