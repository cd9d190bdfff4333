"""Files from others are data, never code (docs/robustness.md).

A checkpoint carrying a pickle payload is refused and the payload never runs; files
claiming 10^11 elements in under 1 KB are refused in one line with little memory; a
damaged result file of a grid is reported and its run redone; and the regression cases
of what the fuzzing campaign (tests/test_fuzz.py) found.
"""

from __future__ import annotations

import io
import json
import struct
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from splatbench.errors import InputError
from tests.assertions import one_line_error
from tests.test_fuzz import _colmap, _gaussians

REPO = Path(__file__).resolve().parents[1]
#: Peak resident memory allowed to a process that reads one hostile file (the issue's bound).
PEAK_MB = 300


class Payload:
    """Unpickling this runs ``exec`` on code that writes ``marker``."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return exec, (f"open({str(self.marker)!r}, 'w').write('payload ran')",)


def payload_checkpoint(path: Path, marker: Path) -> Path:
    from splatbench.train.checkpoint import CHECKPOINT_FORMAT

    torch.save({"format": CHECKPOINT_FORMAT, "strategy_state": Payload(marker)}, path)
    return path


def test_the_payload_is_live_when_unpickled(tmp_path):
    """Control: the file below does run code when unpickled the old way (weights_only=False)."""
    marker = tmp_path / "ran.txt"
    torch.load(payload_checkpoint(tmp_path / "p.pt", marker), weights_only=False)
    assert marker.read_text() == "payload ran"


def test_train_resume_refuses_a_pickle_payload_in_one_line_and_never_runs_it(tmp_path):
    from tests.test_one_line_errors import assert_one_line

    from splatbench.scenes.render import render_dataset

    data = render_dataset("diffuse", tmp_path / "ds", resolution=16, views=4, spp=1, progress=False).path
    marker = tmp_path / "ran.txt"
    ckpt = payload_checkpoint(tmp_path / "their.pt", marker)
    line = assert_one_line(["train", data, "--out", tmp_path / "o", "--quiet", "--set", "iterations=2",
                            "--resume", ckpt], "is not a readable checkpoint")
    assert "refused without running them" in line and str(ckpt) in line
    assert not marker.exists()


def test_an_old_pickled_checkpoint_is_refused(tmp_path):
    """Format 1 pickled the trainer's objects: such a file is refused, nothing rebuilt."""
    from splatbench.strategies.default import DefaultStrategy
    from splatbench.train.checkpoint import read_checkpoint

    path = tmp_path / "old.pt"
    torch.save({"format": "splatbench-checkpoint/1",
                "strategy_state": DefaultStrategy().initialize_state({"means": torch.zeros(2, 3)})}, path)
    one_line_error(lambda: read_checkpoint(path), "old.pt", "refused without running them")
    torch.save({"format": "splatbench-checkpoint/1"}, path)  # plain data, but another format
    one_line_error(lambda: read_checkpoint(path), "is not a splatbench-checkpoint/2 checkpoint")


