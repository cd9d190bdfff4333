"""Pinhole cameras in OpenCV axes, and converters to Mitsuba, COLMAP and Blender/NeRF.

Conventions (``docs/conventions.md``): camera axes x right, y down, z forward;
``world_to_camera`` [4, 4] maps world points to camera points; a camera point
(x, y, z) lands at ``u = fx·x/z + cx``, ``v = fy·y/z + cy`` in continuous pixel
coordinates whose origin is the top-left *corner* of the image, so pixel (row i,
column j) has its centre at ``(j + 0.5, i + 0.5)`` -- COLMAP's convention.

The other tools' conventions, each checked by ``tests/test_cameras.py``:

* **Mitsuba 3** ``perspective``: camera looks along +z with +y up and +x *left*,
  i.e. Mitsuba's camera frame is OpenCV's rotated 180° about z, so
  ``to_world = camera_to_world · diag(-1, -1, 1, 1)``. Normalised film position
  ``(u/W, v/H)`` has the OpenCV pixel orientation (origin top-left, v down). The
  principal point offsets are fractions of the film size, with
  ``cx = W·(0.5 - principal_point_offset_x)``, ``cy = H·(0.5 - principal_point_offset_y)``.
  Pixels are square (``fy = fx``); Mitsuba has no anisotropic focal length.
* **COLMAP** (pycolmap): ``cam_from_world`` is ``world_to_camera``, same axes and
  same pixel-centre convention; PINHOLE params are (fx, fy, cx, cy).
* **Blender / NeRF synthetic / nerfstudio**: ``transform_matrix`` is camera-to-world
  in OpenGL axes (x right, y up, z back): ``transform_matrix = camera_to_world ·
  diag(1, -1, -1, 1)``; ``fx = 0.5·W / tan(camera_angle_x / 2)``; the optional
  nerfstudio keys ``fl_x, fl_y, cx, cy`` override the defaults (fy = fx, principal
  point at the image centre) and are read in the pixel-corner convention above.

Size (~440 lines, over the ~400 guideline on purpose): `Camera` and its three converter
pairs are one concept whose public API is the class itself (``Camera.from_mitsuba``,
``Camera.from_colmap``, ...); the boundary checks at the bottom serve every converter.
Splitting the converters out would scatter one type's API over several modules.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import Any

import numpy as np

from splatbench.guards import as_float_array, check_image_size
from splatbench.errors import InputError
from splatbench.mitsuba_loader import mitsuba

#: Largest accepted ``max |RᵀR - I|`` of the rotation part of ``world_to_camera``.
ORTHONORMAL_TOL = 1e-5

_MITSUBA_FLIP = np.diag([-1.0, -1.0, 1.0, 1.0])  # OpenCV camera axes <-> Mitsuba camera axes
_OPENGL_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV camera axes <-> OpenGL/Blender camera axes


def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name}: expected a positive int, got {value!r}")
    try:
        out = operator.index(value)
    except TypeError:
        raise InputError(f"{name}: expected a positive int, got {value!r}") from None
    if out <= 0:
        raise InputError(f"{name}: expected a positive int, got {out}")
    return int(out)


def _finite_float(name: str, value: Any, positive: bool = False) -> float:
    # float(True) is 1.0 and np.asarray("0.5", float64) is 0.5: a flag or a string is not a number
    if value is None or isinstance(value, (bool, np.bool_, str, bytes)):
        raise InputError(f"{name}: expected a finite number, got {value!r}")
    try:
        out = float(np.asarray(value, dtype=np.float64).reshape(()))
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a finite number, got {value!r}") from None
    if not math.isfinite(out) or (positive and out <= 0):
        kind = "a positive finite" if positive else "a finite"
        raise InputError(f"{name}: expected {kind} number, got {out!r}")
    return out


def _rigid_inverse(matrix: np.ndarray) -> np.ndarray:
    rot, trans = matrix[:3, :3], matrix[:3, 3]
    out = np.eye(4)
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ trans
    return out


def _check_rigid(name: str, matrix: np.ndarray) -> None:
    """One-line `InputError` unless ``matrix`` [4, 4] is a rotation + translation."""
    last = matrix[3]
    if not np.array_equal(last, [0.0, 0.0, 0.0, 1.0]):
        raise InputError(f"{name}: last row must be [0, 0, 0, 1], got {last.tolist()}")
    if not np.isfinite(matrix).all():
        raise InputError(f"{name}: entries must be finite numbers, got {matrix.tolist()}")
    rot = matrix[:3, :3]
    with np.errstate(over="ignore", invalid="ignore"):  # a huge entry overflows RᵀR to inf: not orthonormal
        err = float(np.max(np.abs(rot.T @ rot - np.eye(3))))
    if not err <= ORTHONORMAL_TOL:
        raise InputError(f"{name}: rotation part is not orthonormal "
                         f"(max |RᵀR - I| = {err:.3g} > {ORTHONORMAL_TOL:g}; scale or shear?)")
    det = float(np.linalg.det(rot))
    if det < 0:
        raise InputError(f"{name}: rotation part is a reflection (det = {det:.6g})")


def _matrix4(name: str, value: Any) -> np.ndarray:
    """A [4, 4] float64 array from a nested list, an array or a Mitsuba/Dr.Jit transform."""
    if hasattr(value, "matrix") and not isinstance(value, np.ndarray):
        value = value.matrix  # mi.Transform4f / Transform4d
        value = value() if callable(value) else value
    if value is None:  # np.array(None, float64) is nan, of shape []
        raise InputError(f"{name}: expected shape [4, 4], got null")
    if isinstance(value, (list, tuple)):  # nested lists (JSON): "1.5" or true would convert silently
        _refuse_non_numbers(name, value)
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: cannot convert {type(value).__name__} to a 4x4 matrix ({exc})") from None
    if array.size == 16:  # Dr.Jit's dynamic variants give [4, 4, 1]
        array = array.reshape(4, 4)
    return as_float_array(name, array, (4, 4), {}, dtype=np.float64)


def _refuse_non_numbers(name: str, value: Any) -> None:
    """A one-line `InputError` naming the first entry of nested lists that is a string, a
    boolean or null (each of which NumPy would turn into a number or nan)."""
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _refuse_non_numbers(f"{name}[{i}]", item)
    elif value is None or isinstance(value, (bool, np.bool_, str, bytes)):
        raise InputError(f"{name}: expected a number, got {'null' if value is None else repr(value)}")


def _scalar(value: Any) -> float:
    """A Python float from a float, a 1-element array or a Dr.Jit scalar/array."""
    return float(np.asarray(value, dtype=np.float64).reshape(-1)[0])


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera with OpenCV axes and COLMAP's pixel-centre convention.

    Fields::

        width, height    image size in pixels (positive ints)
        fx, fy           focal lengths in pixels (positive)
        cx, cy           principal point, pixels from the top-left image *corner*
        world_to_camera  [4, 4] float64 rigid transform (rotation, translation, last
                         row [0, 0, 0, 1]); camera axes x right, y down, z forward
        near, far        clip depths along camera z, 0 < near < far

    Frozen, and its array is read-only (a private checked copy): change a camera with
    `dataclasses.replace` or its methods, never in place. A backend wanting the matrix as a
    tensor copies it (``torch.tensor(cam.world_to_camera)``; ``torch.as_tensor`` would share the
    read-only memory and warns that it is not writable).

    Pixel (row i, column j) has its centre at ``(u, v) = (j + 0.5, i + 0.5)``.

    Example::

        cam = Camera.look_at(eye=[0, 0, -3], target=[0, 0, 0], up=[0, -1, 0],
                             width=64, height=48, fov_x_deg=60)
        uv, z = cam.project(np.zeros((1, 3)))   # uv [[32, 24]], z [3]
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    world_to_camera: np.ndarray  # [4, 4], read-only after construction
    near: float = 0.01
    far: float = 1e10

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "width", _positive_int("width", self.width))
        set_(self, "height", _positive_int("height", self.height))
        check_image_size(self.width, self.height, field="width, height", memory=False)  # Dr.Jit's bound
        set_(self, "fx", _finite_float("fx", self.fx, positive=True))
        set_(self, "fy", _finite_float("fy", self.fy, positive=True))
        set_(self, "cx", _finite_float("cx", self.cx))
        set_(self, "cy", _finite_float("cy", self.cy))
        w2c = _matrix4("world_to_camera", self.world_to_camera).copy()
        _check_rigid("world_to_camera", w2c)
        w2c.flags.writeable = False  # checked once: a later `cam.world_to_camera[0, 3] = nan` raises
        set_(self, "world_to_camera", w2c)
        near = _finite_float("near", self.near, positive=True)
        far = _finite_float("far", self.far, positive=True)
        if not near < far:
            raise InputError(f"near, far: expected 0 < near < far, got near={near!r}, far={far!r}")
        set_(self, "near", near)
        set_(self, "far", far)

    def __repr__(self) -> str:
        return (f"Camera({self.width}x{self.height}, fx={self.fx:.6g}, fy={self.fy:.6g}, "
                f"cx={self.cx:.6g}, cy={self.cy:.6g}, center={np.round(self.center, 6).tolist()})")

    # ------------------------------------------------------------- properties
    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the standard name of the intrinsics matrix
        """[3, 3] float64 intrinsics ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def rotation(self) -> np.ndarray:
        """[3, 3] world-to-camera rotation."""
        return self.world_to_camera[:3, :3].copy()

    @property
    def translation(self) -> np.ndarray:
        """[3] world-to-camera translation (the world origin in camera coordinates)."""
        return self.world_to_camera[:3, 3].copy()

    @property
    def camera_to_world(self) -> np.ndarray:
        """[4, 4] float64 inverse of ``world_to_camera`` (OpenCV camera axes)."""
        return _rigid_inverse(self.world_to_camera)

    @property
    def center(self) -> np.ndarray:
        """[3] camera centre in world coordinates, ``-Rᵀ t``."""
        return -self.world_to_camera[:3, :3].T @ self.world_to_camera[:3, 3]

    # -------------------------------------------------------------- geometry
    def project(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Project world points [M, 3] to ``(uv [M, 2], z [M])`` in float64.

        ``uv`` are continuous pixel coordinates (pixel (i, j) centre at (j+0.5, i+0.5));
        ``z`` is the camera-space depth. Where ``z <= 0`` (on or behind the camera
        plane) ``uv`` is NaN. No near/far clipping is applied.
        """
        pts = as_float_array("points", points, (None, 3), {}, dtype=np.float64)
        cam = pts @ self.world_to_camera[:3, :3].T + self.world_to_camera[:3, 3]
        z = cam[:, 2]
        front = z > 0
        safe_z = np.where(front, z, 1.0)
        uv = np.stack([self.fx * cam[:, 0] / safe_z + self.cx, self.fy * cam[:, 1] / safe_z + self.cy], -1)
        uv[~front] = np.nan
        return uv, z

    def scaled(self, factor: float) -> Camera:
        """The same camera for the image resized by ``factor`` (e.g. 0.25 for a quarter).

        New size ``round(W·factor) × round(H·factor)``; with the per-axis ratios
        ``sx = W'/W``, ``sy = H'/H`` (exact image resize, pixel corners map to pixel
        corners) ``fx, cx`` scale by ``sx`` and ``fy, cy`` by ``sy``.
        """
        f = _finite_float("factor", factor, positive=True)
        width, height = round(self.width * f), round(self.height * f)
        if width < 1 or height < 1:
            raise InputError(f"factor: {f!r} turns {self.width}x{self.height} into an empty image")
        sx, sy = width / self.width, height / self.height
        return Camera(width, height, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy,
                      self.world_to_camera, self.near, self.far)

    # ---------------------------------------------------------- constructors
    @classmethod
    def look_at(cls, eye: Any, target: Any, up: Any, width: int, height: int, fov_x_deg: float,
                near: float = 0.01, far: float = 1e10) -> Camera:
        """A camera at ``eye`` looking at ``target`` with ``up`` pointing up in the image.

        Square pixels (``fy = fx = 0.5·W / tan(fov_x/2)``), principal point at the
        image centre (``cx = W/2``, ``cy = H/2``).
        """
        eye_ = as_float_array("eye", eye, (3,), {}, dtype=np.float64)
        target_ = as_float_array("target", target, (3,), {}, dtype=np.float64)
        up_ = as_float_array("up", up, (3,), {}, dtype=np.float64)
        fov = _finite_float("fov_x_deg", fov_x_deg, positive=True)
        if not fov < 180:
            raise InputError(f"fov_x_deg: expected a value in (0, 180), got {fov!r}")
        forward = target_ - eye_
        length = np.linalg.norm(forward)
        if not length > 0:
            raise InputError(f"target: equals eye {eye_.tolist()}; the view direction is undefined")
        forward /= length
        right = np.cross(forward, up_)
        r_len = np.linalg.norm(right)
        if not r_len > 1e-9 * max(np.linalg.norm(up_), 1e-300):
            raise InputError(f"up: {up_.tolist()} is zero or parallel to the view direction {forward.tolist()}")
        right /= r_len
        down = np.cross(forward, right)
        w2c = np.eye(4)
        w2c[:3, :3] = np.stack([right, down, forward])
        w2c[:3, 3] = -w2c[:3, :3] @ eye_
        width_, height_ = _positive_int("width", width), _positive_int("height", height)
        f = 0.5 * width_ / math.tan(math.radians(fov) / 2)
        return cls(width_, height_, f, f, width_ / 2, height_ / 2, w2c, near, far)

    # ---------------------------------------------------------------- Mitsuba
    def to_mitsuba(self) -> dict:
        """A dict for ``mi.load_dict``: a ``perspective`` sensor with an ``hdrfilm``.

        Uses the current Mitsuba variant (sets ``scalar_rgb`` when none is set); the
        transform is a ``mi.ScalarTransform4d`` so the dict itself keeps float64 (a
        loaded sensor stores float32 in single-precision variants). Needs square
        pixels (``fx == fy``); `InputError` otherwise.
        """
        if self.fx != self.fy:
            raise InputError(f"fx, fy: Mitsuba's perspective sensor needs square pixels, "
                             f"got fx={self.fx!r}, fy={self.fy!r}")
        mi = mitsuba(variant=None)
        out: dict[str, Any] = {
            "type": "perspective",
            "fov": math.degrees(2 * math.atan(0.5 * self.width / self.fx)),
            "fov_axis": "x",
            "near_clip": self.near,
            "far_clip": self.far,
            "to_world": mi.ScalarTransform4d(self.camera_to_world @ _MITSUBA_FLIP),
            "film": {"type": "hdrfilm", "width": self.width, "height": self.height,
                     "rfilter": {"type": "box"}},
        }
        off_x, off_y = 0.5 - self.cx / self.width, 0.5 - self.cy / self.height
        if off_x != 0:
            out["principal_point_offset_x"] = off_x
        if off_y != 0:
            out["principal_point_offset_y"] = off_y
        return out

    @classmethod
    def from_mitsuba(cls, sensor: Any, near: float | None = None, far: float | None = None) -> Camera:
        """A camera from a Mitsuba ``perspective`` sensor, or from its `to_mitsuba`-style dict.

        A loaded sensor gives float32 values in single-precision variants; a dict keeps
        float64. ``near``/``far`` override the sensor's clip planes when given.
        """
        if isinstance(sensor, dict):
            cam = _camera_from_mitsuba_dict(sensor)
        else:
            cam = _camera_from_mitsuba_sensor(sensor)
        if near is None and far is None:
            return cam
        return cls(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, cam.world_to_camera,
                   cam.near if near is None else near, cam.far if far is None else far)

    # ----------------------------------------------------------------- COLMAP
    @classmethod
    def from_colmap(cls, camera: Any, image: Any, near: float = 0.01, far: float = 1e10) -> Camera:
        """A camera from a ``pycolmap.Camera`` (PINHOLE or SIMPLE_PINHOLE) and a pose.

        ``image`` is a ``pycolmap.Image`` with a pose, or its ``cam_from_world``
        ``pycolmap.Rigid3d`` (world-to-camera) directly.
        """
        model = getattr(camera, "model_name", None)
        params = np.asarray(getattr(camera, "params", []), dtype=np.float64)
        if model == "PINHOLE":
            fx, fy, cx, cy = params
        elif model == "SIMPLE_PINHOLE":
            f, cx, cy = params
            fx = fy = f
        else:
            raise InputError(f"camera.model: expected PINHOLE or SIMPLE_PINHOLE, got {model!r} "
                             f"(undistort the images first)")
        pose = image
        if hasattr(image, "cam_from_world"):
            if hasattr(image, "has_pose") and not image.has_pose:
                raise InputError(f"image: {getattr(image, 'name', '')!r} has no pose (not registered)")
            pose = image.cam_from_world
            pose = pose() if callable(pose) else pose
        if not hasattr(pose, "matrix"):
            raise InputError(f"image: expected a pycolmap.Image or Rigid3d, got {type(image).__name__}")
        w2c = np.eye(4)
        w2c[:3, :] = np.asarray(pose.matrix(), dtype=np.float64)
        return cls(camera.width, camera.height, fx, fy, cx, cy, w2c, near, far)

    def to_colmap(self) -> tuple[Any, Any]:
        """``(pycolmap.Camera PINHOLE, pycolmap.Rigid3d cam_from_world)``."""
        from splatbench.interrupt import import_pycolmap

        pycolmap = import_pycolmap()

        camera = pycolmap.Camera(model="PINHOLE", width=self.width, height=self.height,
                                 params=[self.fx, self.fy, self.cx, self.cy])
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(self.world_to_camera[:3, :3]),
                                self.world_to_camera[:3, 3].copy())
        return camera, pose

    # ---------------------------------------------------------------- Blender
    @classmethod
    def from_blender(cls, frame: dict, camera_angle_x: float | None, width: int, height: int,
                     near: float = 0.01, far: float = 1e10) -> Camera:
        """A camera from a NeRF-synthetic / nerfstudio ``transforms.json`` frame.

        ``frame["transform_matrix"]`` is camera-to-world in OpenGL axes (x right, y up,
        z back). ``fx = 0.5·width / tan(camera_angle_x / 2)`` unless the frame has
        nerfstudio's ``fl_x`` (``camera_angle_x`` may then be None); ``fy`` is ``fl_y``
        or ``fx``; ``cx``/``cy`` default to the image centre.
        """
        if not isinstance(frame, dict) or "transform_matrix" not in frame:
            raise InputError("frame: expected a dict with a 'transform_matrix' key")
        c2w_gl = _matrix4("transform_matrix", frame["transform_matrix"])
        _check_rigid("transform_matrix", c2w_gl)
        width_, height_ = _positive_int("width", width), _positive_int("height", height)
        if "fl_x" in frame:
            fx = _finite_float("fl_x", frame["fl_x"], positive=True)
        else:
            if camera_angle_x is None:
                raise InputError("camera_angle_x: required when the frame has no 'fl_x'")
            angle = _finite_float("camera_angle_x", camera_angle_x, positive=True)
            if not angle < math.pi:
                raise InputError(f"camera_angle_x: expected radians in (0, pi), got {angle!r}")
            fx = 0.5 * width_ / math.tan(angle / 2)
        fy = _finite_float("fl_y", frame["fl_y"], positive=True) if "fl_y" in frame else fx
        cx = _finite_float("cx", frame["cx"]) if "cx" in frame else width_ / 2
        cy = _finite_float("cy", frame["cy"]) if "cy" in frame else height_ / 2
        w2c = _rigid_inverse(c2w_gl @ _OPENGL_FLIP)
        return cls(width_, height_, fx, fy, cx, cy, w2c, near, far)

    def to_blender(self) -> tuple[dict, float]:
        """``(frame, camera_angle_x)`` for a ``transforms.json``.

        ``frame["transform_matrix"]`` is camera-to-world in OpenGL axes, as nested
        lists; ``camera_angle_x = 2·atan(0.5·W / fx)`` in radians. When ``camera_angle_x``
        alone does not describe the intrinsics (``fy != fx`` or an off-centre principal
        point), the frame also carries nerfstudio's ``fl_x, fl_y, cx, cy, w, h``.
        """
        frame: dict[str, Any] = {"transform_matrix": (self.camera_to_world @ _OPENGL_FLIP).tolist()}
        if self.fy != self.fx or self.cx != self.width / 2 or self.cy != self.height / 2:
            frame.update(fl_x=self.fx, fl_y=self.fy, cx=self.cx, cy=self.cy, w=self.width, h=self.height)
        return frame, 2 * math.atan(0.5 * self.width / self.fx)


# ------------------------------------------------------------------ Mitsuba helpers
def _focal_from_fov(fov_deg: float, axis: str, width: int, height: int) -> float:
    """Focal length in pixels from Mitsuba's ``fov`` / ``fov_axis`` (square pixels)."""
    if not 0 < fov_deg < 180:
        raise InputError(f"fov: expected degrees in (0, 180), got {fov_deg!r}")
    extent = {"x": width, "y": height, "diagonal": math.hypot(width, height),
              "smaller": min(width, height), "larger": max(width, height)}.get(axis)
    if extent is None:
        raise InputError(f"fov_axis: expected one of x, y, diagonal, smaller, larger, got {axis!r}")
    return 0.5 * extent / math.tan(math.radians(fov_deg) / 2)


def _camera_from_mitsuba_dict(d: dict) -> Camera:
    if d.get("type") != "perspective":
        raise InputError(f"sensor.type: expected 'perspective', got {d.get('type')!r}")
    film = d.get("film", {})
    width = _positive_int("film.width", film.get("width", 768))  # Mitsuba's hdrfilm defaults
    height = _positive_int("film.height", film.get("height", 576))
    if "fov" not in d:
        raise InputError("sensor.fov: missing (focal_length strings are not supported)")
    f = _focal_from_fov(_finite_float("fov", d["fov"], positive=True), d.get("fov_axis", "x"), width, height)
    off_x = _finite_float("principal_point_offset_x", d.get("principal_point_offset_x", 0.0))
    off_y = _finite_float("principal_point_offset_y", d.get("principal_point_offset_y", 0.0))
    to_world = _matrix4("to_world", d["to_world"]) if "to_world" in d else np.eye(4)
    _check_rigid("to_world", to_world)
    w2c = _rigid_inverse(to_world @ _MITSUBA_FLIP)
    return Camera(width, height, f, f, width * (0.5 - off_x), height * (0.5 - off_y), w2c,
                  d.get("near_clip", 0.01), d.get("far_clip", 1e4))


def _camera_from_mitsuba_sensor(sensor: Any) -> Camera:
    mi = mitsuba(variant=None)
    class_name = sensor.class_name() if hasattr(sensor, "class_name") else type(sensor).__name__
    if class_name != "PerspectiveCamera":
        raise InputError(f"sensor: expected a Mitsuba 'perspective' sensor, got {class_name}")
    film = sensor.film()
    size, crop = [int(v) for v in film.size()], [int(v) for v in film.crop_size()]
    if size != crop:
        raise InputError(f"sensor.film: crop windows are not supported (size {size}, crop {crop})")
    params = mi.traverse(sensor)
    width, height = size
    f = 0.5 * width / math.tan(math.radians(_scalar(params["x_fov"])) / 2)
    off_x = _scalar(params["principal_point_offset_x"])
    off_y = _scalar(params["principal_point_offset_y"])
    to_world = _matrix4("to_world", sensor.world_transform())
    _check_rigid("to_world", to_world)
    w2c = _rigid_inverse(to_world @ _MITSUBA_FLIP)
    return Camera(width, height, f, f, width * (0.5 - off_x), height * (0.5 - off_y), w2c,
                  _scalar(sensor.near_clip()), _scalar(sensor.far_clip()))
