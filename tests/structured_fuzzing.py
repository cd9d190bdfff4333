"""Structure-aware fuzzing of captures from others: transforms.json and COLMAP text models.

`tests/fuzzing.py` mutates bytes; most of its mutants break a file's syntax and stop at the
parser. The mutations here keep the file parseable and change what it *says*: every node
of a ``transforms.json`` (root, top-level keys, the frame list, a frame, a key of a frame,
a row or an element of a matrix) can become null, an empty string, a value of the wrong
type, NaN / inf / a huge number, zero or negative; keys go missing or appear where they do
not belong; frames are duplicated or removed; paths escape the capture folder (``../``,
absolute, a symlink out); and the file itself can be truncated, not UTF-8, nested too deep
or hold a key twice. COLMAP text models get the same treatment by line and token (wrong
tokens, missing and extra tokens, duplicate camera / image / point ids, dangling
references, image names that escape the image folder).

A case is ``(seed capture, mutation class, case number)``; the random choices are those of
``random.Random(f"{seed}/{class}/{number}")``, so a run is reproducible and a failure names
the case that reproduces it (`describe`). The contract is `fuzzing.run_case`'s: data that
passes the dataset check, or a one-line `InputError`; nothing else, within the time and
memory bound.
"""

from __future__ import annotations

import copy
import json
import math
import os
import random
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# ------------------------------------------------------------------------ seeds


def _png(path: Path, w: int = 6, h: int = 4, alpha: bool = False, seed: int = 1) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    Image.fromarray(rng.integers(0, 255, (h, w, 4 if alpha else 3), dtype=np.uint8)).save(path)


def _pose(i: int) -> list[list[float]]:
    m = np.eye(4)
    m[:3, 3] = [0.1 * i, 0.0, 3.0 + 0.2 * i]
    return m.tolist()


def ngp_seed(folder: Path) -> None:
    """An instant-ngp ``transforms.json`` (as colmap2nerf writes it, the fox's keys): shared
    intrinsics with OPENCV distortion, ``aabb_scale``, per-frame ``sharpness``, 4 frames."""
    from plyfile import PlyData, PlyElement

    for i in range(4):
        _png(folder / "images" / f"{i:04d}.png", seed=i)
    meta = {"camera_angle_x": 1.2, "camera_angle_y": 0.9, "fl_x": 5.0, "fl_y": 5.1, "k1": 0.01, "k2": -0.002,
            "p1": 0.0005, "p2": -0.0003, "cx": 3.05, "cy": 1.95, "w": 6.0, "h": 4.0, "aabb_scale": 4,
            "ply_file_path": "points3D.ply",
            "frames": [{"file_path": f"images/{i:04d}.png", "sharpness": 30.5 + i, "transform_matrix": _pose(i)}
                       for i in range(4)]}
    (folder / "transforms.json").write_text(json.dumps(meta, indent=1))
    vertex = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"),
                                ("blue", "u1")])
    vertex["x"] = [0.0, 0.5, -0.5]
    PlyData([PlyElement.describe(vertex, "vertex")]).write(str(folder / "points3D.ply"))


def blender_seed(folder: Path) -> None:
    """A NeRF-synthetic capture: ``transforms_train.json`` and ``transforms_test.json`` with
    ``camera_angle_x``, file paths without extension (``./train/r_0``), RGBA PNGs."""
    for split, n in (("train", 3), ("test", 2)):
        frames = []
        for i in range(n):
            _png(folder / split / f"r_{i}.png", alpha=True, seed=10 * (split == "test") + i)
            frames.append({"file_path": f"./{split}/r_{i}", "rotation": 0.0126, "transform_matrix": _pose(i)})
        (folder / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": 0.69, "frames": frames},
                                                                    indent=1))


def colmap_text_seed(folder: Path) -> None:
    """A COLMAP text model (cameras, images, points3D, rigs, frames .txt, as pycolmap 4
    writes them) of 3 images and 2 cameras (PINHOLE and OPENCV), with 3 points."""
    from splatbench.cameras import Camera
    from splatbench.interrupt import import_pycolmap

    pycolmap = import_pycolmap()
    rec = pycolmap.Reconstruction()
    pin, _ = Camera(6, 4, 5.0, 5.0, 3.0, 2.0, np.eye(4)).to_colmap()
    pin.camera_id = 1
    rec.add_camera_with_trivial_rig(pin)
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="OPENCV", width=6, height=4, camera_id=2,
                                                    params=[5.0, 5.0, 3.0, 2.0, 0.01, -0.002, 0.0005, -0.0003]))
    for i in range(3):
        pose = np.eye(4)
        pose[0, 3] = 0.1 * i
        image = pycolmap.Image(name=f"v{i}.png", keypoints=np.array([[1.5, 1.5], [2.5, 3.0]]),
                               camera_id=1 if i == 1 else 2, image_id=i + 1)
        rec.add_image_with_trivial_frame(image, Camera(6, 4, 5.0, 5.0, 3.0, 2.0, pose).to_colmap()[1])
        _png(folder / "images" / f"v{i}.png", seed=i)
    for j in range(2):
        track = pycolmap.Track()
        for i in range(3):
            track.add_element(i + 1, j)
        rec.add_point3D(np.array([0.1 * j, 0.0, 2.0]), track, np.array([10, 20, 30], np.uint8))
    sparse = folder / "sparse" / "0"
    sparse.mkdir(parents=True)
    rec.write_text(str(sparse))


def capture_seed(source: Path, frames: int) -> Callable[[Path], None]:
    """A real instant-ngp capture's ``transforms.json`` (every key and value as it is) cut to
    its first ``frames`` frames, with their photos: a seed built from data others made."""
    def build(folder: Path) -> None:
        meta = json.loads((source / "transforms.json").read_text())
        meta["frames"] = meta["frames"][:frames]
        for frame in meta["frames"]:
            (folder / frame["file_path"]).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source / frame["file_path"], folder / frame["file_path"])
        (folder / "transforms.json").write_text(json.dumps(meta, indent=1))
    return build