def test_a_checkpoint_in_another_container_is_refused_before_its_counts_are_used(tmp_path):
    """torch.load also reads torch's legacy (pre-zip) format, whose storage sizes are counts in the
    file allocated before anything is read (the fuzz campaign's 27 KB file asked for 84 MB), and a
    zip member may be compressed (inflating without bound): `save_checkpoint` writes neither, so both
    are refused in one line, allocating no more than a few times the file."""
    import tracemalloc
    import zipfile

    from splatbench.train.checkpoint import read_checkpoint

    legacy = tmp_path / "legacy.pt"
    torch.save({"format": "splatbench-checkpoint/2", "x": torch.zeros(1000)}, legacy,
               _use_new_zipfile_serialization=False)
    tracemalloc.start()
    one_line_error(lambda: read_checkpoint(legacy), "legacy.pt", "not torch's zip archive")
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 1_000_000  # the refusal reads the zip directory only (no such directory here)
    good = tmp_path / "good.pt"
    torch.save({"format": "splatbench-checkpoint/2", "x": torch.zeros(1000)}, good)
    deflated = tmp_path / "deflated.pt"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(deflated, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            dst.writestr(item.filename, src.read(item))
    one_line_error(lambda: read_checkpoint(deflated), "deflated.pt", "is compressed")
    # the fuzz case: zipfile finds the directory at the end, but torch.load goes by the first 4 bytes
    # (not "PK\x03\x04": the legacy reader), so the file is refused by those bytes too
    renamed = tmp_path / "renamed.pt"
    renamed.write_bytes(b"X\x00\x00\x00" + good.read_bytes()[4:])
    assert zipfile.is_zipfile(renamed)
    one_line_error(lambda: read_checkpoint(renamed), "renamed.pt", "not torch's zip archive")


def test_checkpoint_objects_round_trip_as_data(tmp_path):
    """MCMC's state (generator, stats, noise) and the SH schedule survive `_encode`, a
    weights_only load and `_decode`; a name outside the allowlist is refused."""
    from splatbench.strategies.mcmc import MCMCState, MCMCStats
    from splatbench.train import checkpoint as ck
    from splatbench.train.sh_schedule import ShSchedule

    gen = torch.Generator()
    gen.manual_seed(7)
    torch.rand(3, generator=gen)
    state = MCMCState(gen, None, True, MCMCStats(3, 1, 2, 10), [MCMCStats(3, 1, 2, 10)], torch.ones(2, 3))
    path = tmp_path / "s.pt"
    torch.save({"s": ck._encode(state), "sh": ck._encode(ShSchedule("auto", 5))}, path)
    loaded = torch.load(path, weights_only=True)
    back, sh = ck._decode(loaded["s"]), ck._decode(loaded["sh"])
    assert isinstance(back, MCMCState) and back.last == state.last and back.history == state.history
    assert torch.equal(back.generator.get_state(), gen.get_state()) and torch.equal(back.last_noise, state.last_noise)
    assert isinstance(sh, ShSchedule) and vars(sh) == vars(ShSchedule("auto", 5))
    with pytest.raises(ValueError, match="unknown object 'Popen'"):
        ck._decode({"__object__": "Popen", "fields": {}})


# --------------------------------------------------------------- hostile counts
def hostile_ply(path: Path) -> Path:
    from splatbench.ply import property_names

    header = "ply\nformat binary_little_endian 1.0\nelement vertex 100000000000\n"
    header += "".join(f"property float {n}\n" for n in property_names(0)) + "end_header\n"  # degree 0: 17
    path.write_bytes(header.encode() + b"\0" * 64)
    return path


def hostile_cameras_bin(folder: Path) -> Path:
    _colmap(folder, text=False)
    cameras = folder / "sparse" / "0" / "cameras.bin"
    cameras.write_bytes(struct.pack("<QiiQQ4d", 10**11, 1, 1, 6, 4, 5.0, 5.0, 3.0, 2.0))
    return folder


def hostile_npz(path: Path) -> Path:
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": (10**11,)})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        z.writestr("means.npy", header.getvalue() + b"\0" * 16)
    return path


READ = {
    "ply": "from splatbench import Gaussians; Gaussians.from_ply(PATH)",
    "cameras.bin": "from splatbench.data import load_dataset; load_dataset(PATH)",
    "npz": "from splatbench.workloads import load_npz; load_npz(PATH)",
}


@pytest.mark.parametrize("kind,make,size_of", [
    ("ply", lambda t: hostile_ply(t / "h.ply"), lambda p: p.stat().st_size),
    ("cameras.bin", lambda t: hostile_cameras_bin(t / "ds"), lambda p: (p / "sparse/0/cameras.bin").stat().st_size),
    ("npz", lambda t: hostile_npz(t / "h.npz"), lambda p: p.stat().st_size),
])
@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="reads VmHWM from /proc")
def test_a_file_claiming_1e11_elements_is_one_line_with_little_memory(tmp_path, kind, make, size_of):
    """Each read in a fresh process: one InputError line, peak resident memory under PEAK_MB.

    The peak is the process's VmHWM (/proc/self/status), not ru_maxrss: Linux keeps
    ru_maxrss across exec, so a child of this pytest process would report pytest's own."""
    path = make(tmp_path)
    assert size_of(path) < 1024
    code = textwrap.dedent(f"""
        import resource, sys
        from splatbench.errors import InputError
        PATH = {str(path)!r}
        try:
            {READ[kind]}
        except InputError as exc:
            print("ERROR", exc)
        hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0].split()[1]
        print("PEAK_MB", int(hwm) / 1024, "ru_maxrss_MB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
        """)
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and not out.stderr.strip(), out.stderr
    lines = out.stdout.splitlines()
    assert len(lines) == 2 and lines[0].startswith("ERROR ") and "100000000000" in lines[0], lines
    assert float(lines[1].split()[1]) < PEAK_MB, lines


