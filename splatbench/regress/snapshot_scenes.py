"""The scene set a snapshot is taken on: fixed, deterministic, versioned (snapshot scenes, one of
the five kinds of "scene": docs/architecture.md).

``full`` (the default): every scene of conform's probes (tiny scenes, each isolating one
convention), two synthetic workloads seen from random camera poses (so world-space mistakes
show), the bundled garden SfM view at 1/8 resolution, and a real trained model (the bundled
PlayCanvas guitar, 64x64, framed 20 degrees from above). ``small``: the probe scenes and the
synthetic workloads only, for dense toy backends that cannot render ~100k Gaussians. ``parity``:
three of the rasterizer's parity scenes (`splatbench.workloads.parity_scene` 0, 7, 13: standard,
needles and tiny Gaussians, SH degrees 0, 3 and 1, black and coloured backgrounds, some Gaussians
beyond the image edges, random poses), the scenes of splatbench's own snapshot (tests/golden). A
snapshot may hold only some scenes of its set, by name (`scene_set`'s ``only``).

`SCENE_SET_VERSION` is stored in every snapshot and checked: any change to a scene (its
Gaussians, camera, size, cotangent seed) or to the list must bump it, so that a snapshot is
never compared with other scenes (adding a set changes no scene of the others: their snapshots hold).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from splatbench.cameras import Camera
from splatbench.errors import InputError
from splatbench.render_inputs import RenderInput

#: Bump on any change to a scene or to the list (the snapshot records it; check refuses another).
SCENE_SET_VERSION = 1
SCENE_SETS = ("full", "small", "parity")
#: The parity scenes of the ``parity`` set (`splatbench.workloads.parity_scene` seeds).
PARITY_SEEDS = (0, 7, 13)


@dataclass(frozen=True, kw_only=True)
class Scene(RenderInput):
    """One scene: a `RenderInput` (the five parameter groups as float32 values in float64 arrays,
    the camera, background, SH degree) with its ``name`` (keyword); ``seed``: of its cotangents."""

    name: str

    @property
    def seed(self) -> int:
        return zlib.crc32(self.name.encode())


def _f32(x) -> np.ndarray:
    return np.asarray(np.asarray(x, dtype=np.float32), dtype=np.float64)


def _from_gaussians(name: str, g, camera: Camera) -> Scene:
    return Scene(_f32(g.means), _f32(g.log_scales), _f32(g.quats), _f32(g.opacity_logits), _f32(g.sh), camera,
                 name=name)


def _probe_scenes() -> list[Scene]:
    from splatbench.conform.probes import PROBES

    out, seen = [], set()
    for p in PROBES:
        key = p.build.__name__
        if key in seen:
            continue
        seen.add(key)
        s = p.build()
        out.append(Scene(_f32(s.means), _f32(s.log_scales), _f32(s.quats), _f32(s.opacity_logits), _f32(s.sh),
                         s.camera, s.background, s.sh_degree, name=f"probe-{key}"))
    return out


def _synthetic_scenes() -> list[Scene]:
    from splatbench.workloads import synthetic

    return [_from_gaussians(w.name, w.gaussians, w.camera)
            for w in (synthetic(300, 64, 64, seed=1, random_pose=True), synthetic(300, 48, 64, seed=2, random_pose=True))]


GARDEN = "garden-view0-x0.125"
MODEL = "guitar-view0-64x64"


def _garden() -> Scene:
    from splatbench.workloads import GARDEN_SFM, load_npz

    w = load_npz(GARDEN_SFM, view=0)
    return _from_gaussians(GARDEN, w.gaussians, w.camera.scaled(0.125))


def _real_model() -> Scene:
    from splatbench.workloads import model_workload

    w = model_workload("guitar", 0, 3, 64, 64)
    return _from_gaussians(MODEL, w.gaussians, w.camera)


def _parity_scenes() -> list[Scene]:
    from splatbench.workloads import parity_scene

    out = []
    for seed in PARITY_SEEDS:
        w, background = parity_scene(seed)
        g = w.gaussians
        out.append(Scene(_f32(g.means), _f32(g.log_scales), _f32(g.quats), _f32(g.opacity_logits), _f32(g.sh),
                         w.camera, tuple(float(c) for c in background), name=w.name))
    return out


def scene_set(name: str = "full", only: tuple[str, ...] | list[str] | None = None) -> list[Scene]:
    """The scenes of set ``name`` (`SCENE_SETS`), in a fixed order (built fresh each call).
    ``only``: just the scenes of these names (still in the set's order; the two large scenes are
    loaded only when named); a name not in the set is one `InputError` line listing the set's names."""
    if name not in SCENE_SETS:
        raise InputError(f"--scenes: expected one of {list(SCENE_SETS)}, got {name!r}")
    scenes = _parity_scenes() if name == "parity" else _probe_scenes() + _synthetic_scenes()
    large = {GARDEN: _garden, MODEL: _real_model} if name == "full" else {}
    if only is None:
        return scenes + [build() for build in large.values()]
    known = [s.name for s in scenes] + list(large)
    unknown = [n for n in only if n not in known]
    if unknown:
        raise InputError(f"--scene: {unknown[0]!r} is not in scene set {name!r} (its scenes: {', '.join(known)})")
    return [s for s in scenes if s.name in only] + [build() for n, build in large.items() if n in only]
