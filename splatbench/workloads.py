"""Rendering workloads: the standard synthetic scene, npz scenes, and the garden SfM view.

A workload is a set of Gaussians and one camera; benchmarks, the stress test and
the parity tests all draw their scenes from here. This module is also the one home of
workload naming: a `WorkloadSpec` (cheap to pass between processes) is what the
command line's ``--synthetic N WxH`` / ``--workload FILE.npz|garden`` (`parse_synthetic`,
`parse_workload`) and an experiment's scene names ``synthetic-N-S``, ``synthetic-N-WxH``,
``garden``, ``garden-vK`` (`parse_workload_name`, `workload_spec`) stand for.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from splatbench.cameras import Camera
from splatbench.checks import check_sh_degree, parse_size
from splatbench.errors import InputError
from splatbench.gaussians import SH_BASES_OF_DEGREE, Gaussians

GARDEN_SFM = Path(__file__).parent / "data" / "garden_sfm.npz"  # real SfM data; see data/NOTICE.md
WORKLOAD_KEYS = ("means", "log_scales", "quats", "opacity_logits", "sh", "viewmat", "K", "width", "height")
SFM_KEYS = ("means3d", "colors", "viewmats", "Ks", "width", "height")
GARDEN = "garden"  # `--workload garden` / scene "garden": the bundled SfM capture, view 0 (648x420)


@dataclass(frozen=True)
class Workload:
    """A named scene: ``gaussians`` (N Gaussians) seen by ``camera``."""

    name: str
    gaussians: Gaussians
    camera: Camera


def random_unit_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    """[n, 4] uniformly random rotations (w, x, y, z)."""
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def synthetic(n: int, width: int, height: int, seed: int = 0, *, sh_degree: int = 3,
              sigma_px: tuple[float, float] = (0.3, 6.0), anisotropy: float = 0.25,
              depth_range: tuple[float, float] = (2.0, 6.0), margin: float = 0.1) -> Workload:
    """The standard synthetic workload.

    Camera at the origin looking down +z, fx = fy = W, cx = W/2, cy = H/2. Means
    uniform in depth on ``depth_range`` and uniform over the image inset by
    ``margin`` on each side; 1-sigma screen size log-uniform on ``sigma_px`` pixels
    with ``anisotropy`` log-normal spread per axis; random unit quaternions;
    opacity logits N(0, 1); SH DC 0.5 N(0, 1), higher bands 0.05 N(0, 1).
    """
    if n < 0:
        raise InputError(f"n: expected a count >= 0, got {n}")
    k = SH_BASES_OF_DEGREE[check_sh_degree("sh_degree", sh_degree)]
    rng = np.random.default_rng(seed)
    f = float(width)
    z = rng.uniform(*depth_range, n)
    u = rng.uniform(margin * width, (1 - margin) * width, n)
    v = rng.uniform(margin * height, (1 - margin) * height, n)
    means = np.stack([(u - width / 2) * z / f, (v - height / 2) * z / f, z], axis=1)
    sigma = np.exp(rng.uniform(np.log(sigma_px[0]), np.log(sigma_px[1]), n))
    log_scales = np.log(sigma * z / f)[:, None] + anisotropy * rng.standard_normal((n, 3))
    sh = np.concatenate([0.5 * rng.standard_normal((n, 1, 3)), 0.05 * rng.standard_normal((n, k - 1, 3))], 1)
    gaussians = Gaussians(means, log_scales, random_unit_quats(rng, n), rng.standard_normal(n), sh)
    camera = Camera(width, height, f, f, width / 2, height / 2, np.eye(4))
    return Workload(f"synthetic-{n}-{width}x{height}-s{seed}", gaussians, camera)


def save_npz(workload: Workload, path: str | Path) -> None:
    """Write ``workload`` with the keys of `WORKLOAD_KEYS`."""
    g, c = workload.gaussians, workload.camera
    np.savez(path, means=g.means, log_scales=g.log_scales, quats=g.quats, opacity_logits=g.opacity_logits,
             sh=g.sh, viewmat=c.world_to_camera, K=c.K, width=c.width, height=c.height)


def load_npz(path: str | Path, *, view: int = 0) -> Workload:
    """Read a workload npz: either `WORKLOAD_KEYS`, or an SfM capture with `SFM_KEYS`
    (points seeded as 3DGS does, camera ``view``)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"workload: no such file {str(path)!r}")
    try:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as exc:  # noqa: BLE001 - any unreadable file gets one line
        raise InputError(f"workload: {path.name}: not a readable npz ({exc})") from None
    if all(k in arrays for k in SFM_KEYS):
        return _from_sfm(path.stem, arrays, view)
    missing = [k for k in WORKLOAD_KEYS if k not in arrays]
    if missing:
        raise InputError(f"workload: {path.name}: missing keys {missing}")
    K = np.asarray(arrays["K"], dtype=np.float64)
    if K.shape != (3, 3):
        raise InputError(f"workload: {path.name}: K: expected shape [3, 3], got {list(K.shape)}")
    gaussians = Gaussians(arrays["means"], arrays["log_scales"], arrays["quats"], arrays["opacity_logits"],
                          arrays["sh"])
    camera = Camera(int(arrays["width"]), int(arrays["height"]), K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                    np.asarray(arrays["viewmat"], dtype=np.float64))
    return Workload(path.stem, gaussians, camera)