def test_a_decompression_bomb_image_is_one_line(tmp_path):
    """A PNG header claiming 100000 x 100000 pixels (10^10) in 57 bytes: refused at open."""
    import zlib

    from splatbench.safeio import read_image

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    path = tmp_path / "bomb.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 100000, 100000, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))
    one_line_error(lambda: read_image(path, what="bomb.png"), "bomb.png", "decompression bomb")


def test_colmap_model_ids_agree_with_pycolmap():
    from splatbench.data.colmap_bounds import CAMERA_MODEL_PARAMS
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()
    ours = {int(v): pycolmap.Camera.create_from_model_name(0, name, 1.0, 1, 1).params.size
            for name, v in pycolmap.CameraModelId.__members__.items() if name != "INVALID"}
    assert ours == CAMERA_MODEL_PARAMS


# --------------------------------------------------------------- grid files
def test_a_damaged_result_file_is_reported_and_its_run_redone(tmp_path, capsys):
    from splatbench.experiments import parse_experiment, run_experiment
    from splatbench.experiments.store import read_records

    spec = parse_experiment({"name": "g", "kind": "tests.kinds_for_tests:DUMMY", "scenes": ["alpha"], "seeds": [0, 1, 2, 3]},
                            source="g.toml")
    first = run_experiment(spec, workers=1, results_dir=tmp_path, progress=False)
    assert first.done == 4
    files = sorted((tmp_path / "g").glob("*.json"))
    records = {p: json.loads(p.read_text()) for p in files}
    files[0].write_text(files[0].read_text()[:40])                               # torn
    files[1].write_text(json.dumps({**records[files[1]], "seed": "zero"}))       # wrong type
    files[2].write_text(json.dumps({**records[files[2]], "config": {"a b": 1}}))  # not a table row
    files[3].write_bytes(b"\xff\xfe" + files[3].read_bytes())                    # not UTF-8
    capsys.readouterr()
    second = run_experiment(spec, workers=1, results_dir=tmp_path, progress=True)
    err = capsys.readouterr().err
    assert (second.done, second.skipped) == (4, 0)
    for p in files:
        assert f"damaged result file {p.name}" in err and "its run is redone" in err
    assert {r.run_id: r.to_dict()["metrics"] for r in read_records(tmp_path / "g").values()} == \
        {Path(p).stem: d["metrics"] for p, d in records.items()}


def test_a_damaged_claim_is_no_owner():
    from splatbench.experiments.claims import Owner

    good = json.loads(Owner.me().text())
    for bad in ("[" * 100_000, json.dumps({**good, "pid": 1e309}), json.dumps({**good, "pid": -1}),
                json.dumps({**good, "start": [1]}), "\udcff"):
        assert Owner.parse(bad) is None


# --------------------------------------------------------------- what the fuzzing found
def test_found_a_non_utf8_image_name_in_images_bin(tmp_path):
    """images.bin naming an image b"\\x80v0.png": was a UnicodeDecodeError from pycolmap's
    binding, now one line naming the file."""
    from splatbench.data import load_dataset

    _colmap(tmp_path / "ds", text=False)
    images = tmp_path / "ds" / "sparse" / "0" / "images.bin"
    images.write_bytes(images.read_bytes().replace(b"v0.png\0", b"\x80v0.png\0", 1))
    one_line_error(lambda: load_dataset(tmp_path / "ds"), "images.bin", "image 0 name", "not UTF-8")


