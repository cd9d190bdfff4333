"""LPIPS (splatbench.metrics.lpips): published values, a second computation, the weight loader."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from reference.lpips import lpips as lpips_numpy
from splatbench import InputError
from splatbench.metrics import lpips
from splatbench.metrics.perceptual import load_checkpoint, load_weights, weights_path

#: PerceptualSimilarity's example images (`imgs/ex_ref.png`, `ex_p0.png`, `ex_p1.png` of
#: richzhang/PerceptualSimilarity), bundled with their BSD-2 LICENSE beside them
#: (tests/data/perceptual_similarity/README.md says where they come from).
EXAMPLES = Path(__file__).resolve().parent / "data" / "perceptual_similarity"
REPO = Path(__file__).resolve().parents[1]

try:
    weights_path("alex"), weights_path("vgg")
    MISSING = ""
except InputError as exc:
    MISSING = str(exc)
needs_weights = pytest.mark.skipif(bool(MISSING), reason=MISSING)


def example(name: str) -> np.ndarray:
    """[64, 64, 3] float32 in [0, 1], as lpips.load_image reads it (RGB, /255)."""
    return np.asarray(Image.open(EXAMPLES / f"ex_{name}.png").convert("RGB"), dtype=np.float32) / 255


def made(name: str) -> np.ndarray:
    """[64, 64, 3] float32 in [0, 1] made here: a smooth textured reference ("ref"), the same with
    noise ("p0") and blurred ("p1") -- distortions of the kinds LPIPS ranks, with distances of order 0.1."""
    from scipy.ndimage import gaussian_filter
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:64, 0:64] / 64.0
    base = np.stack([0.5 + 0.3 * np.sin(2 * np.pi * (3 * x + c) + 4 * y) for c in (0.0, 0.3, 0.6)], axis=-1)
    ref = np.clip(base + gaussian_filter(rng.normal(0, 0.15, (64, 64, 3)), (1.5, 1.5, 0)), 0, 1)
    if name == "p0":
        return np.clip(ref + rng.normal(0, 0.08, ref.shape), 0, 1).astype(np.float32)
    if name == "p1":
        return gaussian_filter(ref, (2.0, 2.0, 0)).astype(np.float32)
    return ref.astype(np.float32)


#: The published distances are printed to 3 decimals, so the true value lies within half a unit of
#: the last place of the printed one: +-0.0005. Nothing is added for float32 (its rounding moves
#: these distances by ~1e-6, see TOL below) or for the CPU/GPU difference of the authors' run.
PUBLISHED_ROUNDING = 0.0005


@needs_weights
@pytest.mark.parametrize("other,published", [("p0", 0.569), ("p1", 0.422)])
def test_vgg_reproduces_the_published_distances(other, published):
    # PerceptualSimilarity's README example: LPIPS-VGG v0.1 of (ex_ref, ex_p0) and (ex_ref, ex_p1),
    # printed to 3 decimals by lpips_2imgs.py / test_network.py (inputs scaled to [-1, 1]).
    assert lpips(example(other), example("ref"), net="vgg") == pytest.approx(published, abs=PUBLISHED_ROUNDING)


def test_the_examples_are_bundled_with_their_licence():
    """The published-values test runs on a clean clone: the images and the BSD-2 licence are here."""
    for name in ("ex_ref.png", "ex_p0.png", "ex_p1.png", "LICENSE", "README.md"):
        assert (EXAMPLES / name).is_file(), name
    assert "Redistributions of source code must retain the above copyright notice" in (EXAMPLES / "LICENSE").read_text()
    assert "richzhang/PerceptualSimilarity" in (EXAMPLES / "README.md").read_text()
    assert example("ref").shape == (64, 64, 3)


def test_the_examples_are_not_packaged():
    """Test data stays out of the wheel: the packages setuptools finds with pyproject's
    patterns are splatbench and reference (no tests package), and package data is declared
    for splatbench alone."""
    import tomllib

    from setuptools import find_packages

    tool = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = find_packages(str(REPO), include=tool["packages"]["find"]["include"])
    assert found and {name.split(".")[0] for name in found} <= {"splatbench", "reference"}, found
    assert set(tool.get("package-data", {})) <= {"splatbench"}


# float32 torch against float64 NumPy on the same weights: the features pass ~13 layers of sums of
# up to 4,608 products; float32 rounding (6e-8 relative per operation) stays orders of magnitude
# below 1e-5 on distances of order 0.1-1, while a wrong kernel transpose, tap, pooling or scaling
# moves them by more than 1e-2.
TOL = 1e-5


@needs_weights
@pytest.mark.parametrize("net,scale_inputs,others", [("alex", True, ("p0", "p1")), ("alex", False, ("p0", "p1")),
                                                     ("vgg", False, ("p1",))])  # VGG in NumPy: ~1 s a pair
def test_matches_an_independent_numpy_forward_pass(net, scale_inputs, others):
    weights = load_weights(net)
    ref = made("ref")[:, :56]  # not square: a height/width swap of the kernels would show
    for other in others:
        img = made(other)[:, :56]
        want = lpips_numpy(weights, img, ref, net, scale_inputs)
        assert lpips(img, ref, net=net, scale_inputs=scale_inputs) == pytest.approx(want, abs=TOL)


@needs_weights
def test_batches_tensors_and_identity():
    ref, p0, p1 = made("ref"), made("p0"), made("p1")
    batch = lpips(torch.from_numpy(np.stack([p0, p1])), torch.from_numpy(np.stack([ref, ref])))
    assert batch.shape == (2,)
    assert batch[0] == pytest.approx(lpips(p0, ref), abs=TOL) and batch[1] == pytest.approx(lpips(p1, ref), abs=TOL)
    assert lpips(ref, ref) == pytest.approx(0.0, abs=1e-7)
    assert lpips(p0, ref, scale_inputs=False) != pytest.approx(lpips(p0, ref), abs=1e-3)  # the flag matters


@needs_weights
@pytest.mark.parametrize("pred,target,message", [
    (np.zeros((32, 32, 3)), np.zeros((32, 33, 3)), "one shape"),
    (np.zeros((8, 8, 3)), np.zeros((8, 8, 3)), "too small"),
    (np.zeros((30, 40, 3)), np.zeros((30, 40, 3)), "too small"),  # AlexNet's pools need 31 px per side
    (np.full((32, 32, 3), np.nan), np.zeros((32, 32, 3)), "NaN"),
    (np.zeros((32, 32, 3)), np.full((32, 32, 3), 2.0), "expected [0, 1]"),
])
def test_bad_input_is_one_line(pred, target, message):
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        lpips(pred, target)
    with pytest.raises(InputError, match="net: expected"):
        lpips(np.zeros((32, 32, 3)), np.zeros((32, 32, 3)), net="squeeze")


class _Evil:
    def __reduce__(self):
        return (print, ("ran code from a weight file",))


@pytest.mark.parametrize("payload,message", [
    (pickle.dumps({"a": _Evil()}), "refused global builtins.print"),
    (pickle.dumps({"a": {"kernel": np.zeros(3, dtype=np.int64)}}), "refused dtype"),
    (pickle.dumps({"a": np.zeros(3, dtype=object)}), "refused dtype"),
    (pickle.dumps({"a": {"kernel": np.zeros((2, 2), dtype=np.float32)}})[:60], "not an LPIPS weight file"),
    (pickle.dumps({"a": [1, 2]}), "not a finite float32 array"),
])
def test_the_unpickler_builds_float32_arrays_only(tmp_path, capsys, payload, message):
    path = tmp_path / "w.ckpt"
    path.write_bytes(payload)
    with pytest.raises(InputError, match=message) as info:
        load_checkpoint(path)
    assert "\n" not in str(info.value) and "ran code" not in capsys.readouterr().out
    good = {"a": {"kernel": np.arange(6, dtype=np.float32).reshape(2, 3)}}
    path.write_bytes(pickle.dumps(good))
    np.testing.assert_array_equal(load_checkpoint(path)["a"]["kernel"], good["a"]["kernel"])
