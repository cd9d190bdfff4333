"""The fuzzing campaign: every reader of files from others, fed mutated valid files.

Each reader gets a small valid input (a file, or a dataset folder whose files are
mutated one per case) and `tests/fuzzing.py`'s mutations; the contract is checked per
case (`fuzzing.run_case`: data that passes the reader's check, or a one-line
`InputError`; nothing else, within a time and memory bound). Cases are derandomized,
so a run is reproducible and its figures are those of docs/robustness.md:

    python -m pytest tests/test_fuzz.py -q                    # default: N cases per reader
    python -m pytest tests/test_fuzz.py -q -m slow            # 10 N per reader
    SPLATBENCH_FUZZ_STATS=fuzz.json python -m pytest tests/test_fuzz.py -q -m "slow or not slow"

Captures from others (transforms.json in the instant-ngp and NeRF-synthetic forms, COLMAP
text models) also get structure-aware cases (`tests/structured_fuzzing.py`): per mutation
class, `STRUCTURED_CASES` cases in the default suite and 10 times as many in the slow one.

Whatever the campaign found is kept as a regression case in tests/test_robustness.py.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.fuzzing import mutated, run_case, write_stats
from splatbench import Gaussians

# ------------------------------------------------------------------------ seeds


def _gaussians(n: int = 3, degree: int = 1) -> Gaussians:
    rng = np.random.default_rng(0)
    k = (degree + 1) ** 2
    return Gaussians(rng.normal(size=(n, 3)), rng.normal(-2, 0.3, (n, 3)), rng.normal(size=(n, 4)),
                     rng.normal(size=n), rng.normal(0, 0.3, (n, k, 3)))


def _png(path: Path, w: int = 6, h: int = 4, alpha: bool = False) -> None:
    from PIL import Image

    rng = np.random.default_rng(1)
    Image.fromarray(rng.integers(0, 255, (h, w, 4 if alpha else 3), dtype=np.uint8)).save(path)


def _colmap(folder: Path, text: bool) -> None:
    from splatbench.cameras import Camera
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()
    rec = pycolmap.Reconstruction()
    camera, _ = Camera(6, 4, 5.0, 5.0, 3.0, 2.0, np.eye(4)).to_colmap()
    camera.camera_id = 1
    rec.add_camera_with_trivial_rig(camera)
    (folder / "images").mkdir(parents=True)
    for i in range(2):
        pose = np.eye(4)
        pose[0, 3] = 0.1 * i
        image = pycolmap.Image(name=f"v{i}.png", keypoints=np.array([[1.5, 1.5], [2.5, 3.0]]), camera_id=1,
                               image_id=i + 1)
        rec.add_image_with_trivial_frame(image, Camera(6, 4, 5.0, 5.0, 3.0, 2.0, pose).to_colmap()[1])
        _png(folder / "images" / f"v{i}.png")
    for j in range(2):
        track = pycolmap.Track()
        track.add_element(1, j)
        track.add_element(2, j)
        rec.add_point3D(np.array([0.1 * j, 0.0, 2.0]), track, np.array([10, 20, 30], np.uint8))
    sparse = folder / "sparse" / "0"
    sparse.mkdir(parents=True)
    rec.write_text(str(sparse)) if text else rec.write(str(sparse))


def _blender(folder: Path) -> None:
    from plyfile import PlyData, PlyElement

    folder.mkdir(parents=True)
    (folder / "images").mkdir()
    frames = []
    for i in range(2):
        _png(folder / "images" / f"r_{i}.png", alpha=i == 1)
        m = np.eye(4)
        m[2, 3] = 3.0 + i
        frames.append({"file_path": f"images/r_{i}", "transform_matrix": m.tolist()})
    meta = {"camera_angle_x": 0.8, "w": 6, "h": 4, "ply_file_path": "points3D.ply", "frames": frames}
    (folder / "transforms.json").write_text(json.dumps(meta, indent=1))
    vertex = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"),
                                ("blue", "u1")])
    vertex["x"] = [0.0, 0.5, -0.5]
    vertex["red"] = [1, 2, 3]
    PlyData([PlyElement.describe(vertex, "vertex")]).write(str(folder / "points3D.ply"))


def _garden_subset(path: Path) -> None:
    """Real data: the first 16 SfM points and all 3 cameras of the shipped garden capture."""
    from splatbench.workloads import GARDEN_SFM

    with np.load(GARDEN_SFM) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["means3d"], arrays["colors"] = arrays["means3d"][:16], arrays["colors"][:16]
    np.savez_compressed(path, **arrays)


def _checkpoint(path: Path) -> None:
    from splatbench.strategies.default import DefaultStrategy
    from splatbench.train import checkpoint as ck
    from splatbench.train.result import HistoryPoint
    from splatbench.train.sh_schedule import ShSchedule

    params = {"means": torch.zeros(2, 3)}
    state = DefaultStrategy().initialize_state(params)
    torch.save({"format": ck.CHECKPOINT_FORMAT, "config": {"seed": 0}, "train_names": ["a.png"], "step_index": 3,
                "params": {"means": torch.ones(2, 3)}, "strategy_state": ck._encode(state),
                "sh": ck._encode(ShSchedule(3, 10)), "order": [1, 0], "generator": torch.Generator().get_state(),
                "extra": ck._encode({"history": [HistoryPoint(0, 0.5, 20.0, 2)], "loop_seconds": 1.0})}, path)


def _record(folder: Path) -> None:
    from splatbench.experiments.store import RunRecord

    rec = RunRecord(run_id="0123456789abcdef", experiment="exp", kind="tests.kinds_for_tests:DUMMY", scene="alpha", seed=0, status="done",
                    config={"x": 1.0, "nested": {"y": [1, 2]}, "scene": "alpha", "seed": 0},
                    labels={"x": "1.0"}, metrics={"value": 2.5, "n": 3}, curves={"step": [1, 2]}, seconds=0.5,
                    started="2026-01-01T00:00:00+00:00", finished="2026-01-01T00:00:01+00:00", worker="h:1")
    folder.mkdir(parents=True)
    (folder / f"{rec.run_id}.json").write_text(json.dumps(rec.to_dict(), indent=1, sort_keys=True))  # as write_record


# ---------------------------------------------------------------------- checks


def _finite_gaussians(g) -> None:
    assert isinstance(g, Gaussians)
    for a in (g.means, g.log_scales, g.quats, g.opacity_logits, g.sh):
        assert np.isfinite(a).all()


def _valid_dataset(ds) -> None:
    from tests.structured_fuzzing import inside

    for split in (ds.train, ds.test):
        assert all(inside(ds.root, name) for name in split.names), split.names  # nothing read from outside
        assert split.images.dtype == np.float32 and np.isfinite(split.images).all()
        assert split.images.size == 0 or (split.images.min() >= 0 and split.images.max() <= 1)
        if split.alphas is not None:
            assert split.alphas.size == 0 or (split.alphas.min() >= 0 and split.alphas.max() <= 1)
        for cam in split.cameras:
            assert np.isfinite(cam.world_to_camera).all() and cam.width > 0 and cam.height > 0
    if ds.points is not None:
        assert np.isfinite(ds.points.xyz).all() and ds.points.rgb.dtype == np.uint8


def _valid_workload(w) -> None:
    _finite_gaussians(w.gaussians)
    assert np.isfinite(w.camera.world_to_camera).all()


def _valid_checkpoint(state) -> None:
    assert isinstance(state, dict) and state["format"].startswith("splatbench-checkpoint/")


def _valid_record(rec) -> str | None:
    from splatbench.experiments.store import RunRecord

    if rec is None:
        return "refused (None)"  # the runner reports the file and redoes the run
    assert isinstance(rec, RunRecord)
    rec.row()
    return None


def _valid_owner(owner) -> str | None:
    from splatbench.experiments.claims import Owner

    if owner is None:
        return "refused (None)"  # no owner: held while recent, then stale
    assert isinstance(owner, Owner) and owner.pid > 0
    return None


def _valid_array(a) -> None:
    assert isinstance(a, np.ndarray) and a.dtype != object


# ---------------------------------------------------------------------- readers


@dataclass(frozen=True)
class Reader:
    build: Callable[[Path], None]      # writes the valid seed into an empty folder
    read: Callable[[Path], object]     # reads the (mutated) folder
    check: Callable[[object], str | None]  # asserts what a successful read must satisfy
    cases: int                         # default-suite cases (the slow suite runs 10x)
    text: tuple[str, ...] = ()         # files mutated with the text operations too
    members: bool = False              # npz: also mutate one member's .npy bytes inside a valid zip


def _load(folder: Path):
    from splatbench.data import load_dataset

    return load_dataset(folder, test_every=2)


def _load_llff(folder: Path):
    from splatbench.data import load_dataset

    return load_dataset(folder, test_every=2, downscale=2)  # the seed's images_2/ and masks_2/


def _ply_ascii(folder: Path) -> None:
    from plyfile import PlyData, PlyElement

    from splatbench.ply import to_vertex_array

    folder.mkdir(parents=True, exist_ok=True)
    PlyData([PlyElement.describe(to_vertex_array(_gaussians(2, 0)), "vertex")], text=True,
            comments=["splatbench sh_degree 0"]).write(str(folder / "m.ply"))


def _in(folder: Path, write: Callable[[Path], None], name: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    write(folder / name)


def _workload(path: Path) -> None:
    from splatbench.workloads import save_npz, synthetic

    save_npz(synthetic(3, 8, 6, seed=0), path)


def _read_record(folder: Path):
    from splatbench.experiments.store import read_record

    return read_record(folder / "0123456789abcdef.json")


def _read_claim(folder: Path):
    from splatbench.experiments.claims import Owner

    return Owner.parse((folder / "c.claim").read_bytes().decode("utf-8", "replace"))


def _claim(path: Path) -> None:
    from splatbench.experiments.claims import Owner

    path.write_text(Owner.me().text())


def _depth(path: Path) -> None:
    np.save(path, np.linspace(0, 2, 24, dtype=np.float32).reshape(4, 6))


def _jpeg(path: Path) -> None:
    from PIL import Image

    Image.fromarray(np.random.default_rng(2).integers(0, 255, (8, 8, 3), dtype=np.uint8)).save(path, quality=80)


def _read_image(folder: Path):
    from splatbench.safeio import read_image

    name = next(p for p in sorted(folder.iterdir()))
    return read_image(name, what=name.name)


READERS: dict[str, Reader] = {
    "ply-binary": Reader(lambda f: _in(f, _gaussians(12, 1).to_ply, "m.ply"),  # 12 rows: the data outweighs the header
                         lambda f: Gaussians.from_ply(f / "m.ply"), _finite_gaussians, 200),
    "ply-ascii": Reader(_ply_ascii, lambda f: Gaussians.from_ply(f / "m.ply"), _finite_gaussians, 200,
                        text=("m.ply",)),
    "colmap-binary": Reader(lambda f: _colmap(f, text=False), _load, _valid_dataset, 120),
    "colmap-text": Reader(lambda f: _colmap(f, text=True), _load, _valid_dataset, 120,
                          text=tuple(f"sparse/0/{p}.txt" for p in ("cameras", "images", "points3D", "rigs",
                                                                   "frames"))),
    "blender": Reader(_blender, _load, _valid_dataset, 120, text=("transforms.json",)),
    "npz-workload": Reader(lambda f: _in(f, _workload, "w.npz"),
                           lambda f: __import__("splatbench.workloads").workloads.load_npz(f / "w.npz"),
                           _valid_workload, 200, members=True),
    "npz-garden": Reader(lambda f: _in(f, _garden_subset, "g.npz"),
                         lambda f: __import__("splatbench.workloads").workloads.load_npz(f / "g.npz", view=1),
                         _valid_workload, 200, members=True),
    "npy-depth": Reader(lambda f: _in(f, _depth, "d.npy"),
                        lambda f: __import__("splatbench.safeio").safeio.read_npy(f / "d.npy", what="d.npy"),
                        _valid_array, 200),
    "image": Reader(lambda f: (_in(f, _png, "a.png")), _read_image, _valid_array, 200),
    "image-jpeg": Reader(lambda f: (_in(f, _jpeg, "a.jpg")), _read_image, _valid_array, 200),
    "checkpoint": Reader(lambda f: _in(f, _checkpoint, "c.pt"),
                         lambda f: __import__("splatbench.train.checkpoint").train.checkpoint.read_checkpoint(
                             f / "c.pt"), _valid_checkpoint, 200),
    "result-record": Reader(_record, _read_record, _valid_record, 200, text=("0123456789abcdef.json",)),
    "claim": Reader(lambda f: _in(f, _claim, "c.claim"), _read_claim, _valid_owner, 200, text=("c.claim",)),
}


def _files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _rezip(data: bytes, member: str, content: bytes) -> bytes:
    """The npz ``data`` with ``member``'s bytes replaced (a valid zip around a hostile array)."""
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as dst:
        for info in src.infolist():
            dst.writestr(info.filename, content if info.filename == member else src.read(info))
    return out.getvalue()