def test_found_a_nan_sfm_point(tmp_path):
    """A NaN x in points3D.bin: was accepted into Dataset.points, now one line."""
    from splatbench.data import load_dataset

    _colmap(tmp_path / "ds", text=False)
    points = tmp_path / "ds" / "sparse" / "0" / "points3D.bin"
    data = bytearray(points.read_bytes())
    data[16:24] = struct.pack("<d", float("nan"))  # point 0: count (8) + id (8), then x
    points.write_bytes(bytes(data))
    one_line_error(lambda: load_dataset(tmp_path / "ds"), "points3D.bin", "1 of 2 points are not finite")


def test_found_a_npy_header_numpy_cannot_parse(tmp_path):
    """A .npy header with its dict cut short: was a SyntaxError from numpy's header parser."""
    from splatbench.safeio import read_npy

    path = tmp_path / "d.npy"
    np.save(path, np.zeros((4, 6), np.float32))
    data = path.read_bytes()
    path.write_bytes(data[:10] + b"{'descr': '<f4'\x93NUMPY\0" + data[10:])
    one_line_error(lambda: read_npy(path, what="d.npy"), "d.npy", "not a valid .npy array")


def test_found_npz_members_must_be_read_whole(tmp_path):
    """The bounded npz reader first read each member after its header: every valid npz
    failed. A valid workload reads back exactly."""
    from splatbench.workloads import load_npz, save_npz, synthetic

    w = synthetic(3, 8, 6, seed=0)
    save_npz(w, tmp_path / "w.npz")
    back = load_npz(tmp_path / "w.npz")
    assert np.array_equal(back.gaussians.means, w.gaussians.means)
    assert np.array_equal(back.camera.K, w.camera.K) and back.camera.width == w.camera.width


def test_an_object_array_in_an_npz_is_refused_unread(tmp_path):
    from splatbench.safeio import read_npz

    path = tmp_path / "o.npz"
    np.savez(path, means=np.array([Payload(tmp_path / "ran.txt")], dtype=object))
    one_line_error(lambda: read_npz(path, what="o.npz"), "o.npz", "array 'means'", "Python objects")
    assert not (tmp_path / "ran.txt").exists()


def test_a_hostile_ply_point_cloud_in_a_blender_dataset(tmp_path):
    from splatbench.data import load_dataset
    from tests.test_fuzz import _blender

    _blender(tmp_path / "b")
    hostile_ply(tmp_path / "b" / "points3D.ply")
    one_line_error(lambda: load_dataset(tmp_path / "b"), "points3D.ply", "element 'vertex' count", "100000000000")


def test_found_a_png_chunk_length_pillow_would_allocate(tmp_path):
    """A 6x4 PNG whose IDAT states 134 MB: Pillow read the rest of the chunk with
    file.read(134 MB) (allocated before reading). Now read from memory: the read gives
    what is there, and the peak stays near the file's size."""
    import tracemalloc
    import zlib

    from splatbench.safeio import read_image

    raw = zlib.compress(b"".join(b"\0" + bytes(18) for _ in range(4)))
    def chunk(kind: bytes, data: bytes, length: int | None = None) -> bytes:
        return struct.pack(">I", len(data) if length is None else length) + kind + data + \
            struct.pack(">I", zlib.crc32(kind + data))

    path = tmp_path / "a.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 6, 4, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", raw, length=0x08000057) + chunk(b"IEND", b""))
    tracemalloc.start()
    try:
        try:
            read_image(path, what="a.png")
        except InputError as exc:
            assert "\n" not in str(exc)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, peak