def sfm_camera(arrays: dict, view: int) -> Camera:
    """Camera ``view`` of an SfM capture (viewmats [V, 4, 4] world-to-camera, Ks [V, 3, 3])."""
    count = len(arrays["viewmats"])
    if not 0 <= view < count:
        raise InputError(f"view: expected an index in [0, {count}), got {view}")
    K = np.asarray(arrays["Ks"][view], dtype=np.float64)
    return Camera(int(arrays["width"]), int(arrays["height"]), K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                  np.asarray(arrays["viewmats"][view], dtype=np.float64))


def _from_sfm(name: str, arrays: dict, view: int) -> Workload:
    from splatbench.init import from_points

    gaussians = from_points(arrays["means3d"], arrays["colors"])
    return Workload(f"{name}-view{view}", gaussians, sfm_camera(arrays, view))


# --------------------------------------------------------------------------- naming
@dataclass(frozen=True)
class WorkloadSpec:
    """A workload to build where it is used (cheap to pass between processes).

    ``kind`` "synthetic": `synthetic(n, width, height, seed)`;
    ``kind`` "npz": `load_npz(path, view=view)`.
    """

    kind: str
    n: int = 0           # synthetic: number of Gaussians
    width: int = 0       # synthetic: image width (pixels)
    height: int = 0      # synthetic: image height (pixels)
    seed: int = 0        # synthetic: random seed
    path: str = ""       # npz: absolute path of the file
    view: int = 0        # npz: camera index
    label: str = ""      # name in the results ("" = the workload's own name)

    def build(self) -> Workload:
        """The `Workload` (Gaussians and camera)."""
        if self.kind == "synthetic":
            return synthetic(self.n, self.width, self.height, self.seed)
        if self.kind == "npz":
            return load_npz(self.path, view=self.view)
        raise InputError(f"workload kind: expected 'synthetic' or 'npz', got {self.kind!r}")


def parse_synthetic(count: str, size: str, seed: int = 0) -> WorkloadSpec:
    """``--synthetic N WxH`` -> a synthetic `WorkloadSpec`."""
    try:
        n = int(count)
    except ValueError:
        raise InputError(f"--synthetic: expected a Gaussian count, got {count!r}") from None
    if n < 1:
        raise InputError(f"--synthetic: expected a Gaussian count >= 1, got {count!r}")
    width, height = parse_size(size, "--synthetic")
    return WorkloadSpec("synthetic", n=n, width=width, height=height, seed=seed)


def parse_workload(arg: str) -> WorkloadSpec:
    """``--workload FILE.npz|garden`` -> an npz `WorkloadSpec` (the file must exist)."""
    if arg.lower() == GARDEN:
        return WorkloadSpec("npz", path=str(GARDEN_SFM), view=0, label="garden-view0")
    path = Path(arg).expanduser()
    if not path.is_file():
        raise InputError(f"--workload: no such file {arg!r}")
    if path.suffix != ".npz":
        raise InputError(f"--workload: expected a .npz file or 'garden', got {arg!r}")
    return WorkloadSpec("npz", path=str(path.resolve()), view=0)


_SYNTHETIC = re.compile(r"^synthetic-(\d+)-(\d+)(?:x(\d+))?$")
_GARDEN = re.compile(r"^garden(?:-v(\d+))?$")


def parse_workload_name(name: str) -> tuple[str, dict[str, int]]:
    """``"synthetic-20000-256"`` -> ("synthetic", {n, width, height}); ``"garden-v2"`` ->
    ("garden", {view}); one-line `InputError` otherwise."""
    m = _SYNTHETIC.match(name)
    if m:
        n, w = int(m.group(1)), int(m.group(2))
        h = int(m.group(3)) if m.group(3) else w
        if n < 1 or w < 1 or h < 1 or w * h > 4096 * 4096:
            raise InputError(f"scene: {name!r}: expected N >= 1 Gaussians and a size up to 4096x4096")
        return "synthetic", {"n": n, "width": w, "height": h}
    m = _GARDEN.match(name)
    if m:
        return "garden", {"view": int(m.group(1) or 0)}
    raise InputError(f"scene: unknown workload {name!r} (expected 'synthetic-N-S', 'synthetic-N-WxH', 'garden' "
                     f"or 'garden-vK')")


def workload_spec(name: str, seed: int) -> WorkloadSpec:
    """The `WorkloadSpec` a scene name (`parse_workload_name`) and seed stand for."""
    kind, args = parse_workload_name(name)
    if kind == "synthetic":
        return WorkloadSpec("synthetic", n=args["n"], width=args["width"], height=args["height"], seed=seed)
    return WorkloadSpec("npz", path=str(GARDEN_SFM), view=args["view"])


def build_workload(name: str, seed: int) -> Workload:
    """The `Workload` a scene name and seed stand for."""
    return workload_spec(name, seed).build()
