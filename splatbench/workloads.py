"""Rendering workloads: the standard synthetic scene, npz scenes, the garden SfM view, and
trained models (a 3DGS PLY framed from a few directions).

A workload is a set of Gaussians and one camera; benchmarks, the stress test and
the parity tests all draw their scenes from here (a workload is one of the five kinds of
"scene": docs/architecture.md). This module is also the one home of
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
from splatbench.guards import check_sh_degree, parse_size
from splatbench.errors import InputError
from splatbench.fsutil import atomic_write
from splatbench.gaussians import SH_BASES_OF_DEGREE, Gaussians, quat_to_rotmat
from splatbench.safeio import read_npz

GARDEN_SFM = Path(__file__).parent / "data" / "garden_sfm.npz"  # real SfM data; see data/NOTICE.md
#: Real trained 3DGS models (PlayCanvas, MIT; see data/NOTICE.md), by name: `--model guitar`.
MODELS_DIR = Path(__file__).parent / "data" / "models"
BUNDLED_MODELS = {"guitar": MODELS_DIR / "pc_guitar.ply", "biker": MODELS_DIR / "pc_biker.ply"}
#: ``--model``'s defaults: cameras around the model, and their image size.
MODEL_VIEWS = 3
MODEL_SIZE = "256x256"
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


PARITY_KINDS = ("standard", "overlap", "needles", "tiny", "large")


def random_camera_pose(rng: np.random.Generator) -> np.ndarray:
    """A random world_to_camera [4, 4] (rotation from a random unit quaternion)."""
    M = np.eye(4)
    M[:3, :3] = quat_to_rotmat(random_unit_quats(rng, 1)[0])
    M[:3, 3] = rng.uniform(-3, 3, 3)
    return M


def parity_scene(seed: int) -> tuple[Workload, tuple[float, float, float]]:
    """(workload, background) for parity scene ``seed``: the rasterizer's parity and gradient tests'
    scenes and regress's ``parity`` set. Gaussians generated in camera space (so they land in view),
    some beyond the image edges, moved to the world through a random rigid camera pose; off-centre
    principal point, non-square image; the kind (`PARITY_KINDS`) cycles with the seed, the SH degree
    is seed % 4, odd seeds have a random background."""
    rng = np.random.default_rng(10_000 + seed)
    kind = PARITY_KINDS[seed % len(PARITY_KINDS)]
    degree = seed % 4
    W, H = int(rng.integers(24, 72)), int(rng.integers(24, 72))
    n = int(rng.choice([1, 12, 60, 200, 400])) if kind != "overlap" else 300
    fx = W * rng.uniform(0.8, 1.5)
    fy = fx * rng.uniform(0.9, 1.1)
    cx = W / 2 + rng.uniform(-0.15, 0.15) * W
    cy = H / 2 + rng.uniform(-0.15, 0.15) * H
    z = rng.uniform(2, 6, n)
    if kind == "overlap":  # heavy overlap: a dense, opaque clump at the centre
        u, v = rng.normal(cx, 0.1 * W, n), rng.normal(cy, 0.1 * H, n)
    else:  # include some Gaussians beyond the image edges
        u, v = rng.uniform(-0.1 * W, 1.1 * W, n), rng.uniform(-0.1 * H, 1.1 * H, n)
    sigma_px = {"standard": (0.3, 6.0), "overlap": (1.0, 8.0), "needles": (0.5, 4.0), "tiny": (0.05, 0.8),
                "large": (5.0, 25.0)}[kind]
    aniso = 1.5 if kind == "needles" else 0.25
    cam_pts = np.stack([(u - cx) * z / fx, (v - cy) * z / fy, z], axis=1)
    sigma = np.exp(rng.uniform(np.log(sigma_px[0]), np.log(sigma_px[1]), n))
    log_scales = np.log(sigma * z / fx)[:, None] + aniso * rng.standard_normal((n, 3))
    logits = rng.normal(2.0 if kind == "overlap" else 0.0, 1.5, n)
    k = (degree + 1) ** 2
    sh = np.concatenate([0.6 * rng.standard_normal((n, 1, 3)), 0.1 * rng.standard_normal((n, k - 1, 3))], 1)
    w2c = random_camera_pose(rng)
    R, t = w2c[:3, :3], w2c[:3, 3]
    means = (cam_pts - t) @ R  # R^T (p - t), row-wise
    gaussians = Gaussians(means, log_scales, random_unit_quats(rng, n), logits, sh)
    camera = Camera(W, H, fx, fy, cx, cy, w2c)
    background = tuple(rng.uniform(0, 1, 3)) if seed % 2 else (0.0, 0.0, 0.0)
    return Workload(f"parity-{seed}-{kind}-d{degree}", gaussians, camera), background


def synthetic(n: int, width: int, height: int, seed: int = 0, *, sh_degree: int = 3,
              sigma_px: tuple[float, float] = (0.3, 6.0), anisotropy: float = 0.25,
              depth_range: tuple[float, float] = (2.0, 6.0), margin: float = 0.1,
              random_pose: bool = False) -> Workload:
    """The standard synthetic workload.

    Camera at the origin looking down +z, fx = fy = W, cx = W/2, cy = H/2 (with
    ``random_pose``: the same image from a random rigid camera pose, see `random_pose`). Means
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
    name = f"synthetic-{n}-{width}x{height}-s{seed}"
    if random_pose:
        return posed(Workload(name + "-posed", gaussians, camera), seed)
    return Workload(name, gaussians, camera)


