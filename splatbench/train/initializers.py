"""Initial Gaussians for training, by name (`TrainConfig.init`).

`INITIALIZERS` maps a name to a function ``(dataset, settings) -> Gaussians`` (or an
`Initialization`, to report how the points were made); a new method plugs in with
`register_init`::

    @register_init("mast3r")
    def mast3r(dataset, settings): ...

Built in (every one seeded by `splatbench.init.from_points`: 3-NN scales, opacity
``settings.opacity``, DC colour from the point colour):

* ``sfm`` -- pycolmap SfM on the **training** views only (SIFT, exhaustive matching,
  incremental mapping; `splatbench.sfm.run_sfm`), aligned to the dataset's frame by a
  similarity on the camera centres, starting from its sparse points and their colours
  as 3DGS does on a real capture. The model is cached by content in ``$SPLATBENCH_CACHE/sfm/<hash>``
  (`splatbench.sfm.cached_sfm`): the same training images, cameras and seed reuse it.
  SfM's seed is ``settings.sfm_seed`` (0: one model per dataset, as a capture has one
  COLMAP model; the run's seed varies training only). A dataset SfM cannot register
  is one `InputError` line.
* ``surface`` -- the dataset's own point cloud (`Dataset.points`): samples of the true
  surfaces for a scene rendered by ``splatbench scenes``, ``points3D`` for a COLMAP
  folder, ``ply_file_path`` for the Blender layout.
* ``random`` -- ``settings.random_points`` points uniform in the axis-aligned box of
  the training camera centres (3DGS's Blender default: 100k points in a cube), with
  uniform random colours.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

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
    sfm_seed: int = 0     # init="sfm": pycolmap's seed
    say: Callable[[str], None] | None = None  # progress lines as they happen (init="sfm": starting, done)


@dataclass(frozen=True)
class Initialization:
    """What `initialize` returns: the Gaussians and how they were made.

    ``summary``: JSON-ready numbers (``method``, ``points``; for SfM ``registered``,
    ``total``, ``center_rmse_rel``, ``cached``); ``note``: one line for the train log
    (None when there is nothing to say)."""

    gaussians: Gaussians
    summary: dict[str, Any] = field(default_factory=dict)
    note: str | None = None


Initializer = Callable[..., "Gaussians | Initialization"]  # (dataset, settings: InitSettings) -> ...
INITIALIZERS: dict[str, Initializer] = {}


def register_init(name: str) -> Callable[[Initializer], Initializer]:
    """Decorator: make ``fn(dataset, settings) -> Gaussians`` available as ``init=name``."""

    def deco(fn: Initializer) -> Initializer:
        INITIALIZERS[name] = fn
        return fn

    return deco


def initialize(name: str, dataset, settings: InitSettings) -> Initialization:
    """The initial Gaussians of method ``name`` and their summary (`InputError` if unknown)."""
    if name not in INITIALIZERS:
        raise InputError(f"init: unknown initialisation {name!r} (expected one of: {', '.join(INITIALIZERS)})")
    made = INITIALIZERS[name](dataset, settings)
    init = made if isinstance(made, Initialization) else Initialization(made)
    return Initialization(init.gaussians, {"method": name, "points": len(init.gaussians), **init.summary},
                          init.note)


@register_init("sfm")
def sfm(dataset, settings: InitSettings) -> Initialization:
    """pycolmap SfM on the training views (cached by content), aligned to the dataset's frame."""
    from splatbench.sfm import cached_sfm

    root = str(dataset.root)
    say = settings.say or (lambda line: None)
    try:
        run, cached = cached_sfm(dataset, seed=settings.sfm_seed, say=say)
    except InputError as exc:
        raise InputError(f"init: 'sfm' failed on {root!r}: {exc} (use init=surface or init=random)") from None
    if len(run.xyz) < 2:
        raise InputError(f"init: 'sfm' on {root!r} triangulated {len(run.xyz)} point(s), need 2 (use init=surface "
                         f"or init=random)")
    gaussians = from_points(run.xyz, run.rgb, sh_degree=settings.sh_degree, opacity=settings.opacity)
    summary = {"registered": run.registered, "total": run.total, "center_rmse_rel": run.center_rmse_rel,
               "sfm_seconds": round(run.seconds, 3), "cached": cached, "model": str(run.model_path)}
    note = (f"SfM: {len(run.xyz)} points, {run.registered}/{run.total} training views registered (camera-centre "
            f"RMSE {run.center_rmse_rel:.2%} of the rig radius; {'cached' if cached else 'ran'} in "
            f"{run.model_path.parent})")
    say(note)  # as soon as SfM is done, not only among the run's notes at the end
    return Initialization(gaussians, summary, note)


@register_init("surface")
def surface(dataset, settings: InitSettings) -> Gaussians | Initialization:
    """The dataset's own points (true-surface samples of a rendered scene; a COLMAP folder's points3D).

    A capture without a point cloud (a NeRF / instant-ngp transforms.json) starts from random
    points instead, as graphdeco does, said in a note (never silently)."""
    points = dataset.points
    if points is not None and len(points) >= 2:
        return from_points(points.xyz, points.rgb, sh_degree=settings.sh_degree, opacity=settings.opacity)
    have = "no point cloud" if points is None else f"{len(points)} point(s)"
    made = random(dataset, settings)
    note = (f"init: 'surface' needs the dataset's points, but {str(dataset.root)!r} has {have}: "
            f"started from {len(made)} random points in the camera bounds, as graphdeco does (set init=random "
            f"to ask for that, or init=sfm to triangulate points)")
    (settings.say or (lambda line: None))(note)
    return Initialization(made, {"method": "random", "asked": "surface"}, note)


@register_init("random")
def random(dataset, settings: InitSettings) -> Gaussians:
    """Uniform points in the bounding box of the training camera centres, random colours."""
    centres = np.stack([c.center for c in dataset.train.cameras])
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    rng = np.random.default_rng(settings.seed)
    xyz = lo + (hi - lo) * rng.random((settings.random_points, 3))
    rgb = rng.random((settings.random_points, 3))
    return from_points(xyz, rgb, sh_degree=settings.sh_degree, opacity=settings.opacity)


__all__ = ["INITIALIZERS", "InitSettings", "Initialization", "initialize", "register_init"]