def test_found_a_npy_header_length_numpy_would_allocate(tmp_path):
    """A version-3 .npy whose 4-byte header length reads 662 MB (a version byte flipped
    from 1): numpy reads a header of that length before checking it. Now the length is
    bounded (numpy's 10000) before anything is read."""
    import tracemalloc

    from splatbench.safeio import read_npy

    path = tmp_path / "d.npy"
    np.save(path, np.zeros((4, 6), np.float32))
    data = bytearray(path.read_bytes())
    data[6] = 3  # version 3.0: the length field becomes 4 bytes, b"v\x00{'"
    path.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        one_line_error(lambda: read_npy(path, what="d.npy"), "d.npy", "header length", "at most 10000")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, peak


# --------------------------------------------------------------- what the structure-aware campaign found
# (tests/structured_fuzzing.py; one test per bug class, each on the seed capture the campaign mutates)
def _ngp(tmp_path: Path, **frame0) -> Path:
    from tests.structured_fuzzing import ngp_seed

    root = tmp_path / "cap"
    ngp_seed(root)
    meta = json.loads((root / "transforms.json").read_text())
    meta["frames"][0].update(frame0)
    (root / "transforms.json").write_text(json.dumps(meta))
    return root


@pytest.mark.parametrize("file_path", ["", ".", "./", "/", " "])
def test_found_an_empty_file_path(tmp_path, file_path):
    """file_path "" / "." / "/": was `ValueError: PosixPath('.') has an empty name` from
    Path.with_name (issue 29 item 9); now one line naming the frame and the field."""
    from splatbench.data import load_dataset

    root = _ngp(tmp_path, file_path=file_path)
    one_line_error(lambda: load_dataset(root), "transforms.json: frames[0]", "file_path")


@pytest.mark.parametrize("file_path", ["../outside.png", "images/../../outside.png", "OUTSIDE", "~/outside.png"])
def test_found_a_file_path_that_leaves_the_capture(tmp_path, file_path):
    """An absolute path outside the capture was `ValueError ... is not in the subpath` from
    Path.relative_to; a `../` path was read from outside the folder (a capture from others
    could make splatbench read any image on the machine into a run). Both are refused."""
    from splatbench.data import load_dataset
    from tests.test_fuzz import _png

    _png(tmp_path / "outside.png")
    root = _ngp(tmp_path, file_path=str(tmp_path / "outside.png") if file_path == "OUTSIDE" else file_path)
    one_line_error(lambda: load_dataset(root), "frames[0]: file_path", "leaves the capture folder")


def test_a_symlink_inside_the_capture_is_followed(tmp_path, monkeypatch):
    """The policy's other side: an image folder that is a symlink (images kept on another
    disk) loads; the names stay the capture's own."""
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _ngp(tmp_path)
    (root / "images").rename(tmp_path / "elsewhere")
    (root / "images").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    ds = load_dataset(root, test_every=2)
    assert ds.train.names == ["images/0001.png", "images/0003.png"]


def test_found_a_file_path_longer_than_the_file_system_allows(tmp_path):
    """A 300-character name: was `OSError: [Errno 36] File name too long` from Path.is_file,
    in transforms.json (file_path) and in images.txt (an image name)."""
    from splatbench.data import load_dataset

    root = _ngp(tmp_path, file_path="x" * 300)
    one_line_error(lambda: load_dataset(root), "frames[0]: file_path", "longer than file systems allow")
    root = _colmap_text(tmp_path)
    images = root / "sparse" / "0" / "images.txt"
    images.write_text(images.read_text().replace(" v1.png", " " + "x" * 300 + ".png"))
    one_line_error(lambda: load_dataset(root), "images.txt: image 2: name", "longer than file systems allow")


@pytest.mark.parametrize("value", [None, [], {}, 5, ""])
def test_found_a_ply_file_path_of_the_wrong_type(tmp_path, monkeypatch, value):
    """ply_file_path null / [] / 5: was `TypeError: unsupported operand type(s) for /`."""
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _ngp(tmp_path)
    meta = json.loads((root / "transforms.json").read_text())
    meta["ply_file_path"] = value
    (root / "transforms.json").write_text(json.dumps(meta))
    one_line_error(lambda: load_dataset(root), "transforms.json: ply_file_path")