def llff_seed(folder: Path) -> None:
    """An LLFF capture as NeRD ships one: ``poses_bounds.npy`` (4 rows, float64, [h, w, f] of
    12x8 originals), ``images_2/`` at 6x4 and ``masks_2/`` with ``_mask`` names (read at
    ``downscale=2``)."""
    from splatbench.cameras import Camera
    from splatbench.data.llff import row_from_camera

    rows = []
    for i in range(4):
        _png(folder / "images_2" / f"IMG_{i:04d}.png", seed=i)
        mask = np.random.default_rng(20 + i).integers(0, 2, (4, 6)).astype(np.uint8) * 255
        (folder / "masks_2").mkdir(parents=True, exist_ok=True)
        from PIL import Image

        Image.fromarray(mask).save(folder / "masks_2" / f"IMG_{i:04d}_mask.png")
        w2c = np.eye(4)
        w2c[:3, 3] = [-0.1 * i, 0.0, 0.0]
        rows.append(row_from_camera(Camera(12, 8, 10.0, 10.0, 6.0, 4.0, w2c), 1.0 + 0.1 * i, 5.0))
    np.save(folder / "poses_bounds.npy", np.stack(rows))


SEEDS: dict[str, Callable[[Path], None]] = {"ngp": ngp_seed, "blender": blender_seed, "colmap-text": colmap_text_seed,
                                            "llff": llff_seed}


# ------------------------------------------------------------------------ values

NULLISH = [None, "", " ", "null", "None", "NaN"]
NUMBERS = [math.nan, math.inf, -math.inf, 1e308, -1e308, 10 ** 400, -(10 ** 400), 2 ** 64, 2 ** 63, 2 ** 31,
           -1, -1.5, 0, 0.0, -0.0, 5e-324, 1e-300, 1e30]
WRONG = [True, False, 1, 2.5, "x", "12", [], [1, 2], [[1]], {}, {"a": 1}, [None], "\u00e9\u4e2d", "\ud83d\ude00"]
ESCAPES = ["../outside.png", "../../outside.png", "images/../../outside.png", "./../outside", "..", "/",
           "/etc/passwd", "/dev/zero", "~/outside.png", "file:///etc/passwd", "images\\..\\..\\outside.png",
           "images/0001.png/..", "images/\u0000x.png", "//outside.png", "." * 300, "a/" * 200 + "x.png"]
TOKENS = ["nan", "NaN", "inf", "-inf", "1e309", "-1e309", "1e308", "-1", "0", "-0", "1.5", "18446744073709551616",
          "100000000000", "2147483648", "abc", "", "null", "None", "0x10", "1e-320", "\u00e9"]