def posed(workload: Workload, seed: int) -> Workload:
    """``workload`` (its camera at the origin, the identity pose) moved to a random rigid camera
    pose, seeded: a uniformly random rotation R and a centre c ~ N(0, 2² I). The means are
    mapped to x_world = Rᵀ x_cam + c and the camera gets world_to_camera = [R | -R c], so the
    camera-space means, and so the image up to the SH view directions, stay those of the
    identity pose; the rotations turn with them (q_world = q_R* q_cam, q_R the quaternion of R).

    At the identity a world-space mistake cancels out (a view direction taken from the world
    origin, W for Wᵀ, a sign error in the translation): a compared backend with one of those
    renders the identity-pose image correctly. Here it does not.
    """
    rng = np.random.default_rng([seed, 0x9E37])  # its own stream: the Gaussians stay those of `seed`
    q = random_unit_quats(rng, 1)[0]
    R = quat_to_rotmat(q[None])[0]
    c = 2.0 * rng.standard_normal(3)
    w2c = np.eye(4)
    w2c[:3, :3], w2c[:3, 3] = R, -R @ c
    g = workload.gaussians
    means = (np.asarray(g.means, dtype=np.float64) - workload.camera.world_to_camera[:3, 3]) \
        @ workload.camera.world_to_camera[:3, :3]  # back to camera space (identity: unchanged)
    moved = Gaussians(means @ R + c, g.log_scales, _quat_product(q * [1, -1, -1, -1], np.asarray(g.quats)),
                      g.opacity_logits, g.sh)
    cam = workload.camera
    return Workload(workload.name, moved, Camera(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, w2c,
                                                 near=cam.near, far=cam.far))


def _quat_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a b of (w, x, y, z) quaternions: a [4], b [N, 4] -> [N, 4]."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b.T
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=1)


def model_path(model: str | Path) -> Path:
    """A bundled model's name (`BUNDLED_MODELS`: guitar, biker) or a PLY file, as an existing path."""
    if str(model).lower() in BUNDLED_MODELS:
        return BUNDLED_MODELS[str(model).lower()]
    path = Path(model).expanduser()
    if not path.is_file():
        raise InputError(f"--model: no such file {str(model)!r} (a 3DGS .ply, or one of "
                         f"{', '.join(BUNDLED_MODELS)})")
    return path


def model_workload(model: str | Path, view: int, views: int, width: int, height: int, up=None) -> Workload:
    """View ``view`` of ``views`` around a trained model (a 3DGS PLY, or a `BUNDLED_MODELS` name).

    The cameras are `splatbench.framing.framing_rig`'s: evenly spaced azimuths about the up
    axis, 20° above the horizontal, framing the model at ``width`` x ``height``. The up axis:
    ``up`` [3] when given, else the one the PLY records (`splatbench.ply.ViewHints`), else
    `splatbench.framing.DEFAULT_UP`.
    """
    from splatbench.framing import DEFAULT_UP, framing_rig
    from splatbench.ply import read_view_hints

    path = model_path(model)
    if not 0 <= view < views:
        raise InputError(f"view: expected an index in [0, {views}), got {view}")
    gaussians = Gaussians.from_ply(path)
    if up is None:
        up = read_view_hints(path).up or DEFAULT_UP
    camera = framing_rig(gaussians, views, width, height, up=up)[view]
    return Workload(f"{path.stem}-view{view}", gaussians, camera)


def save_npz(workload: Workload, path: str | Path) -> Path:
    """Write ``workload`` with the keys of `WORKLOAD_KEYS` into ``path`` (as named: no suffix is
    added), whole or not at all (`fsutil.atomic_write`); returns the path."""
    g, c = workload.gaussians, workload.camera

    def write(temp: Path) -> None:
        with open(temp, "wb") as stream:  # a stream: np.savez would add ".npz" to the temporary's name
            np.savez(stream, means=g.means, log_scales=g.log_scales, quats=g.quats, opacity_logits=g.opacity_logits,
                     sh=g.sh, viewmat=c.world_to_camera, K=c.K, width=c.width, height=c.height)

    return atomic_write(path, write)