def campaign(name: str, tmp_path: Path, cases: int) -> None:
    reader = READERS[name]
    seed = tmp_path / "seed"
    reader.build(seed)
    files = _files(seed)
    total = sum(len(b) for b in files.values())
    reader.read(seed)  # the seed itself reads, and passes the check
    reader.check(reader.read(seed))
    work = tmp_path / "case"

    @settings(max_examples=cases, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.data())
    def case(data):
        rel = data.draw(st.sampled_from(sorted(files)), label="file")
        content = files[rel]
        if reader.members and data.draw(st.booleans(), label="inside a member"):
            with zipfile.ZipFile(io.BytesIO(content)) as z:
                member = data.draw(st.sampled_from(sorted(z.namelist())), label="member")
                inner = z.read(member)
            content = _rezip(content, member, data.draw(mutated(inner), label="mutated member"))
        else:
            content = data.draw(mutated(content, text=rel in reader.text), label="mutated")
        if work.exists():
            shutil.rmtree(work)
        shutil.copytree(seed, work)
        (work / rel).write_bytes(content)
        run_case(name, lambda: reader.read(work), reader.check, total + len(content))

    case()


@pytest.fixture(scope="module", autouse=True)
def _stats():
    yield
    if os.environ.get("SPLATBENCH_FUZZ_STATS"):
        write_stats(os.environ["SPLATBENCH_FUZZ_STATS"])


