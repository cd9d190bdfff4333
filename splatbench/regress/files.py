"""The snapshot format, and taking one (`snapshot`).

A snapshot is a folder::

    DIR/snapshot.json           what it is (below)
    DIR/scenes/NAME.npz         per scene: the quantities, and the oracle's bands

``snapshot.json``: ``format`` ("splatbench-snapshot"), ``format_version`` (1), ``scene_set``
and ``scene_set_version`` (`splatbench.regress.snapshot_scenes`), ``selected`` (only in a snapshot of
some scenes of the set: their names), ``backend`` (name, version, spec,
description, the declared conventions, outputs, gradients), ``versions`` (splatbench, numpy,
torch, drjit, python), ``device``, and ``scenes``: per scene its ``name``, ``file``,
``sha256`` (of the npz), ``n`` (Gaussians), ``width``, ``height`` and ``quantities`` (name ->
shape). Each npz holds one float64 array per quantity (``rgb`` [H, W, 3], ``alpha`` [H, W],
``depth`` [H, W], ``grad_<group>`` shaped like the group) and the oracle's bands
(``band`` [H, W] bool, ``tie_slack`` [H, W], ``grad_band`` [N] bool, ``grad_weight`` [H, W]).
Plain NumPy ``.npy`` members in a zip (readable by ``numpy.load(..., allow_pickle=False)``),
written with fixed timestamps, and rendered with torch on one thread and its deterministic
algorithms: two snapshots of the same code on the same machine are byte for byte equal.
Nothing is unpickled when read; every member's shape is checked against the file's size
(`splatbench.safeio.read_npz`), against the JSON and against the scene it claims to be.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from splatbench.backends.base import Backend
from splatbench.errors import InputError
from splatbench.fsutil import building_dir
from splatbench.regress.snapshot_scenes import SCENE_SET_VERSION, Scene, scene_set

SNAPSHOT_FORMAT = "splatbench-snapshot"
FORMAT_VERSION = 1
MANIFEST = "snapshot.json"
BAND_KEYS = ("band", "tie_slack", "grad_band", "grad_weight")
_EPOCH = (1980, 1, 1, 0, 0, 0)  # zip timestamps fixed: a snapshot is a function of the code alone
MAX_MANIFEST_BYTES = 10_000_000


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """A plain, deterministic ``.npz`` (stored members, fixed timestamps, sorted keys, no pickle)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for key in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[key]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, buf.getvalue())


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _versions() -> dict[str, str]:
    from splatbench.versions import package_version

    return {"splatbench": package_version("splatbench"), "numpy": np.__version__,
            "torch": package_version("torch"), "drjit": package_version("drjit"),
            "python": ".".join(map(str, sys.version_info[:3]))}


def resolve_device(backend: Backend, device: str) -> str:
    """"cpu" or "cuda" for ``device`` ("auto": CUDA when torch sees a GPU and the backend lists it), as conform."""
    from splatbench.devices import check_device, torch_device

    devices = backend.info.devices
    if check_device(device) == "auto":
        device = "cuda" if "cuda" in devices and torch_device("auto") == "cuda" else \
            ("cpu" if "cpu" in devices else devices[0])
    if device == "cuda":
        torch_device("cuda")
    if device not in devices:
        raise InputError(f"device: backend {backend.name!r} runs on {', '.join(devices)}, not {device!r}")
    return device


def backend_record(backend: Backend, spec: str) -> dict:
    from splatbench.conform import backend_version

    info = backend.info
    return {"name": info.name, "spec": spec, "version": backend_version(backend), "description": info.description,
            "declared": {k: getattr(info, k) for k in info.declared}, "conventions": info.reference_options(),
            "outputs": list(info.outputs), "gradients": bool(info.gradients), "exact": bool(info.exact)}