@pytest.mark.parametrize("text,message", [
    ('{"deep": ' + "[" * 100_000 + "]" * 100_000 + ', "frames": []}', "nested too deeply"),  # was RecursionError
    ('{"w": 1' + "0" * 400 + ', "frames": []}', "beyond float64's range"),                  # was OverflowError
    ('{"w": 1' + "0" * 400 + '.5, "frames": []}', "beyond float64's range"),                 # read as inf
    ('{"frames": [], "frames": [{"file_path": "images/0000.png"}]}', "key 'frames' is given twice"),  # last won
    ('[{"frames": []}]', "expected a JSON object"),
    ('{"frames": []}', "frames: the list is empty"),                                         # loaded nothing
])
def test_found_json_a_lenient_reader_takes_in(tmp_path, text, message):
    """JSON that is valid but not a capture: nesting deeper than the parser's recursion, a
    number beyond float64, a key given twice (json.loads kept the last silently), no frames."""
    from splatbench.data import load_dataset

    root = _ngp(tmp_path)
    (root / "transforms.json").write_text(text)
    one_line_error(lambda: load_dataset(root), "transforms.json", message)


def test_a_byte_order_mark_is_read_as_utf8(tmp_path, monkeypatch):
    """Windows editors write a UTF-8 byte-order mark; it was refused as invalid JSON."""
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _ngp(tmp_path)
    (root / "transforms.json").write_bytes(b"\xef\xbb\xbf" + (root / "transforms.json").read_bytes())
    assert len(load_dataset(root, test_every=2).train) == 2


def test_found_a_duplicated_frame(tmp_path, monkeypatch):
    """A frame given twice (same image) was loaded twice: one photo weighed double in training,
    or sat in train and test at once. Within a file: refused; across transforms_train.json and
    transforms_test.json: a note says the test scores measure fitting."""
    from splatbench.data import load_dataset
    from tests.structured_fuzzing import blender_seed

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _ngp(tmp_path)
    meta = json.loads((root / "transforms.json").read_text())
    meta["frames"].append({**meta["frames"][1], "transform_matrix": meta["frames"][2]["transform_matrix"]})
    (root / "transforms.json").write_text(json.dumps(meta))
    one_line_error(lambda: load_dataset(root), "frames[4]", "images/0001.png", "as frames[1] does")
    blender = tmp_path / "blender"
    blender_seed(blender)
    train = json.loads((blender / "transforms_train.json").read_text())
    test = json.loads((blender / "transforms_test.json").read_text())
    test["frames"].append(train["frames"][0])
    (blender / "transforms_test.json").write_text(json.dumps(test))
    ds = load_dataset(blender)
    assert any("1 images are both training and test views (train/r_0.png" in n for n in ds.notes), ds.notes


def _colmap_text(tmp_path: Path) -> Path:
    from tests.structured_fuzzing import colmap_text_seed

    colmap_text_seed(tmp_path / "ds")
    return tmp_path / "ds"


@pytest.mark.parametrize("name", ["../outside.png", "../../outside.png"])
def test_found_a_colmap_image_name_that_leaves_the_image_folder(tmp_path, name):
    """images.txt naming "../outside.png": was read from beside the image folder (or from
    outside the capture)."""
    from splatbench.data import load_dataset
    from tests.test_fuzz import _png

    root = _colmap_text(tmp_path)
    _png(root / "outside.png")
    _png(tmp_path / "outside.png")
    images = root / "sparse" / "0" / "images.txt"
    images.write_text(images.read_text().replace(" v1.png", f" {name}"))
    one_line_error(lambda: load_dataset(root), "images.txt: image 2", "name", "leaves the image folder")


