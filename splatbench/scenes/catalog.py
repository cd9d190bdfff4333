"""The scene catalog: folders holding a Mitsuba scene file and a camera-rig spec.

A scene is a folder ``<name>/`` with two files:

* ``scene.xml`` -- a Mitsuba 3 scene (``<scene version="3.x.x">``), without a sensor:
  the rig supplies the cameras. Its integrator, if it declares one, renders the
  images; relative file names (textures) resolve against the folder.
* ``rig.toml`` -- a `RigSpec`: how cameras are placed, how many train and test views,
  resolution, samples per pixel, seed.

Scene folders are found in, by precedence: the folders given by the caller
(``--scenes-dir``), the folders in the environment variable ``SPLATBENCH_SCENES``
(``os.pathsep``-separated), and the repository's ``scenes/``. A scene found earlier
shadows one of the same name found later, so a user can override a built-in scene
by copying and editing it. ``scenes/README.md`` documents every rig field.

Example::

    from splatbench.scenes import find_scenes, get_scene
    sorted(find_scenes())              # ['diffuse', 'far', 'glossy', 'occlusion', 'textured', 'thin']
    spec = get_scene("diffuse")
    cams = spec.rig.cameras()          # list[Camera], train and test views in rig order
    spec.rig.test_indices()            # [0, 8, 16, 24]
"""

from __future__ import annotations

import math
import os
import re
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from splatbench.cameras import Camera
from splatbench.guards import check_keys
from splatbench.errors import InputError

#: Camera placements a rig can ask for.
RIG_KINDS = ("orbit", "hemisphere", "forward")
#: Environment variable with extra scene folders (``os.pathsep``-separated).
SCENES_ENV = "SPLATBENCH_SCENES"
#: With ``views=V`` given explicitly, view ``i`` is a test view when ``i % TEST_EVERY == 0``
#: (3DGS's ``llffhold``).
TEST_EVERY = 8
SCENE_FILE = "scene.xml"
RIG_FILE = "rig.toml"

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def builtin_scenes_dir() -> Path:
    """The repository's ``scenes/`` folder (it may not exist in a non-editable install)."""
    return Path(__file__).resolve().parents[2] / "scenes"