def snapshot(backend, out: str | Path, *, scenes: str = "full", only: tuple[str, ...] | None = None,
             device: str = "auto", progress=None) -> Path:
    """Render every scene of set ``scenes`` (or ``only`` the scenes of these names in it) with ``backend``
    (a spec, `Backend` or callable) and write the snapshot folder ``out`` (module doc); `check` then
    checks those scenes. An existing snapshot there is replaced; a folder holding
    anything else is refused. A backend that raises is one `InputError` line naming the scene: a
    snapshot is a reference, never taken of a backend that fails."""
    from splatbench.backends.registry import get_backend
    from splatbench.verification.calls import Fault, check_signature
    from splatbench.regress.measure import bands, quantities, render

    spec = backend if isinstance(backend, str) else getattr(backend, "name", repr(backend))
    backend = get_backend(backend)
    out = Path(out)
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not (out / MANIFEST).is_file())):
        raise InputError(f"--out: {str(out)!r} exists and is not a snapshot folder; choose a new or empty folder")
    say = progress or (lambda line: None)
    if only is not None and not only:
        raise InputError("--scene: no scene named; name one or more, or leave --scene out for the whole set")
    chosen = scene_set(scenes, only)  # an unknown name: one line, before anything renders
    device = resolve_device(backend, device)
    try:
        check_signature(backend)
    except Fault as fault:
        raise InputError(f"backend {backend.name!r}: {fault}") from None
    with building_dir(out) as tmp:
        (tmp / "scenes").mkdir()
        records = []
        with _deterministic_torch():
            for scene in chosen:
                try:
                    values = render(backend, scene, device)
                except Fault as fault:
                    raise InputError(f"backend {backend.name!r} fails on scene {scene.name!r}: {fault}; a snapshot is "
                                     f"only taken of a backend that renders every scene") from None
                b = bands(backend.info, scene)
                arrays = {**values, "band": b.band, "tie_slack": b.tie_slack, "grad_band": b.grad_band,
                          "grad_weight": b.grad_weight}
                path = tmp / "scenes" / f"{scene.name}.npz"
                write_npz(path, arrays)
                records.append({"name": scene.name, "file": f"scenes/{scene.name}.npz", "sha256": sha256(path),
                                "n": scene.n, "width": scene.camera.width, "height": scene.camera.height,
                                "quantities": {q: list(values[q].shape) for q in quantities(backend)}})
                say(f"{scene.name}: {len(values)} quantities")
        manifest = {"format": SNAPSHOT_FORMAT, "format_version": FORMAT_VERSION, "scene_set": scenes,
                    "scene_set_version": SCENE_SET_VERSION, "backend": backend_record(backend, spec),
                    "versions": _versions(), "device": device, "scenes": records}
        if only is not None:
            manifest["selected"] = [s.name for s in chosen]
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1, sort_keys=True, default=str) + "\n",
                                    encoding="utf-8")
    return out


@contextlib.contextmanager
def _deterministic_torch():
    """Torch on one thread with deterministic algorithms while a snapshot renders (restored after):
    a multi-threaded CPU reduction (gsplat's PyTorch path) sums in a varying order, which moves a
    float32 result by ~1e-7 between runs, and a snapshot is a function of the code alone."""
    import torch  # a snapshot's inputs are torch tensors (measure.render): torch is loaded anyway

    threads, deterministic = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    warn_only = torch.is_deterministic_algorithms_warn_only_enabled()
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True, warn_only=True)  # an op without a deterministic kernel still runs
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(deterministic, warn_only=warn_only)
        torch.set_num_threads(threads)


@dataclass(frozen=True)
class Snapshot:
    """A snapshot as read and verified: its manifest, and per scene name the arrays (lazily read)."""

    folder: Path
    manifest: dict

    @property
    def scene_names(self) -> list[str]:
        return [s["name"] for s in self.manifest["scenes"]]

    def scenes(self) -> list[Scene]:
        """The scenes this snapshot holds: its set's, or those of it that were selected."""
        return scene_set(self.manifest["scene_set"], self.manifest.get("selected"))

    def record(self, name: str) -> dict:
        return next(s for s in self.manifest["scenes"] if s["name"] == name)

    def arrays(self, scene: Scene) -> dict[str, np.ndarray]:
        """The arrays of ``scene``, each checked against the manifest and the scene (one line if not)."""
        from splatbench.safeio import read_npz

        rec = self.record(scene.name)
        path = self.folder / rec["file"]
        where = f"snapshot {str(self.folder)!r}: {rec['file']}"
        if not path.is_file():
            raise InputError(f"{where}: missing; the snapshot is incomplete: take the snapshot again")
        if sha256(path) != rec["sha256"]:
            raise InputError(f"{where}: its SHA-256 is not the one snapshot.json records: the file was changed "
                             f"after the snapshot was taken; take the snapshot again")
        arrays = read_npz(path, what=where)
        H, W, N = scene.camera.height, scene.camera.width, scene.n
        expect = {**{q: tuple(s) for q, s in rec["quantities"].items()}, "band": (H, W), "tie_slack": (H, W),
                  "grad_band": (N,), "grad_weight": (H, W)}
        for key, shape in expect.items():
            if key not in arrays:
                raise InputError(f"{where}: missing array {key!r}")
            if tuple(arrays[key].shape) != shape:
                raise InputError(f"{where}: array {key!r} has shape {list(arrays[key].shape)}, expected "
                                 f"{list(shape)}")
            if arrays[key].dtype.kind not in "fb" or (arrays[key].dtype.kind == "f" and
                                                      not np.isfinite(arrays[key]).all()):
                raise InputError(f"{where}: array {key!r} is not finite numbers")
        extra = sorted(set(arrays) - set(expect))
        if extra:
            raise InputError(f"{where}: unexpected array {extra[0]!r}")
        return arrays


    def verify(self) -> None:
        """Check every scene file against the manifest (SHA-256, readable npz, shapes, finite values):
        one `InputError` line naming the first bad file, before any rendering."""
        for scene in self.scenes():
            self.arrays(scene)