def test_found_two_colmap_images_of_one_name(tmp_path):
    """Two image records (ids 2 and 99) naming v1.png in a model without rigs.txt / frames.txt
    (COLMAP before 3.12) were both loaded: one photo twice. (With frames.txt pycolmap refuses
    image 99, which no frame holds.)"""
    from splatbench.data import load_dataset

    root = _colmap_text(tmp_path)
    for name in ("rigs.txt", "frames.txt"):
        (root / "sparse" / "0" / name).unlink()
    images = root / "sparse" / "0" / "images.txt"
    lines = images.read_text().split("\n")
    i = next(k for k, line in enumerate(lines) if line.endswith(" v1.png"))
    lines[i + 2:i + 2] = ["99" + lines[i][1:], lines[i + 1]]
    images.write_text("\n".join(lines))
    one_line_error(lambda: load_dataset(root), "images.txt: image", "name 'v1.png' is also the name of image")


def test_found_a_negative_colmap_camera_size_that_hung_undistortion(tmp_path, monkeypatch):
    """cameras.txt giving the OPENCV camera height -6: pycolmap reads it as 2^64 - 6 and
    undistort_camera walked that many border pixels (the case never ended). Now the size is
    checked before any pycolmap computation, and a distorted camera's size against its photo
    before undistortion."""
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _colmap_text(tmp_path)
    cameras = root / "sparse" / "0" / "cameras.txt"
    text = cameras.read_text()
    cameras.write_text(text.replace("2 OPENCV 6 4 ", "2 OPENCV 6 -6 "))
    one_line_error(lambda: load_dataset(root), "cameras.txt: camera 2: width, height")
    cameras.write_text(text.replace("2 OPENCV 6 4 ", "2 OPENCV 30000 20000 "))
    one_line_error(lambda: load_dataset(root), "images/v0.png: image size 6x4 disagrees with its camera 30000x20000")


@pytest.mark.parametrize("value", [True, "0.1"])
def test_found_a_distortion_coefficient_that_is_not_a_number(tmp_path, value):
    """p1 = true was read as float(True) = 1.0 (a strong distortion nobody gave); "0.1" as 0.1."""
    from splatbench.data import load_dataset

    root = _ngp(tmp_path)
    meta = json.loads((root / "transforms.json").read_text())
    meta["p1"] = value
    (root / "transforms.json").write_text(json.dumps(meta))
    # p1 is written at the top level, so the line names it there (a frame's own key is named by its frame)
    one_line_error(lambda: load_dataset(root), "transforms.json: p1: expected a number")


def test_found_distortion_coefficients_that_leave_a_pixel(tmp_path, monkeypatch):
    """k1 = 1e10: COLMAP's undistorter cropped each 6x4 photo to 1x1, which loaded as a dataset
    of one-pixel views. Now refused, naming the coefficients."""
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _ngp(tmp_path)
    meta = json.loads((root / "transforms.json").read_text())
    meta["k1"] = 1e10
    (root / "transforms.json").write_text(json.dumps(meta))
    one_line_error(lambda: load_dataset(root), "images/0000.png: undistorting its OPENCV camera", "keeps 1x1 of 6x4",
                   "implausible distortion coefficients")


def test_found_top_level_keys_in_a_frame_ignored_silently(tmp_path, monkeypatch):
    """A frame's ply_file_path (read at the top level only) was dropped without a word."""
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _ngp(tmp_path, ply_file_path="mine.ply")
    ds = load_dataset(root, test_every=2)
    assert any("ignored keys" in n and "frames[].ply_file_path" in n for n in ds.notes), ds.notes


def test_found_a_colmap_text_file_cut_mid_number(tmp_path, monkeypatch):
    """cameras.txt cut inside its last number: p2 = -0.0003 (written -0.00029999...) read as
    -0.00, silently. A number cut short is still a number, so the load goes on, but a note
    names the file: COLMAP ends every line with a newline."""
    from splatbench.data import load_dataset

    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = _colmap_text(tmp_path)
    cameras = root / "sparse" / "0" / "cameras.txt"
    data = cameras.read_bytes()
    cameras.write_bytes(data[:data.rindex(b" -0.0002") + len(b" -0.00")])
    ds = load_dataset(root, test_every=2)  # the seed's split: the two OPENCV views are the test views
    assert any("sparse/0/cameras.txt: its last line has no newline" in n and "-0.00'" in n for n in ds.notes), ds.notes
