"""`splatbench run --dry-run` checks the dataset folders its runs read (the trial's issue 1).

`splatbench.data.check_dataset` is `load_dataset` reading file names and image headers only:
the same cameras, names and sizes, the same one-line errors, and no pixel decoded. The
train kind's `check_inputs` runs it per scene and reading, and checks the served size
against what the run's metrics need; the dry run (and a real run, before anything starts)
refuses a bad scene in one line naming the scene, the file or field, and the fix. The
real captures in ../shared/data are checked when present.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from splatbench.cameras import Camera
from splatbench.data import check_dataset, load_dataset
from splatbench.data.llff import POSES_FILE, row_from_camera
from splatbench.errors import InputError
from tests.assertions import one_line_error

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
ORIGINAL, STORED, VIEWS = 512, 64, 9  # originals' side (poses_bounds), images_8/'s side, views


def _lpips_missing() -> str:
    from splatbench.metrics.perceptual import weights_path

    try:
        weights_path("alex")
        return ""
    except InputError as exc:
        return str(exc)


#: A run skips LPIPS without its weights (lpips_plan), and then needs no LPIPS-sized views.
needs_weights = pytest.mark.skipif(bool(_lpips_missing()), reason=_lpips_missing() or "weights installed")


def llff_capture(root: Path) -> Path:
    """A masked LLFF capture: ``VIEWS`` random 64x64 photos in images_8/ (originals 512 px),
    their masks in masks_8/ (NeRD's ``_mask`` names), rows of cameras on a circle."""
    rng = np.random.default_rng(0)
    (root / "images_8").mkdir(parents=True)
    (root / "masks_8").mkdir()
    rows = []
    for i in range(VIEWS):
        a = 2 * np.pi * i / VIEWS
        cam = Camera.look_at([4 * np.cos(a), 0.5, 4 * np.sin(a)], [0, 0, 0], [0, -1, 0], ORIGINAL, ORIGINAL, 40.0)
        rows.append(row_from_camera(Camera(ORIGINAL, ORIGINAL, cam.fx, cam.fx, ORIGINAL / 2, ORIGINAL / 2,
                                           cam.world_to_camera), 1.0, 9.0))
        Image.fromarray(rng.integers(0, 256, (STORED, STORED, 3), dtype=np.uint8)).save(root / "images_8" /
                                                                                        f"IMG_{i}.png")
        Image.fromarray(np.where(rng.random((STORED, STORED)) < 0.5, 255, 0).astype(np.uint8)).save(
            root / "masks_8" / f"IMG_{i}_mask.png")
    np.save(root / POSES_FILE, np.stack(rows))
    return root


def blender_capture(root: Path, *, distortion: bool = False) -> Path:
    """A transforms.json capture of 9 random 48x32 photos (OPENCV k1 when ``distortion``)."""
    rng = np.random.default_rng(1)
    (root / "images").mkdir(parents=True)
    frames = []
    for i in range(VIEWS):
        Image.fromarray(rng.integers(0, 256, (32, 48, 3), dtype=np.uint8)).save(root / "images" / f"{i:04d}.jpg")
        pose = np.eye(4)
        pose[:3, 3] = [0.3 * i, 0.0, 4.0]
        frames.append({"file_path": f"images/{i:04d}.jpg", "transform_matrix": pose.tolist()})
    meta = {"fl_x": 40.0, "fl_y": 40.0, "cx": 24.0, "cy": 16.0, "w": 48, "h": 32, "frames": frames}
    if distortion:
        meta.update(k1=-0.05, k2=0.01, p1=0.0, p2=0.0)
    (root / "transforms.json").write_text(json.dumps(meta))
    return root


def _no_decoding(monkeypatch) -> None:
    """Make every pixel decode, resize and undistortion fail: what check_dataset must not call."""
    def refuse(*args, **kwargs):
        raise AssertionError("decoded pixels")

    import splatbench.data.dataset as dataset
    import splatbench.data.undistort as undistort
    import splatbench.safeio as safeio

    for module, name in ((dataset, "read_image_with_alpha"), (dataset, "read_npy"), (dataset, "_resize"),
                         (dataset, "area_resize"), (safeio, "read_image"), (undistort, "undistort_views")):
        monkeypatch.setattr(module, name, refuse)


def _same_views(a, b) -> None:
    for sa, sb in ((a.train, b.train), (a.test, b.test)):
        assert sa.names == sb.names and sa.pixels.shape == sb.pixels.shape
        assert (sa.alpha_pixels is None) == (sb.alpha_pixels is None)
        for ca, cb in zip(sa.cameras, sb.cameras):  # exactly: the same code computed them
            assert (ca.width, ca.height, ca.fx, ca.fy, ca.cx, ca.cy) == (cb.width, cb.height, cb.fx, cb.fy, cb.cx, cb.cy)
            assert np.array_equal(ca.world_to_camera, cb.world_to_camera)


@pytest.mark.parametrize("layout, downscale", [("llff", 8), ("llff", 16), ("blender", 2), ("distorted", 2)])
def test_check_dataset_is_load_dataset_without_decoding(tmp_path, monkeypatch, layout, downscale):
    monkeypatch.setenv("SPLATBENCH_CACHE", str(tmp_path / "cache"))
    root = (llff_capture(tmp_path / "cap") if layout == "llff" else
            blender_capture(tmp_path / "cap", distortion=layout == "distorted"))
    loaded = load_dataset(root, downscale=downscale)
    from splatbench.data.dataset import _load

    _no_decoding(monkeypatch)
    checked = check_dataset(root, downscale=downscale)
    dry = _load(root, "auto", 8, "images", (0, 0, 0), downscale, True, None, headers_only=True)
    _same_views(loaded, dry)
    assert dry.train.pixels.strides[0] == 0  # zeros that take no memory
    height, width = loaded.train.image_size
    assert (checked.layout, checked.train_views, checked.test_views, checked.width, checked.height, checked.masks) == \
        (loaded.layout, len(loaded.train), len(loaded.test), width, height, loaded.masks)
    assert [n for n in checked.notes if "lens distortion" not in n] == \
        [n for n in loaded.notes if "lens distortion" not in n]
    if layout == "distorted":  # the undistorted size is pycolmap's camera, said as not run
        assert [n for n in checked.notes if "would be undistorted" in n and "not run: a dry check" in n]
    if layout == "llff":
        assert checked.masks == "masks_8" and (width, height) == (ORIGINAL // downscale,) * 2


def _drop_image(root):
    (root / "images_8" / "IMG_3.png").unlink()


def _drop_mask(root):
    (root / "masks_8" / "IMG_3_mask.png").unlink()


def _small_mask(root):
    Image.new("L", (32, 32)).save(root / "masks_8" / "IMG_3_mask.png")


def _wrong_aspect(root):
    Image.new("RGB", (64, 48)).save(root / "images_8" / "IMG_3.png")


def _no_poses(root):
    (root / POSES_FILE).unlink()


def _not_an_image(root):
    (root / "images_8" / "IMG_3.png").write_bytes(b"not a png")


@pytest.mark.parametrize("damage, downscale, parts", [
    (_drop_image, 8, [POSES_FILE, "9 rows for 8 images in images_8/"]),
    (_drop_mask, 8, ["masks_8/: no mask for images_8/IMG_3.png", "data.masks=false"]),
    (_small_mask, 8, ["masks_8/IMG_3_mask.png: mask size 32x32 differs", "re-export it"]),
    (_wrong_aspect, 8, ["images_8/IMG_3.png: image size 64x48 disagrees with its camera"]),
    (_no_poses, 8, ["holds neither a COLMAP model", "not a capture folder; give the folder"]),
    (_not_an_image, 8, ["images_8/IMG_3.png: not an image Pillow can decode", "replace it"]),
    (None, 4, ["data.downscale=4: no image folder serves it", "available factors 8 from images_8/",
               "set data.downscale to one of them or larger"]),
    (None, 2.5, ["downscale: expected an int >= 1, got 2.5"]),
])
def test_a_bad_capture_is_the_loaders_one_line_without_decoding(tmp_path, monkeypatch, damage, downscale, parts):
    root = llff_capture(tmp_path / "cap")
    if damage is not None:
        damage(root)
    at_load = one_line_error(lambda: load_dataset(root, downscale=downscale), *parts)
    _no_decoding(monkeypatch)
    assert one_line_error(lambda: check_dataset(root, downscale=downscale), *parts) == at_load


def _experiment(tmp_path: Path, scene: str, base: str = "") -> Path:
    path = tmp_path / "exp.toml"
    path.write_text(f'name = "dry"\nkind = "train"\nscenes = [{scene}]\nseeds = [0]\n[base]\niterations = 20\n{base}')
    return path


def _dry_run(path: Path, results: Path):
    from splatbench.cli import main

    return CliRunner().invoke(main, ["run", str(path), "--dry-run", "--results", str(results)])


@pytest.mark.parametrize("scene, base, parts", [
    ('{ name = "cap", path = "cap", downscale = 4 }', "",
     ["scenes.cap: data.downscale=4: no image folder serves it", "set data.downscale to one of them or larger"]),
    ('{ name = "cap", path = "cap", downscale = 0 }', "", ["scenes.cap.downscale: expected an int >= 1, got 0"]),
    ('{ name = "cap", path = "cap", downscale = -8 }', "", ["scenes.cap.downscale: expected an int >= 1, got -8"]),
    ('{ name = "cap", path = "cap", downscale = 2.5 }', "", ["scenes.cap.downscale: expected an int >= 1, got 2.5"]),
    # 512 / 20 = 25.6 -> 26 px: LPIPS's AlexNet needs 31 (MIN_SIDE); the largest downscale giving 31 is 16
    pytest.param('{ name = "cap", path = "cap", downscale = 20 }', "",
                 ["scenes.cap: data.downscale=20: its views are 26x26 px, under the 31 px a side that LPIPS with "
                  "alex", "set the scene's downscale to at most about 16", 'eval.lpips_net = "none"'],
                 marks=needs_weights),
    # without LPIPS the SSIM window (11: 6 px) is what the views need: 512 / 128 = 4 px
    ('{ name = "cap", path = "cap", downscale = 128 }', 'eval.lpips_net = "none"\n',
     ["scenes.cap: data.downscale=128: its views are 4x4 px, under the 6 px a side that SSIM's 11-px window"]),
    ('{ name = "cap", path = "cap/images_8" }', "", ["scenes.cap: dataset:", "images_8' holds neither a COLMAP",
                                                      "give the folder that holds one of them"]),
])
def test_dry_run_refuses_a_bad_scene_in_one_line(tmp_path, scene, base, parts):
    llff_capture(tmp_path / "cap")
    out = _dry_run(_experiment(tmp_path, scene, base), tmp_path / "results")
    assert out.exit_code != 0
    lines = out.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("splatbench: error: ") and "Traceback" not in out.output, out.output
    for part in parts:
        assert part in lines[0], (part, lines[0])
    assert not (tmp_path / "results").exists()


def test_dry_run_lists_a_good_scene_with_what_it_reads_and_a_real_run_refuses_before_anything(tmp_path):
    from splatbench.experiments.grid import load_experiment
    from splatbench.experiments.runner import run_experiment

    llff_capture(tmp_path / "cap")
    out = _dry_run(_experiment(tmp_path, '{ name = "cap", path = "cap", downscale = 16 }'), tmp_path / "results")
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()
    assert lines[0].split()[1:3] == ["pending", "cap"]
    assert lines[1] == (f"scene cap: {tmp_path / 'cap'}: llff, 7 train and 2 test views of 32x32 px "
                        f"(data.downscale=16; images_8/ reduced by 2 on load; masks_8/ as alphas)")
    (tmp_path / "cap" / "masks_8" / "IMG_5_mask.png").unlink()
    spec = load_experiment(_experiment(tmp_path, '{ name = "cap", path = "cap", downscale = 16 }'))
    one_line_error(lambda: run_experiment(spec, results_dir=tmp_path / "results", progress=False),
                   "exp.toml: scenes.cap: masks_8/: no mask for images_8/IMG_5.png")
    assert not (tmp_path / "results").exists()  # refused before any folder, dataset or worker


@pytest.mark.skipif(not (SHARED / "maryrose" / POSES_FILE).is_file() or not (SHARED / "fox").is_dir(),
                    reason="needs ../shared/data (maryrose, ethiopian_head, fox)")
def test_real_captures_dry_run_keeps_the_committed_run_ids_and_refuses_a_bad_downscale(tmp_path):
    # Every committed run record of a grid on the real captures keeps its run id: the reader gives
    # the dataset the same content hash. A stale report's grid has changed on purpose (STALE.md).
    checked = []
    for name in ("sh_degree", "loss_weighting", "densification_schedules", "densification"):
        committed = {p.stem for p in (ROOT / "reports" / name / "runs").glob("*.json")}
        if not committed or (ROOT / "reports" / name / "STALE.md").is_file():
            continue
        out = _dry_run(ROOT / "experiments" / f"{name}.toml", tmp_path / "results")
        assert out.exit_code == 0, out.output
        listed = {line.split()[0] for line in out.output.splitlines() if line.split()[1:2] == ["pending"]}
        assert committed <= listed, f"{name}: committed runs no longer in its grid: {sorted(committed - listed)}"
        checked.append(out)
    assert checked, "no committed grid on the real captures to check"
    said = [line for line in checked[0].output.splitlines()
            if line.startswith(("scene fox:", "scene maryrose:", "scene ethiopian_head:"))]
    shared = SHARED.resolve()  # the folder as the dry run names it: links resolved (../shared may be one)
    assert said == [f"scene fox: {shared / 'fox'}: blender, 58 train and 9 test views of 89x158 px "
                    f"(data.downscale=12; OPENCV lens distortion undistorted by pycolmap)",
                    f"scene maryrose: {shared / 'maryrose'}: llff, 60 train and 9 test views of 144x144 px "
                    f"(data.downscale=24; images_8/ reduced by 3 on load; masks_8/ as alphas)",
                    f"scene ethiopian_head: {shared / 'ethiopian_head'}: llff, 57 train and 9 test views of 160x160 "
                    f"px (data.downscale=25; images_8/ reduced by 3.125 on load; masks_8/ as alphas)"]
    scene = f'{{ name = "maryrose", path = "{SHARED / "maryrose"}", downscale = 4 }}'
    out = _dry_run(_experiment(tmp_path, scene), tmp_path / "results")
    assert out.exit_code != 0 and len(out.output.strip().splitlines()) == 1
    assert "scenes.maryrose: data.downscale=4: no image folder serves it" in out.output
    assert "available factors 8 from images_8/" in out.output


class _TestSplit:
    """What `lpips_plan` reads of a test split: its length and (H, W)."""

    def __init__(self, count: int, size: tuple[int, int]):
        self.count, self.image_size = count, size

    def __len__(self) -> int:
        return self.count


@needs_weights
@pytest.mark.parametrize("side, net, final, curves", [
    (31, "alex", ["alex"], ["alex"]),  # AlexNet's MIN_SIDE exactly: both computed
    (30, "alex", [], []),              # one pixel short: AlexNet in neither (it would fail inside the net)
    (20, "vgg", ["vgg"], []),          # VGG needs 16, the curves' AlexNet 31: the final VGG is kept
    (15, "vgg", [], []),
])
def test_a_run_skips_each_lpips_net_its_test_images_are_too_small_for(side, net, final, curves):
    """The training loop's LPIPS plan drops a net whose first layers need more pixels a side than
    the test images have (MIN_SIDE), with a note naming it, instead of failing at the first
    evaluation; a grid is refused up front by the dry run instead (above)."""
    from splatbench.metrics.perceptual import weights_path
    from splatbench.train.config import EvalConfig, TrainConfig
    from splatbench.train.loop import lpips_plan

    try:
        weights_path("vgg")
    except InputError:
        pytest.skip("VGG weights not installed")
    cfg = TrainConfig(eval=EvalConfig(lpips_net=net))
    got_final, got_curves, note = lpips_plan(cfg, _TestSplit(3, (side, side + 7)))
    assert [n for n, _ in got_final] == final and [n for n, _ in got_curves] == curves
    assert (note == "") == (final == [net] and curves == ["alex"]), note
    if note:
        assert f"{side + 7}x{side} px" in note