def read_snapshot(folder: str | Path, scenes: list[Scene] | None = None) -> Snapshot:
    """Read and verify ``folder``'s manifest against this splatbench's scene set (module doc); one
    `InputError` line naming the file and the fix when it is missing, damaged, tampered with, or of
    another format or scene-set version."""
    from splatbench.fsutil import read_text
    from splatbench.safeio import file_size

    folder = Path(folder)
    path = folder / MANIFEST
    if folder.is_file():  # a file is never a snapshot: name the folder that holds one
        hint = (f"give the folder holding it: --against {folder.parent}" if folder.name == MANIFEST else
                f"give the folder `splatbench snapshot BACKEND --out DIR` wrote (it holds {MANIFEST})")
        raise InputError(f"--against: {str(folder)!r} is a file, not a snapshot folder; {hint}")
    if not folder.is_dir():
        raise InputError(f"--against: no snapshot folder {str(folder)!r} (take one with `splatbench snapshot BACKEND "
                         f"--out {folder}`)")
    if file_size(path, f"--against: {MANIFEST}") > MAX_MANIFEST_BYTES:
        raise InputError(f"--against: {path}: larger than {MAX_MANIFEST_BYTES} bytes; not a snapshot manifest")
    try:
        manifest = json.loads(read_text(path, f"--against: {MANIFEST}"))
    except json.JSONDecodeError as exc:
        raise InputError(f"--against: {path}: not valid JSON ({exc.msg} at line {exc.lineno}); take the snapshot "
                         f"again") from None
    where = f"--against: {path}"
    if not isinstance(manifest, dict) or manifest.get("format") != SNAPSHOT_FORMAT:
        raise InputError(f"{where}: not a splatbench snapshot (format {manifest.get('format') if isinstance(manifest, dict) else None!r})")
    if manifest.get("format_version") != FORMAT_VERSION:
        raise InputError(f"{where}: snapshot format version {manifest.get('format_version')!r}, this splatbench "
                         f"reads {FORMAT_VERSION}; take the snapshot again with this version")
    if manifest.get("scene_set_version") != SCENE_SET_VERSION:
        raise InputError(f"{where}: taken on scene set version {manifest.get('scene_set_version')!r}, this splatbench "
                         f"has version {SCENE_SET_VERSION} (other scenes): take the snapshot again (`splatbench "
                         f"snapshot BACKEND --out {folder}`) from the code you trust")
    for key, kind in (("scene_set", str), ("backend", dict), ("scenes", list), ("device", str)):
        if not isinstance(manifest.get(key), kind):
            raise InputError(f"{where}: field {key!r} missing or of the wrong type; the file is damaged")
    selected = manifest.get("selected")
    if selected is not None and not (isinstance(selected, list) and selected and
                                     all(isinstance(n, str) for n in selected)):
        raise InputError(f"{where}: field 'selected' is not a list of scene names; the file is damaged")
    if scenes is None:
        try:
            scenes = scene_set(manifest["scene_set"], selected)
        except InputError as exc:
            raise InputError(f"{where}: {exc}; the file is damaged or of another splatbench") from None
    expected = [s.name for s in scenes]
    names = []
    for rec in manifest["scenes"]:
        if not isinstance(rec, dict) or not all(k in rec for k in ("name", "file", "sha256", "quantities")):
            raise InputError(f"{where}: a scene record is incomplete; the file is damaged")
        if rec["file"] != f"scenes/{rec['name']}.npz":
            raise InputError(f"{where}: scene {rec['name']!r} names the file {rec['file']!r}, not "
                             f"'scenes/{rec['name']}.npz'; the file is damaged")
        names.append(rec["name"])
    if names != expected:
        missing = sorted(set(expected) - set(names)) or sorted(set(names) - set(expected))
        raise InputError(f"{where}: its scenes are not those of set {manifest['scene_set']!r} version "
                         f"{SCENE_SET_VERSION} (e.g. {missing[0] if missing else names[0]!r}); the file is damaged")
    return Snapshot(folder, manifest)