@pytest.mark.parametrize("name", sorted(READERS))
def test_fuzz(name, tmp_path):
    campaign(name, tmp_path, READERS[name].cases)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(READERS))
def test_fuzz_slow(name, tmp_path):
    campaign(name, tmp_path, 10 * READERS[name].cases)


# ------------------------------------------------------------- structure-aware: captures from others

#: Cases per mutation class (tests/structured_fuzzing.py) in the default suite; the slow suite runs 10x.
#: 15 classes for each transforms.json form and 13 for COLMAP text: 344 cases, 3440 in the slow suite.
STRUCTURED_CASES = 8
#: LLFF's cases are cheaper (an .npy of 4 rows, 6x4 images): 7 classes x 80 = 560, 5600 in the slow suite.
LLFF_CASES = 80


def structured_campaign(kind: str, tmp_path: Path, per_class: int) -> None:
    from tests import structured_fuzzing as sf

    seed = tmp_path / "seed"
    sf.SEEDS[kind](seed)
    load = _load_llff if kind == "llff" else _load
    _valid_dataset(load(seed))  # the seed itself loads and passes the check
    total = sum(len(b) for b in _files(seed).values())
    for klass in sf.CLASSES[kind]:
        for number in range(per_class):
            what = sf.mutate(kind, klass, number, seed, tmp_path / "case")
            try:
                run_case(f"{kind}: {klass}", lambda: load(tmp_path / "case" / "capture"), _valid_dataset,
                         2 * total)
            except BaseException as exc:  # name the case that reproduces it
                raise AssertionError(f"{sf.describe(kind, klass, number)}: {what}: {type(exc).__name__}: "
                                     f"{str(exc)[:300]}") from exc


@pytest.fixture
def _cache(tmp_path, monkeypatch):
    """Undistorted images of the cases go to a temporary cache, not ~/.cache."""
    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))


@pytest.mark.parametrize("kind", ["ngp", "blender", "colmap-text", "llff"])
def test_fuzz_structured(kind, tmp_path, _cache):
    structured_campaign(kind, tmp_path, LLFF_CASES if kind == "llff" else STRUCTURED_CASES)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["ngp", "blender", "colmap-text", "llff"])
def test_fuzz_structured_slow(kind, tmp_path, _cache):
    structured_campaign(kind, tmp_path, 10 * (LLFF_CASES if kind == "llff" else STRUCTURED_CASES))
