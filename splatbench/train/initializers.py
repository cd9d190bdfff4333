"""Initial Gaussians for training, by name (`TrainConfig.init`).

`INITIALIZERS` maps a name to a function ``(dataset, settings) -> Gaussians``; a new
method (for example SfM by pycolmap) plugs in with `register_init`::

    @register_init("colmap_sfm")
    def colmap_sfm(dataset, settings): ...

Built in:

* ``sfm`` -- the dataset's sparse points (COLMAP ``points3D`` / ``ply_file_path``),
  seeded by `splatbench.init.from_points` (3-NN scales, opacity ``settings.opacity``).
* ``surface`` -- the dataset's dense surface points, seeded the same way (today the
  datasets ship one point cloud, so ``sfm`` and ``surface`` read the same points).
* ``random`` -- ``settings.random_points`` points uniform in the axis-aligned box of
  the training camera centres (3DGS's Blender default: 100k points in a cube), with
  uniform random colours.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from splatbench.errors import InputError
from splatbench.gaussians import Gaussians
from splatbench.init import from_points


@dataclass(frozen=True)
class InitSettings:
    """What an initializer may use besides the dataset."""

    sh_degree: int        # SH degree of the Gaussians (bands above 0 start at zero)
    opacity: float        # initial opacity in (0, 1)
    random_points: int    # init="random": number of points
    seed: int             # init="random": numpy seed


Initializer = Callable[..., Gaussians]  # (dataset: Dataset, settings: InitSettings) -> Gaussians
INITIALIZERS: dict[str, Initializer] = {}


def register_init(name: str) -> Callable[[Initializer], Initializer]:
    """Decorator: make ``fn(dataset, settings) -> Gaussians`` available as ``init=name``."""

    def deco(fn: Initializer) -> Initializer:
        INITIALIZERS[name] = fn
        return fn

    return deco


def initialize(name: str, dataset, settings: InitSettings) -> Gaussians:
    """The initial Gaussians of method ``name`` (`InputError` if unknown)."""
    if name not in INITIALIZERS:
        raise InputError(f"init: unknown initialisation {name!r} (expected one of: {', '.join(INITIALIZERS)})")
    return INITIALIZERS[name](dataset, settings)


def _dataset_points(dataset, settings: InitSettings, method: str) -> Gaussians:
    points = dataset.points
    if points is None or len(points) < 2:
        have = "no point cloud" if points is None else f"{len(points)} point(s)"
        raise InputError(f"init: {method!r} needs the dataset's points, but {str(dataset.root)!r} has {have} "
                         f"(use init=random)")
    return from_points(points.xyz, points.rgb, sh_degree=settings.sh_degree, opacity=settings.opacity)


@register_init("sfm")
def sfm(dataset, settings: InitSettings) -> Gaussians:
    """The dataset's sparse (SfM) points."""
    return _dataset_points(dataset, settings, "sfm")


@register_init("surface")
def surface(dataset, settings: InitSettings) -> Gaussians:
    """The dataset's dense surface points."""
    return _dataset_points(dataset, settings, "surface")


@register_init("random")
def random(dataset, settings: InitSettings) -> Gaussians:
    """Uniform points in the bounding box of the training camera centres, random colours."""
    centres = np.stack([c.center for c in dataset.train.cameras])
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    rng = np.random.default_rng(settings.seed)
    xyz = lo + (hi - lo) * rng.random((settings.random_points, 3))
    rgb = rng.random((settings.random_points, 3))
    return from_points(xyz, rgb, sh_degree=settings.sh_degree, opacity=settings.opacity)


__all__ = ["INITIALIZERS", "InitSettings", "initialize", "register_init"]