def _paths(node, prefix=()):
    """Every path (tuple of keys / indices) of a JSON tree, the root's () first."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _get(doc, path):
    for p in path:
        doc = doc[p]
    return doc


def _set(doc, path, value):
    if not path:
        return value
    _get(doc, path[:-1])[path[-1]] = value
    return doc


def _dumps(doc) -> str:
    """JSON as other tools write it; NaN/Infinity as Python (and instant-ngp's nlohmann) write them."""
    return json.dumps(doc, indent=1, allow_nan=True)


# ------------------------------------------------------------------------ transforms.json mutations


@dataclass
class Case:
    folder: Path          # the capture copy to mutate
    outside: Path         # a folder beside it, with a valid image and PLY (what an escaping path finds)
    rng: random.Random
    files: list[str]      # the capture's JSON files (blender, ngp) or COLMAP text files

    def load(self, rel: str):
        return json.loads((self.folder / rel).read_text())

    def save(self, rel: str, doc) -> None:
        (self.folder / rel).write_text(_dumps(doc))

    def pick_json(self) -> str:
        return self.rng.choice(self.files)


def _frame_keys(doc) -> list[tuple]:
    return [("frames", i, k) for i, f in enumerate(doc.get("frames") or []) if isinstance(f, dict) for k in f]


def _node_edit(c: Case, value_of: Callable[[random.Random, object], object], where: str = "any") -> str:
    rel = c.pick_json()
    doc = c.load(rel)
    paths = list(_paths(doc))
    if where == "leaf":
        paths = [p for p in paths if not isinstance(_get(doc, p), (dict, list))] or paths
    path = c.rng.choice(paths)
    value = value_of(c.rng, _get(doc, path))
    c.save(rel, _set(doc, path, value))
    return f"{rel}: {'/'.join(map(str, path)) or '<root>'} = {value!r:.60}"


def m_null(c: Case) -> str:
    return _node_edit(c, lambda r, old: r.choice([None, None, None, "null"]))


def m_empty(c: Case) -> str:
    return _node_edit(c, lambda r, old: r.choice(["", "", [], {}, " "]))


def m_wrong_type(c: Case) -> str:
    return _node_edit(c, lambda r, old: r.choice([v for v in WRONG if type(v) is not type(old)]))


def m_number(c: Case) -> str:
    return _node_edit(c, lambda r, old: r.choice(NUMBERS), where="leaf")


def m_size(c: Case) -> str:
    """Zero or negative sizes and focal lengths (top level or per frame)."""
    rel = c.pick_json()
    doc = c.load(rel)
    key = c.rng.choice(["w", "h", "fl_x", "fl_y", "camera_angle_x", "camera_angle_y", "cx", "cy"])
    value = c.rng.choice([0, -1, -6, 0.0, -0.5, 0.5, 1, 10 ** 12, 6.5])
    target = doc if c.rng.random() < 0.6 or not doc.get("frames") else c.rng.choice(doc["frames"])
    if isinstance(target, dict):
        target[key] = value
    c.save(rel, doc)
    return f"{rel}: {key} = {value!r}"


def m_missing_key(c: Case) -> str:
    rel = c.pick_json()
    doc = c.load(rel)
    dicts = [p for p in _paths(doc) if isinstance(_get(doc, p), dict) and _get(doc, p)]
    path = c.rng.choice(dicts)
    node = _get(doc, path)
    key = c.rng.choice(sorted(node))
    del node[key]
    c.save(rel, doc)
    return f"{rel}: del {'/'.join(map(str, path + (key,)))}"


def m_extra_key(c: Case) -> str:
    """A key where it does not belong, or one splatbench reads placed where it is not expected."""
    rel = c.pick_json()
    doc = c.load(rel)
    dicts = [p for p in _paths(doc) if isinstance(_get(doc, p), dict)]
    path = c.rng.choice(dicts)
    key = c.rng.choice(["unknown", "fl_x", "w", "h", "camera_model", "k4", "k3", "frames", "file_path",
                        "transform_matrix", "ply_file_path", "camera_angle_x", "", "\u00e9", "__proto__"])
    value = c.rng.choice([1, 0.5, "OPENCV", "OPENCV_FISHEYE", "FISHEYE624", "x", None, [], {}, -1, 1e308,
                          "images/0000.png", _pose(7)])
    _get(doc, path)[key] = value
    c.save(rel, doc)
    return f"{rel}: {'/'.join(map(str, path + (key,)))} = {value!r:.40}"


def m_duplicate_frame(c: Case) -> str:
    rel = c.pick_json()
    doc = c.load(rel)
    frames = doc["frames"]
    i = c.rng.randrange(len(frames))
    dup = copy.deepcopy(frames[i])
    how = c.rng.choice(["same", "other pose", "other split"])
    if how == "other pose":
        dup["transform_matrix"] = _pose(9)
    if how == "other split" and len(c.files) > 1:  # the same image in train and test
        other = [f for f in c.files if f != rel][0]
        odoc = c.load(other)
        odoc["frames"].append(dup)
        c.save(other, odoc)
        return f"{other}: frames += {rel}'s frames[{i}]"
    frames.insert(c.rng.randrange(len(frames) + 1), dup)
    c.save(rel, doc)
    return f"{rel}: frames[{i}] duplicated ({how})"


def m_missing_frames(c: Case) -> str:
    rel = c.pick_json()
    doc = c.load(rel)
    how = c.rng.choice(["drop one", "drop all", "no key", "drop file", "drop image", "one frame"])
    if how == "drop one":
        del doc["frames"][c.rng.randrange(len(doc["frames"]))]
    elif how == "drop all":
        doc["frames"] = []
    elif how == "no key":
        del doc["frames"]
    elif how == "one frame":
        doc["frames"] = doc["frames"][:1]
    elif how == "drop file":
        (c.folder / rel).unlink()
        return f"{rel}: deleted"
    else:
        frame = c.rng.choice(doc["frames"])
        for p in sorted(c.folder.rglob("*")):
            if p.is_file() and p.suffix in (".png", ".jpg") and Path(frame["file_path"]).stem == p.stem \
                    and Path(frame["file_path"]).parent.name == p.parent.name:
                p.unlink()
        return f"{rel}: the image of {frame['file_path']!r} deleted"
    c.save(rel, doc)
    return f"{rel}: frames: {how}"


def m_path_escape(c: Case) -> str:
    rel = c.pick_json()
    doc = c.load(rel)
    key = "ply_file_path" if "ply_file_path" in doc and c.rng.random() < 0.2 else "file_path"
    choices = ESCAPES + [str(c.outside / "outside.png"), str(c.outside / "outside"), "../outside/outside.png",
                         "../" + c.folder.name + "/" + doc["frames"][0]["file_path"].lstrip("./"),
                         str(c.folder / doc["frames"][0]["file_path"].lstrip("./"))]
    if key == "ply_file_path":
        choices = ["../outside/outside.ply", str(c.outside / "outside.ply"), "/etc/passwd", "..", "", "/",
                   "../" + c.folder.name + "/points3D.ply"]
    value = c.rng.choice(choices)
    if key == "file_path":
        c.rng.choice(doc["frames"])[key] = value
    else:
        doc[key] = value
    c.save(rel, doc)
    return f"{rel}: {key} = {value!r:.80}"


def m_empty_path(c: Case) -> str:
    rel = c.pick_json()
    doc = c.load(rel)
    value = c.rng.choice(["", "", ".", "./", "images/", "train/", " ", "\t", "images", "./train",
                          doc["frames"][0]["file_path"] + " ", doc["frames"][0]["file_path"] + "/"])
    frame = c.rng.choice(doc["frames"])
    frame["file_path"] = value
    c.save(rel, doc)
    return f"{rel}: file_path = {value!r}"


def m_symlink(c: Case) -> str:
    """An image, the image folder or the JSON itself a symlink out of the capture (or a loop)."""
    rel = c.pick_json()
    doc = c.load(rel)
    frame_path = c.rng.choice(doc["frames"])["file_path"]
    images = sorted(p for p in c.folder.rglob("*") if p.suffix in (".png", ".jpg") and p.is_file())
    target = c.rng.choice(images)
    how = c.rng.choice(["image out", "folder out", "json out", "loop", "dangling", "image out"])
    if how == "image out":
        target.unlink()
        target.symlink_to(c.outside / "outside.png")
    elif how == "folder out":
        shutil.rmtree(target.parent)
        target.parent.symlink_to(c.outside, target_is_directory=True)
    elif how == "json out":
        (c.outside / "evil.json").write_text(_dumps(doc))
        (c.folder / rel).unlink()
        (c.folder / rel).symlink_to(c.outside / "evil.json")
    elif how == "loop":
        target.unlink()
        target.symlink_to(target)
    else:
        target.unlink()
        target.symlink_to(c.outside / "missing.png")
    return f"{target.relative_to(c.folder)}: symlink ({how}; a frame names {frame_path!r})"


def m_encoding(c: Case) -> str:
    rel = c.pick_json()
    text = (c.folder / rel).read_text()
    how = c.rng.choice(["latin-1 in a string", "utf-16", "bom", "cp1252 name", "lone surrogate", "nul"])
    if how == "latin-1 in a string":
        data = text.encode().replace(b'"file_path": "', b'"file_path": "\xe9', 1)
    elif how == "utf-16":
        data = text.encode("utf-16")
    elif how == "bom":
        data = b"\xef\xbb\xbf" + text.encode()
    elif how == "cp1252 name":
        data = text.replace('"frames"', '"fr\u00e4mes"').encode("cp1252")
    elif how == "lone surrogate":
        data = text.replace('"file_path": "', '"file_path": "\\udcff', 1).encode()
    else:
        data = text.encode().replace(b'"file_path": "', b'"file_path": "\\u0000', 1)
    (c.folder / rel).write_bytes(data)
    return f"{rel}: {how}"


def m_truncated(c: Case) -> str:
    rel = c.pick_json()
    data = (c.folder / rel).read_bytes()
    cut = c.rng.choice([0, 1, c.rng.randrange(len(data)), len(data) - 1, len(data) - 2])
    (c.folder / rel).write_bytes(data[:cut])
    return f"{rel}: truncated at {cut} of {len(data)} bytes"


def m_syntax(c: Case) -> str:
    """Valid JSON a lenient reader takes in silently: a key given twice, nesting too deep, a
    top-level list, a huge number literal."""
    rel = c.pick_json()
    text = (c.folder / rel).read_text()
    how = c.rng.choice(["duplicate key", "deep", "list root", "huge literal", "comment", "trailing comma"])
    if how == "duplicate key":
        key = c.rng.choice(["frames", "camera_angle_x", "file_path", "w", "transform_matrix"])
        text = text.replace(f'"{key}":', f'"{key}": null, "{key}":', 1) if key != "frames" else \
            text.replace('"frames":', '"frames": [], "frames":', 1)
    elif how == "deep":
        depth = c.rng.choice([1000, 100_000])
        text = text.replace('"frames":', f'"deep": {"[" * depth}{"]" * depth}, "frames":', 1)
    elif how == "list root":
        text = f"[{text}]"
    elif how == "huge literal":  # an integer of 5000 digits (beyond Python's int-string limit) or 401
        numbers = list(re.finditer(r"(?<=[\s\[:])-?\d+(\.\d+)?(?=[,\s\]}])", text))
        m = c.rng.choice(numbers)
        digits = c.rng.choice([5000, 400, 309])
        text = text[:m.start()] + "1" + "0" * digits + c.rng.choice(["", ".0", ".5"]) + text[m.end():]
    elif how == "comment":
        text = "// written by hand\n" + text
    else:
        text = text.rstrip().rstrip("}") + ",}"
    (c.folder / rel).write_text(text)
    return f"{rel}: {how}"


JSON_CLASSES: dict[str, Callable[[Case], str]] = {
    "null": m_null, "empty": m_empty, "wrong type": m_wrong_type, "number": m_number, "size": m_size,
    "missing key": m_missing_key, "extra key": m_extra_key, "duplicate frame": m_duplicate_frame,
    "missing frames": m_missing_frames, "path escape": m_path_escape, "empty path": m_empty_path,
    "symlink": m_symlink, "encoding": m_encoding, "truncated": m_truncated, "syntax": m_syntax,
}


# ------------------------------------------------------------------------ COLMAP text mutations


def _data_lines(lines: list[str]) -> list[int]:
    return [i for i, line in enumerate(lines) if line.strip() and not line.startswith("#")]


def _colmap_file(c: Case, parts=("cameras", "images", "points3D")) -> tuple[Path, list[str]]:
    path = c.folder / "sparse" / "0" / f"{c.rng.choice(parts)}.txt"
    return path, path.read_text().split("\n")


def _image_pairs(lines: list[str]) -> list[int]:
    """Indices of the first line of each image record of images.txt (two lines each)."""
    data = _data_lines(lines)
    return data[0::2] if len(data) % 2 == 0 else [i for i in data if len(lines[i].split()) >= 10]


def _token_edit(c: Case, value_of: Callable[[random.Random, str, int, str], str], parts=("cameras", "images",
                                                                                        "points3D")) -> str:
    path, lines = _colmap_file(c, parts)
    data = _data_lines(lines)
    if not data:
        return f"{path.name}: no data line"
    i = c.rng.choice(data)
    tokens = lines[i].split(" ")
    k = c.rng.randrange(len(tokens))
    tokens[k] = value_of(c.rng, tokens[k], k, path.stem)
    lines[i] = " ".join(tokens)
    path.write_text("\n".join(lines))
    return f"{path.name}: line {i + 1} token {k} = {tokens[k]!r:.40}"


def c_token(c: Case) -> str:
    return _token_edit(c, lambda r, old, k, part: r.choice(TOKENS), parts=("cameras", "images", "points3D", "rigs",
                                                                            "frames"))


def c_null(c: Case) -> str:
    return _token_edit(c, lambda r, old, k, part: r.choice(["", "null", "None", "-", "''", '""']))


def c_size(c: Case) -> str:
    """Camera width / height / focal lengths zero, negative, huge, fractional."""
    path = c.folder / "sparse" / "0" / "cameras.txt"
    lines = path.read_text().split("\n")
    i = c.rng.choice(_data_lines(lines))
    tokens = lines[i].split()
    k = c.rng.choice([2, 3, 4, 5])
    tokens[k] = c.rng.choice(["0", "-1", "-6", "6.5", "4294967296", "100000000", "1e9", "0.0", "-5.0"])
    lines[i] = " ".join(tokens)
    path.write_text("\n".join(lines))
    return f"cameras.txt: line {i + 1} token {k} = {tokens[k]!r}"


def c_missing_tokens(c: Case) -> str:
    path, lines = _colmap_file(c, ("cameras", "images", "points3D", "rigs", "frames"))
    data = _data_lines(lines)
    if not data:
        return f"{path.name}: no data line"
    i = c.rng.choice(data)
    tokens = lines[i].split()
    keep = c.rng.randrange(len(tokens))
    lines[i] = " ".join(tokens[:keep])
    path.write_text("\n".join(lines))
    return f"{path.name}: line {i + 1} cut to {keep} tokens"


def c_extra_tokens(c: Case) -> str:
    path, lines = _colmap_file(c, ("cameras", "images", "points3D", "rigs", "frames"))
    data = _data_lines(lines)
    if not data:
        return f"{path.name}: no data line"
    i = c.rng.choice(data)
    extra = c.rng.choice(["1", "0.5", "x", "1 2 3", "-1 -1", "nan", "7 8"])
    lines[i] = lines[i] + " " + extra
    path.write_text("\n".join(lines))
    return f"{path.name}: line {i + 1} += {extra!r}"


def c_duplicate_id(c: Case) -> str:
    """A camera, image or point record given twice (same id; same or other content)."""
    part = c.rng.choice(["cameras", "images", "images", "points3D", "images name"])
    path = c.folder / "sparse" / "0" / f"{part.split()[0]}.txt"
    lines = path.read_text().split("\n")
    if part.startswith("images"):
        pairs = _image_pairs(lines)
        i = c.rng.choice(pairs)
        first, second = lines[i], lines[i + 1]
        tokens = first.split()
        if part == "images name":  # another id, the same name
            tokens[0] = "99"
        elif c.rng.random() < 0.5:  # the same id, another name
            tokens[9] = "v9.png"
        lines[i + 2:i + 2] = [" ".join(tokens), second]
    else:
        i = c.rng.choice(_data_lines(lines))
        tokens = lines[i].split()
        if c.rng.random() < 0.5:
            tokens[1 if part == "points3D" else 2] = "0.7" if part == "points3D" else "8"
        lines.insert(i + 1, " ".join(tokens))
    path.write_text("\n".join(lines))
    older = c.rng.random() < 0.5  # COLMAP before 3.12 writes no rigs.txt / frames.txt
    if older:
        for name in ("rigs.txt", "frames.txt"):
            (path.parent / name).unlink()
    return f"{path.name}: duplicate {part} record (line {i + 1}){' without rigs/frames' if older else ''}"


def c_dangling(c: Case) -> str:
    """A reference to what is not there: an image's camera, a track's image or 2-D point,
    a 2-D point's 3-D point, a missing record or file."""
    how = c.rng.choice(["camera of image", "track image", "track point2D", "point3D of point2D", "drop camera",
                        "drop image", "drop points2D line", "drop file", "empty file"])
    sparse = c.folder / "sparse" / "0"
    if how in ("drop file", "empty file"):
        part = c.rng.choice(["cameras", "images", "points3D", "rigs", "frames"])
        (sparse / f"{part}.txt").unlink() if how == "drop file" else (sparse / f"{part}.txt").write_text("")
        return f"{part}.txt: {how}"
    if how in ("drop camera",):
        path = sparse / "cameras.txt"
        lines = path.read_text().split("\n")
        del lines[c.rng.choice(_data_lines(lines))]
        path.write_text("\n".join(lines))
        return f"cameras.txt: {how}"
    if how == "track image" or how == "track point2D":
        path = sparse / "points3D.txt"
        lines = path.read_text().split("\n")
        i = c.rng.choice(_data_lines(lines))
        tokens = lines[i].split()
        k = 8 + 2 * c.rng.randrange((len(tokens) - 8) // 2) + (how == "track point2D")
        tokens[k] = c.rng.choice(["7", "99", "-1", "0", "4294967295"])
        lines[i] = " ".join(tokens)
        path.write_text("\n".join(lines))
        return f"points3D.txt: line {i + 1} {how} = {tokens[k]}"
    path = sparse / "images.txt"
    lines = path.read_text().split("\n")
    i = c.rng.choice(_image_pairs(lines))
    if how == "camera of image":
        tokens = lines[i].split()
        tokens[8] = c.rng.choice(["7", "0", "-1", "4294967296"])
        lines[i] = " ".join(tokens)
    elif how == "point3D of point2D":
        tokens = lines[i + 1].split()
        if tokens:
            tokens[2] = c.rng.choice(["7", "99", "-2", "18446744073709551615"])
        lines[i + 1] = " ".join(tokens)
    elif how == "drop image":
        del lines[i:i + 2]
    else:
        del lines[i + 1]
    path.write_text("\n".join(lines))
    return f"images.txt: {how} (record at line {i + 1})"


def c_pose(c: Case) -> str:
    """Quaternions and translations: zero, unnormalized, NaN, huge."""
    path = c.folder / "sparse" / "0" / "images.txt"
    lines = path.read_text().split("\n")
    i = c.rng.choice(_image_pairs(lines))
    tokens = lines[i].split()
    how = c.rng.choice(["zero quaternion", "scaled quaternion", "nan", "huge translation", "tiny quaternion"])
    if how == "zero quaternion":
        tokens[1:5] = ["0", "0", "0", "0"]
    elif how == "scaled quaternion":
        tokens[1:5] = [str(float(t) * 1000) for t in tokens[1:5]]
    elif how == "nan":
        tokens[c.rng.randrange(1, 8)] = c.rng.choice(["nan", "inf", "-inf"])
    elif how == "huge translation":
        tokens[c.rng.randrange(5, 8)] = c.rng.choice(["1e308", "1e200", "-1e300"])
    else:
        tokens[1:5] = ["1e-300", "0", "0", "0"]
    lines[i] = " ".join(tokens)
    path.write_text("\n".join(lines))
    return f"images.txt: line {i + 1} {how}"


def c_model(c: Case) -> str:
    path = c.folder / "sparse" / "0" / "cameras.txt"
    lines = path.read_text().split("\n")
    i = c.rng.choice(_data_lines(lines))
    tokens = lines[i].split()
    model, params = c.rng.choice([("pinhole", None), ("UNKNOWN", None), ("SIMPLE_PINHOLE", ["5", "3", "2"]),
                                  ("SIMPLE_RADIAL", ["5", "3", "2", "0.01"]), ("OPENCV", ["5", "5", "3", "2"]),
                                  ("OPENCV_FISHEYE", ["5", "5", "3", "2", "0.1", "0", "0", "0"]),
                                  ("FOV", ["5", "5", "3", "2", "0.5"]), ("PINHOLE", ["5", "5", "3", "2", "1"]),
                                  ("RADIAL", ["5", "3", "2", "nan", "0"]), ("FULL_OPENCV", ["5"] * 12),
                                  ("PINHOLE", ["-5", "5", "3", "2"]), ("", None)])
    tokens[1] = model
    if params is not None:
        tokens[4:] = params
    lines[i] = " ".join(tokens)
    path.write_text("\n".join(lines))
    return f"cameras.txt: line {i + 1} model {model!r} params {params}"


def c_name(c: Case) -> str:
    """An image name that escapes the image folder, is empty, absolute, or names a folder."""
    path = c.folder / "sparse" / "0" / "images.txt"
    lines = path.read_text().split("\n")
    i = c.rng.choice(_image_pairs(lines))
    tokens = lines[i].split()
    name = c.rng.choice(["../outside.png", "../../outside/outside.png", str(c.outside / "outside.png"), "/etc/passwd",
                         "..", ".", "", "images", "../images/v0.png", "sub/../v0.png", "./v1.png", "v0.png",
                         "a b.png", "V0.PNG", "v0.png\t", "x" * 300 + ".png", "../sparse/0/cameras.txt"])
    tokens[9:] = [name] if name else []
    lines[i] = " ".join(tokens)
    path.write_text("\n".join(lines))
    return f"images.txt: line {i + 1} name {name!r:.60}"


def c_symlink(c: Case) -> str:
    target = c.folder / "images" / f"v{c.rng.randrange(3)}.png"
    how = c.rng.choice(["image out", "folder out", "sparse out", "loop"])
    if how == "image out":
        target.unlink()
        target.symlink_to(c.outside / "outside.png")
    elif how == "folder out":
        shutil.rmtree(c.folder / "images")
        (c.folder / "images").symlink_to(c.outside, target_is_directory=True)
    elif how == "sparse out":
        moved = c.outside / "sparse0"
        shutil.move(str(c.folder / "sparse" / "0"), moved)
        (c.folder / "sparse" / "0").symlink_to(moved, target_is_directory=True)
    else:
        target.unlink()
        target.symlink_to(target)
    return f"symlink ({how})"


def c_encoding(c: Case) -> str:
    path, lines = _colmap_file(c, ("cameras", "images", "points3D"))
    text = "\n".join(lines)
    how = c.rng.choice(["latin-1 name", "utf-16", "bom", "crlf", "nul"])
    if how == "latin-1 name":
        data = text.encode().replace(b"v1.png", b"v\xe91.png")
    elif how == "utf-16":
        data = text.encode("utf-16")
    elif how == "bom":
        data = b"\xef\xbb\xbf" + text.encode()
    elif how == "crlf":
        data = text.replace("\n", "\r\n").encode()
    else:
        data = text.encode().replace(b" ", b"\0", 1)
    path.write_bytes(data)
    return f"{path.name}: {how}"


def c_truncated(c: Case) -> str:
    path, _ = _colmap_file(c, ("cameras", "images", "points3D", "rigs", "frames"))
    data = path.read_bytes()
    cut = c.rng.choice([0, c.rng.randrange(len(data)), len(data) - 1, len(data) - 3])
    path.write_bytes(data[:cut])
    return f"{path.name}: truncated at {cut} of {len(data)} bytes"


COLMAP_CLASSES: dict[str, Callable[[Case], str]] = {
    "token": c_token, "null": c_null, "size": c_size, "missing tokens": c_missing_tokens,
    "extra tokens": c_extra_tokens, "duplicate id": c_duplicate_id, "dangling reference": c_dangling,
    "pose": c_pose, "camera model": c_model, "path escape": c_name, "symlink": c_symlink, "encoding": c_encoding,
    "truncated": c_truncated,
}

# ------------------------------------------------------------------------ LLFF: poses_bounds.npy and masks
POSES = "poses_bounds.npy"
VALUES = [math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0, -0.0, -1.0, 5e-324, 1e-300, 2.0 ** 64, 0.5, 1e9]


def _rows(c: Case) -> np.ndarray:
    return np.load(c.folder / POSES)


def l_value(c: Case) -> str:
    rows = _rows(c)
    i, j, v = c.rng.randrange(rows.shape[0]), c.rng.randrange(17), c.rng.choice(VALUES)
    rows[i, j] = v
    np.save(c.folder / POSES, rows)
    return f"{POSES}[{i}, {j}] = {v!r}"


def l_pose(c: Case) -> str:
    rows = _rows(c)
    i = c.rng.randrange(rows.shape[0])
    pose = rows[i, :15].reshape(3, 5)
    how = c.rng.choice(["scale", "swap", "flip", "zero", "hw", "focal", "bounds", "shear"])
    if how == "scale":
        pose[:, :3] *= c.rng.choice([0.5, 1.00001, 1.001, 2.0, 1e6])
    elif how == "swap":
        pose[:, [0, 1]] = pose[:, [1, 0]]
    elif how == "flip":
        pose[:, c.rng.randrange(3)] *= -1
    elif how == "zero":
        pose[:, :3] = 0
    elif how == "hw":
        pose[c.rng.randrange(2), 4] = c.rng.choice([0, -8, 8.5, 1e9, 2 ** 31, 3, 24, 1])
    elif how == "focal":
        pose[2, 4] = c.rng.choice([0, -10, 1e308, 5e-324, 1e-9])
    elif how == "bounds":
        rows[i, 15:] = c.rng.choice([(5.0, 1.0), (0.0, 5.0), (-1.0, 5.0), (1.0, 1.0), (1.0, 1e308)])
    else:
        pose[0, 1] += c.rng.choice([1e-7, 1e-4, 0.1])
    rows[i, :15] = pose.ravel()
    np.save(c.folder / POSES, rows)
    return f"{POSES} row {i}: {how}"


def l_shape(c: Case) -> str:
    rows = _rows(c)
    how = c.rng.choice(["fewer", "more", "columns", "transposed", "flat", "3d", "empty", "scalar", "15 columns",
                        "one row"])
    new = {"fewer": rows[:-1], "more": np.concatenate([rows, rows[:2]]), "columns": rows[:, :16],
           "transposed": rows.T, "flat": rows.ravel(), "3d": rows[None], "empty": rows[:0],
           "scalar": np.float64(3.0), "15 columns": rows[:, :15], "one row": rows[:1]}[how]
    np.save(c.folder / POSES, new)
    return f"{POSES}: {how} {list(np.shape(new))}"


def l_dtype(c: Case) -> str:
    rows = _rows(c)
    how = c.rng.choice(["bool", "int", "float16", "float32", "complex", "big-endian", "string", "structured",
                        "object", "pickle", "datetime"])
    path = c.folder / POSES
    if how == "object":
        np.save(path, np.array([rows, "x"], dtype=object), allow_pickle=True)
    elif how == "pickle":
        import pickle

        path.write_bytes(pickle.dumps(rows))
    elif how == "structured":
        np.save(path, np.zeros((4, 17), dtype=[("a", "f8"), ("b", "i4")]))
    else:
        dtype = {"bool": bool, "int": np.int64, "float16": np.float16, "float32": np.float32,
                 "complex": np.complex128, "big-endian": ">f8", "string": "U8", "datetime": "M8[s]"}[how]
        np.save(path, rows.astype(dtype) if how != "datetime" else rows.astype(np.int64).astype(dtype))
    return f"{POSES}: dtype {how}"


def l_bytes(c: Case) -> str:
    path = c.folder / POSES
    data = bytearray(path.read_bytes())
    how = c.rng.choice(["truncated", "header", "magic", "version", "fortran", "shape claim", "empty", "garbage"])
    if how == "truncated":
        data = data[:c.rng.choice([0, 5, 10, 60, 127, len(data) - 8, len(data) - 1])]
    elif how == "header":
        k = c.rng.randrange(10, 120)
        data[k] = c.rng.choice(b"{}()':,0123456789 \x00\xff")
    elif how == "magic":
        data[0:6] = b"\x93NUMPX"
    elif how == "version":
        data[6] = c.rng.choice([0, 4, 9, 255])
    elif how == "fortran":
        data = bytearray(bytes(data).replace(b"'fortran_order': False", b"'fortran_order': True "))
    elif how == "shape claim":
        data = bytearray(bytes(data).replace(b"(4, 17)", c.rng.choice([b"(9, 17)", b"(4, 99)", b"(99999999999, 17)",
                                                                      b"(-4, 17)", b"(4, 1, 17)"])))
    elif how == "empty":
        data = bytearray()
    else:
        data = bytearray(c.rng.randbytes(len(data)))
    path.write_bytes(bytes(data))
    return f"{POSES}: {how}"


def l_mask(c: Case) -> str:
    from PIL import Image

    folder = c.folder / "masks_2"
    names = sorted(p.name for p in folder.iterdir())
    name = c.rng.choice(names)
    how = c.rng.choice(["missing", "size", "rgb", "rgba", "16 bit", "not an image", "truncated", "empty",
                        "ambiguous", "folder", "symlink out", "only masks/", "dangling"])
    path = folder / name
    if how == "missing":
        path.unlink()
    elif how == "size":
        Image.fromarray(np.zeros(c.rng.choice([(4, 5), (5, 6), (8, 12), (1, 1)]), np.uint8)).save(path)
    elif how in ("rgb", "rgba"):
        Image.fromarray(np.full((4, 6, 3 if how == "rgb" else 4), 200, np.uint8)).save(path)
    elif how == "16 bit":
        Image.fromarray(np.full((4, 6), 60000, np.uint16)).save(path)
    elif how == "not an image":
        path.write_bytes(b"not an image")
    elif how == "truncated":
        path.write_bytes(path.read_bytes()[:c.rng.randrange(1, 60)])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "ambiguous":
        shutil.copyfile(path, folder / name.replace("_mask.png", ".jpg"))
        shutil.copyfile(path, folder / name.replace("_mask.png", ".png"))
    elif how == "folder":
        path.unlink()
        path.mkdir()
    elif how == "symlink out":
        path.unlink()
        path.symlink_to(c.outside / "outside.png")
    elif how == "only masks/":
        folder.rename(c.folder / "masks")
    else:
        path.unlink()
        path.symlink_to(c.folder / "nowhere.png")
    return f"masks_2/{name}: {how}"


def l_images(c: Case) -> str:
    folder = c.folder / "images_2"
    names = sorted(p.name for p in folder.iterdir())
    name = c.rng.choice(names)
    how = c.rng.choice(["missing", "extra", "size", "not an image", "no folder", "images_0", "images_99999",
                        "a file", "empty folder"])
    if how == "missing":
        (folder / name).unlink()
    elif how == "extra":
        shutil.copyfile(folder / name, folder / "ZZZ.png")
    elif how == "size":
        _png(folder / name, w=c.rng.choice([5, 7, 12]), h=c.rng.choice([3, 4, 8]))
    elif how == "not an image":
        (folder / name).write_bytes(b"\x89PNG garbage")
    elif how == "no folder":
        shutil.rmtree(folder)
    elif how in ("images_0", "images_99999"):
        folder.rename(c.folder / how)
    elif how == "a file":
        shutil.rmtree(folder)
        folder.write_bytes(b"x")
    else:
        for n in names:
            (folder / n).unlink()
    return f"images_2/{name}: {how}"


LLFF_CLASSES: dict[str, Callable[[Case], str]] = {
    "npy value": l_value, "npy pose": l_pose, "npy shape": l_shape, "npy dtype": l_dtype, "npy bytes": l_bytes,
    "mask": l_mask, "image": l_images,
}

CLASSES = {"ngp": JSON_CLASSES, "blender": JSON_CLASSES, "colmap-text": COLMAP_CLASSES, "fox": JSON_CLASSES,
           "llff": LLFF_CLASSES}


def seed_files(kind: str, folder: Path) -> list[str]:
    if kind == "llff":
        return [POSES]
    if kind == "colmap-text":
        return [p.relative_to(folder).as_posix() for p in sorted((folder / "sparse" / "0").glob("*.txt"))]
    return sorted(p.name for p in folder.glob("transforms*.json"))


def make_outside(folder: Path) -> None:
    """What an escaping path would find: a valid image (as large as the seed's) and a PLY."""
    from plyfile import PlyData, PlyElement

    folder.mkdir(parents=True, exist_ok=True)
    _png(folder / "outside.png", seed=5)
    for name in ("v0.png", "v1.png", "v2.png", "0000.png", "0001.png", "0002.png", "0003.png", "r_0.png", "r_1.png",
                 "r_2.png"):
        _png(folder / name, seed=6, alpha=name.startswith("r_"))
    vertex = np.zeros(2, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    PlyData([PlyElement.describe(vertex, "vertex")]).write(str(folder / "outside.ply"))


def mutate(kind: str, klass: str, number: int, seed: Path, work: Path) -> str:
    """Copy ``seed`` to ``work/capture`` (with ``work/outside`` beside it), apply case
    (``kind``, ``klass``, ``number``); return its description."""
    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(seed, work / "capture", symlinks=True)
    make_outside(work / "outside")
    case = Case(work / "capture", work / "outside", random.Random(f"{kind}/{klass}/{number}"),
                seed_files(kind, seed))
    return CLASSES[kind][klass](case)


def inside(root: Path, rel: str) -> bool:
    """``rel`` names a file under ``root`` without leaving it lexically (no absolute path, no
    ``..`` above the folder); symlinks the user made inside the folder are followed."""
    norm = os.path.normpath(rel)
    return not os.path.isabs(rel) and norm != ".." and not norm.startswith("../") and (root / rel).is_file()


__all__ = ["SEEDS", "CLASSES", "JSON_CLASSES", "COLMAP_CLASSES", "LLFF_CLASSES", "mutate", "inside", "describe"]


def describe(kind: str, klass: str, number: int) -> str:
    return f"structured case ({kind!r}, {klass!r}, {number})"


def table(stats: dict[str, dict[str, int]]) -> str:
    """The markdown table of docs/robustness.md ("Captures from others") from the outcome
    counts that ``SPLATBENCH_FUZZ_STATS=fuzz.json pytest tests/test_fuzz.py -k structured``
    writes: one row per mutation class, one column per seed capture."""
    kinds = [("ngp", "instant-ngp `transforms.json`"), ("blender", "NeRF-synthetic `transforms_{train,test}.json`"),
             ("colmap-text", "COLMAP text model"), ("llff", "LLFF `poses_bounds.npy` + masks")]
    names = list(JSON_CLASSES) + [k for k in COLMAP_CLASSES if k not in JSON_CLASSES] + list(LLFF_CLASSES)
    from splatbench.report_files import markdown_table

    rows = []
    totals = {kind: {} for kind, _ in kinds}
    for klass in names:
        cells = []
        for kind, _ in kinds:
            counts = stats.get(f"{kind}: {klass}")
            if not counts:
                cells.append("–")
                continue
            for outcome, n in counts.items():
                totals[kind][outcome] = totals[kind].get(outcome, 0) + n
            cells.append(f"{sum(counts.values())}: {counts.get('ok', 0)} load, {counts.get('InputError', 0)} InputError"
                         + "".join(f", {n} {o}" for o, n in sorted(counts.items()) if o not in ("ok", "InputError")))
        rows.append([klass, *cells])
    rows.append(["**all**", *(f"**{sum(t.values())}: {t.get('ok', 0)} load, {t.get('InputError', 0)} InputError**"
                              for t in totals.values())])
    return markdown_table(["mutation class", *(label for _, label in kinds)], rows)


if __name__ == "__main__":  # python -m tests.structured_fuzzing fuzz.json
    import sys

    print(table(json.loads(Path(sys.argv[1]).read_text())))