def load_npz(path: str | Path, *, view: int = 0) -> Workload:
    """Read a workload npz: either `WORKLOAD_KEYS`, or an SfM capture with `SFM_KEYS`
    (points seeded as 3DGS does, camera ``view``)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"workload: no such file {str(path)!r}")
    arrays = read_npz(path, what=f"workload: {path.name}")  # every header checked against the file; no pickle
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
    from splatbench.gaussians_from_points import from_points

    gaussians = from_points(arrays["means3d"], arrays["colors"])
    return Workload(f"{name}-view{view}", gaussians, sfm_camera(arrays, view))


# --------------------------------------------------------------------------- naming
@dataclass(frozen=True)
class WorkloadSpec:
    """A workload to build where it is used (cheap to pass between processes).

    ``kind`` "synthetic": `synthetic(n, width, height, seed, random_pose=posed)`;
    ``kind`` "npz": `load_npz(path, view=view)`;
    ``kind`` "model": `model_workload(path, view, views, width, height, up)`.
    """

    kind: str
    n: int = 0           # synthetic: number of Gaussians
    width: int = 0       # synthetic, model: image width (pixels)
    height: int = 0      # synthetic, model: image height (pixels)
    seed: int = 0        # synthetic: random seed
    path: str = ""       # npz, model: absolute path of the file
    view: int = 0        # npz, model: camera index
    label: str = ""      # name in the results ("" = the workload's own name)
    posed: bool = False  # synthetic: a random camera pose instead of the identity
    views: int = 0       # model: cameras around the model (view is one of them)
    up: tuple = ()       # model: the world's up [3] (() = the PLY's, else the default)

    def build(self) -> Workload:
        """The `Workload` (Gaussians and camera)."""
        if self.kind == "synthetic":
            return synthetic(self.n, self.width, self.height, self.seed, random_pose=self.posed)
        if self.kind == "npz":
            return load_npz(self.path, view=self.view)
        if self.kind == "model":
            return model_workload(self.path, self.view, self.views, self.width, self.height,
                                  tuple(self.up) if self.up else None)
        raise InputError(f"workload kind: expected 'synthetic', 'npz' or 'model', got {self.kind!r}")


def parse_synthetic(count: str, size: str, seed: int = 0, *, posed: bool = False) -> WorkloadSpec:
    """``--synthetic N WxH`` -> a synthetic `WorkloadSpec` (``posed``: from a random camera pose)."""
    try:
        n = int(count)
    except ValueError:
        raise InputError(f"--synthetic: expected a Gaussian count, got {count!r}") from None
    if n < 1:
        raise InputError(f"--synthetic: expected a Gaussian count >= 1, got {count!r}")
    width, height = parse_size(size, "--synthetic")
    return WorkloadSpec("synthetic", n=n, width=width, height=height, seed=seed, posed=posed)


def parse_model(model: str, up: str | None = None, views: int | None = None,
                size: str | None = None) -> list[WorkloadSpec]:
    """``--model FILE.ply|guitar|biker`` [``--up``, ``--model-views``, ``--model-size``] -> one
    model `WorkloadSpec` per view (`model_workload`)."""
    from splatbench.framing import parse_up

    views = MODEL_VIEWS if views is None else views
    size = MODEL_SIZE if size is None else size
    path = model_path(model)
    if path.suffix.lower() != ".ply":
        raise InputError(f"--model: expected a 3DGS .ply file (or a bundled model's name), got {model!r}")
    if views < 1:
        raise InputError(f"--model-views: expected a count >= 1, got {views}")
    width, height = parse_size(size, "--model-size")
    vector = parse_up(up) if up is not None else ()
    return [WorkloadSpec("model", path=str(path.resolve()), view=k, views=views, width=width, height=height,
                         up=tuple(vector)) for k in range(views)]


def parse_models(models, up: str | None, views: int | None = None, size: str | None = None) -> list[WorkloadSpec]:
    """The `WorkloadSpec`s of the ``--model`` options (`model_options`): one per model and view;
    ``--up`` without a model is an error."""
    if up is not None and not models:
        raise InputError("--up: applies to --model only")
    return [spec for m in models for spec in parse_model(m, up, views, size)]


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


def model_options(command):
    """``--model``, ``--up``, ``--model-views`` and ``--model-size`` (one definition for `splatbench
    compare` and `splatbench bench raster`): the command receives ``models``, ``up``,
    ``model_views`` and ``model_size`` (`parse_models` reads them)."""
    import click

    for option in reversed((
        click.option("--model", "models", multiple=True, metavar="FILE.ply|guitar|biker",
                     help="A trained 3DGS model as workloads: --model-views cameras around it, 20 degrees above "
                          "the horizontal (repeatable); guitar and biker are the bundled real models."),
        click.option("--up", default=None, metavar="AXIS|X,Y,Z",
                     help="The models' up axis (+y, -z, ... or X,Y,Z) [default: the one the PLY records, else -y]."),
        click.option("--model-views", "model_views", default=MODEL_VIEWS, show_default=True, type=int,
                     help="Cameras around each --model."),
        click.option("--model-size", "model_size", default=MODEL_SIZE, show_default=True, metavar="WxH",
                     help="Image size of the --model views."),
    )):
        command = option(command)
    return command