# ----------------------------------------------------------------------------- rig
@dataclass(frozen=True)
class RigSpec:
    """Where the cameras of a scene go, read from ``rig.toml`` (see ``scenes/README.md``).

    Angles in degrees. Azimuth is measured around ``up`` from the world axis most
    perpendicular to it (+x for ``up = +y``) towards ``up × x`` (+z); elevation is the
    angle above the plane perpendicular to ``up``.
    """

    kind: str                                   # "orbit" | "hemisphere" | "forward"
    radius: float                               # distance from every eye to `target` (forward: of the rig centre)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the point every camera looks at
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)      # world up; it points up in every image
    elevation_deg: tuple[float, float] = (20.0, 40.0)     # orbit: swept range; hemisphere: the cap; forward: centre = mid
    azimuth_deg: tuple[float, float] = (0.0, 360.0)       # range; a full turn (>= 360) leaves out the end point
    spread: float = 0.0                         # forward only: radius of the disc of eye positions (> 0)
    fov_deg: float = 45.0                       # horizontal field of view
    train_views: int = 28                       # number of training views
    test_views: int = 4                         # number of held-out views (spread evenly through the sequence)
    resolution: tuple[int, int] = (256, 256)    # (width, height) in pixels
    spp: int = 64                               # samples per pixel of the colour render
    seed: int = 0                               # sampler seeds, hemisphere azimuth offset, point sampling
    near: float = 0.05                          # near clip (camera z)
    far: float = 1000.0                         # far clip (camera z)
    points: int = 20_000                        # points3D sampled for the COLMAP layout
    description: str = ""                       # one line shown by `splatbench scenes list`

    # ---------------------------------------------------------------- reading
    @classmethod
    def from_toml(cls, path: str | Path) -> RigSpec:
        """Read and validate a ``rig.toml``; errors are one line naming the file and field."""
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError(f"{path}: missing (a scene folder needs {SCENE_FILE} and {RIG_FILE})") from None
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"{path}: invalid TOML ({exc})") from None
        return cls.from_mapping(data, source=str(path))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "rig") -> RigSpec:
        """Validate a mapping of rig fields (the parsed TOML)."""
        check_keys(sorted(data), (f.name for f in fields(cls)), source=source)
        if "kind" not in data or "radius" not in data:
            missing = "kind" if "kind" not in data else "radius"
            raise InputError(f"{source}: {missing}: required")
        p = _Fields(source)
        kind = data["kind"]
        if kind not in RIG_KINDS:
            raise InputError(f"{source}: kind: expected one of {', '.join(RIG_KINDS)}, got {kind!r}")
        d = {f.name: f.default for f in fields(cls)}
        d.update(data)
        up = p.vec3("up", d["up"])
        if not np.linalg.norm(up) > 0:
            raise InputError(f"{source}: up: expected a non-zero vector, got {list(up)}")
        elevation = p.range_("elevation_deg", d["elevation_deg"], -89.0, 89.0)
        azimuth = p.range_("azimuth_deg", d["azimuth_deg"], -720.0, 720.0)
        spread = p.number("spread", d["spread"], minimum=0.0)
        if kind == "forward" and not spread > 0:
            raise InputError(f"{source}: spread: a forward rig needs spread > 0, got {spread!r}")
        fov = p.number("fov_deg", d["fov_deg"], minimum=0.0, strict=True)
        if not fov < 180:
            raise InputError(f"{source}: fov_deg: expected a value in (0, 180), got {fov!r}")
        near = p.number("near", d["near"], minimum=0.0, strict=True)
        far = p.number("far", d["far"], minimum=0.0, strict=True)
        if not near < far:
            raise InputError(f"{source}: near, far: expected near < far, got near={near!r}, far={far!r}")
        if not isinstance(d["description"], str):
            raise InputError(f"{source}: description: expected a string, got {d['description']!r}")
        return cls(kind=kind, radius=p.number("radius", d["radius"], minimum=0.0, strict=True),
                   target=p.vec3("target", d["target"]), up=up, elevation_deg=elevation, azimuth_deg=azimuth,
                   spread=spread, fov_deg=fov, train_views=p.integer("train_views", d["train_views"], 1),
                   test_views=p.integer("test_views", d["test_views"], 0),
                   resolution=parse_resolution(d["resolution"], field=f"{source}: resolution"),
                   spp=p.integer("spp", d["spp"], 1), seed=p.integer("seed", d["seed"], 0), near=near, far=far,
                   points=p.integer("points", d["points"], 0), description=d["description"])

    # ---------------------------------------------------------------- cameras
    @property
    def views(self) -> int:
        """Total number of views the rig asks for (train + test)."""
        return self.train_views + self.test_views

    def test_indices(self, views: int | None = None) -> list[int]:
        """Indices of the held-out views in the sequence of `cameras`.

        ``views=None``: the rig's ``test_views`` spread evenly over its
        ``train_views + test_views`` views, ``floor(k·N/T)`` for k < T -- every 8th view,
        as 3DGS holds out, when N = 8·T. ``views=V``: every 8th view (``i % 8 == 0``).
        """
        if views is None:
            n, t = self.views, self.test_views
            return sorted({(k * n) // t for k in range(t)}) if t else []
        n = _count("views", views)
        return list(range(0, n, TEST_EVERY))

    def eyes(self, views: int | None = None) -> np.ndarray:
        """[N, 3] float64 camera centres, deterministic for a given rig and ``views``."""
        n = self.views if views is None else _count("views", views)
        target = np.asarray(self.target, dtype=np.float64)
        up, ex, ez = _frame(np.asarray(self.up, dtype=np.float64))
        el_lo, el_hi = np.radians(self.elevation_deg)
        az_lo, az_hi = np.radians(self.azimuth_deg)
        full_turn = az_hi - az_lo >= 2 * math.pi - 1e-9
        i = np.arange(n, dtype=np.float64)

        def direction(az: np.ndarray, el: np.ndarray) -> np.ndarray:
            return (np.cos(el)[:, None] * (np.cos(az)[:, None] * ex + np.sin(az)[:, None] * ez)
                    + np.sin(el)[:, None] * up)

        if self.kind == "orbit":
            # evenly spaced azimuths; elevation sweeps its range as a cosine, 3 periods per sequence
            frac = i / n if full_turn else i / max(n - 1, 1)
            az = az_lo + (az_hi - az_lo) * frac
            el = 0.5 * (el_lo + el_hi) + 0.5 * (el_hi - el_lo) * np.cos(2 * math.pi * 3 * i / n)
            return target + self.radius * direction(az, el)
        if self.kind == "hemisphere":
            # a Fibonacci spiral on the cap (equal-area heights), seeded azimuth offset
            offset = np.random.default_rng(self.seed).uniform(0.0, 1.0)
            h = np.sin(el_lo) + (np.sin(el_hi) - np.sin(el_lo)) * (i + 0.5) / n
            frac = (offset + i * _GOLDEN_ANGLE / (2 * math.pi)) % 1.0
            az = az_lo + (az_hi - az_lo) * frac
            return target + self.radius * direction(az, np.arcsin(h))
        # forward: a sunflower disc of eyes around the rig centre, in the plane facing the target
        centre_dir = direction(np.array([0.5 * (az_lo + az_hi)]), np.array([0.5 * (el_lo + el_hi)]))[0]
        _, px, py = _frame(centre_dir)
        r = self.spread * np.sqrt((i + 0.5) / n)
        phi = i * _GOLDEN_ANGLE
        return (target + self.radius * centre_dir + (r * np.cos(phi))[:, None] * px
                + (r * np.sin(phi))[:, None] * py)

    def cameras(self, views: int | None = None, resolution: tuple[int, int] | None = None) -> list[Camera]:
        """The rig's cameras in sequence order (``Camera.look_at`` from each eye to ``target``).

        ``views`` overrides the total number of views and ``resolution`` the
        ``(width, height)``; the horizontal field of view is kept.
        """
        width, height = self.resolution if resolution is None else parse_resolution(resolution)
        return [Camera.look_at(eye, self.target, self.up, width, height, self.fov_deg, self.near, self.far)
                for eye in self.eyes(views)]


def parse_resolution(value: Any, base: tuple[int, int] | None = None, field: str = "resolution") -> tuple[int, int]:
    """``(width, height)`` from an int, ``[W, H]``, ``"WxH"`` or ``"W"``.

    A single number is the width; the height follows ``base``'s aspect ratio (square
    when no ``base`` is given).
    """
    if isinstance(value, str):
        parts = value.lower().split("x")
        try:
            nums = [int(p) for p in parts]
        except ValueError:
            raise InputError(f"{field}: expected W or WxH, got {value!r}") from None
        value = nums[0] if len(nums) == 1 else nums
    if isinstance(value, (list, tuple)):
        if len(value) != 2 or not all(_is_int(v) and v > 0 for v in value):
            raise InputError(f"{field}: expected [width, height] positive ints, got {value!r}")
        return int(value[0]), int(value[1])
    if not (_is_int(value) and value > 0):
        raise InputError(f"{field}: expected a positive int or [width, height], got {value!r}")
    width = int(value)
    height = width if base is None else max(1, round(width * base[1] / base[0]))
    return width, height


# ---------------------------------------------------------------------------- scenes
@dataclass(frozen=True)
class SceneSpec:
    """One catalog entry: a folder with ``scene.xml`` and ``rig.toml``."""

    name: str        # the folder name
    folder: Path     # absolute path of the scene folder
    rig: RigSpec     # parsed and validated rig.toml

    @property
    def scene_file(self) -> Path:
        return self.folder / SCENE_FILE

    @property
    def rig_file(self) -> Path:
        return self.folder / RIG_FILE

    def files(self) -> list[Path]:
        """Every file of the scene folder, sorted (what the dataset cache hashes)."""
        return sorted(p for p in self.folder.rglob("*")
                      if p.is_file() and not any(part.startswith(".") for part in p.relative_to(self.folder).parts))


def load_scene_spec(folder: str | Path) -> SceneSpec:
    """Read and validate one scene folder (one-line `InputError` naming the bad file)."""
    folder = Path(folder).resolve()
    if not folder.is_dir():
        raise InputError(f"scene: {str(folder)!r} is not a folder")
    if not _NAME.match(folder.name):
        raise InputError(f"scene: folder name {folder.name!r} must be letters, digits, '_', '-' or '.'")
    _check_scene_xml(folder / SCENE_FILE)
    return SceneSpec(folder.name, folder, RigSpec.from_toml(folder / RIG_FILE))


def scene_dirs(extra: Iterable[str | Path] = ()) -> list[Path]:
    """Folders searched for scenes, by precedence: ``extra``, ``$SPLATBENCH_SCENES``, built-in."""
    out: list[Path] = []
    for p in extra:
        path = Path(p).expanduser()
        if not path.is_dir():
            raise InputError(f"--scenes-dir: {str(path)!r} is not a folder")
        out.append(path.resolve())
    for p in filter(None, os.environ.get(SCENES_ENV, "").split(os.pathsep)):
        path = Path(p).expanduser()
        if not path.is_dir():
            raise InputError(f"{SCENES_ENV}: {str(path)!r} is not a folder")
        out.append(path.resolve())
    builtin = builtin_scenes_dir()
    if builtin.is_dir():
        out.append(builtin)
    return list(dict.fromkeys(out))


def find_scenes(extra: Iterable[str | Path] = ()) -> dict[str, SceneSpec]:
    """All scenes, name -> `SceneSpec`, sorted by name; earlier folders shadow later ones.

    A sub-folder holding a ``scene.xml`` is a scene (its ``rig.toml`` must exist and be
    valid); other sub-folders are ignored.
    """
    found: dict[str, SceneSpec] = {}
    for root in scene_dirs(extra):
        for sub in sorted(root.iterdir()):
            if sub.name in found or not (sub / SCENE_FILE).is_file():
                continue
            found[sub.name] = load_scene_spec(sub)
    return dict(sorted(found.items()))


def get_scene(name: str | Path, extra: Iterable[str | Path] = ()) -> SceneSpec:
    """A scene by catalog name, or by the path of a scene folder (a name with a ``/``)."""
    if isinstance(name, Path) or "/" in str(name) or os.sep in str(name):
        return load_scene_spec(name)
    scenes = find_scenes(extra)
    if str(name) not in scenes:
        known = ", ".join(scenes) or "none"
        raise InputError(f"scene: unknown name {str(name)!r} (known: {known})")
    return scenes[str(name)]


# --------------------------------------------------------------------------- helpers
def _check_scene_xml(path: Path) -> None:
    if not path.is_file():
        raise InputError(f"{path}: missing (a scene folder needs {SCENE_FILE} and {RIG_FILE})")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InputError(f"{path}: invalid XML ({exc})") from None
    version = root.get("version", "")
    if root.tag != "scene" or not version.startswith("3."):
        raise InputError(f'{path}: expected a Mitsuba 3 <scene version="3.x.x"> root, '
                         f"got <{root.tag} version={version!r}>")


def _frame(up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, x, z): ``u = up/|up|`` and two unit axes completing a right-handed frame (x, u, z)."""
    u = up / np.linalg.norm(up)
    axis = np.eye(3)[int(np.argmin(np.abs(u)))]  # the world axis most perpendicular to up
    x = axis - (axis @ u) * u
    x /= np.linalg.norm(x)
    return u, x, np.cross(x, u)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _count(name: str, value: Any) -> int:
    if not (_is_int(value) and value > 0):
        raise InputError(f"{name}: expected a positive int, got {value!r}")
    return int(value)


class _Fields:
    """Typed field readers that raise one-line errors prefixed with the source file."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, name: str, want: str, value: Any) -> InputError:
        return InputError(f"{self.source}: {name}: expected {want}, got {value!r}")

    def number(self, name: str, value: Any, minimum: float | None = None, strict: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(name, "a finite number", value)
        if minimum is not None and (value < minimum or (strict and value == minimum)):
            raise self.fail(name, f"a number {'>' if strict else '>='} {minimum:g}", value)
        return float(value)

    def integer(self, name: str, value: Any, minimum: int) -> int:
        if not _is_int(value) or value < minimum:
            raise self.fail(name, f"an int >= {minimum}", value)
        return int(value)

    def vec3(self, name: str, value: Any) -> tuple[float, float, float]:
        if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 3:
            raise self.fail(name, "[x, y, z]", value)
        return tuple(self.number(name, v) for v in value)  # type: ignore[return-value]

    def range_(self, name: str, value: Any, lo: float, hi: float) -> tuple[float, float]:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value, value]
        if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
            raise self.fail(name, "a number or [low, high]", value)
        a, b = (self.number(name, v) for v in value)
        if not lo <= a <= b <= hi:
            raise self.fail(name, f"{lo:g} <= low <= high <= {hi:g}", list(value))
        return a, b
