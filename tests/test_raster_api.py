"""The rasterizer's public boundary: shapes, one-line errors, lifetimes, edge cases."""

from __future__ import annotations

import inspect

import gc
import weakref

import numpy as np
import pytest
import torch

import splatbench
from splatbench import Camera, Gaussians, InputError
from splatbench.raster import compositing as composite_module
from splatbench.raster.options import RasterOptions
from splatbench.workloads import synthetic

GROUPS = ("means", "log_scales", "quats", "opacity_logits", "sh")


@pytest.fixture(scope="module")
def scene():
    return synthetic(300, 40, 32, seed=3)


def params(workload, requires_grad=True):
    return [torch.tensor(getattr(workload.gaussians, k), requires_grad=requires_grad) for k in GROUPS]


def test_render_result_shapes(scene):
    res = splatbench.render(scene.gaussians, scene.camera)
    assert res.rgb.shape == (32, 40, 3) and res.alpha.shape == (32, 40) and res.depth.shape == (32, 40)
    assert res.radii.shape == (300,) and res.radii.dtype == np.int32
    np.testing.assert_array_equal(res.visible, res.radii > 0)
    assert res.num_pairs > 0 and res.sh_degree == 3
    assert np.isfinite(res.rgb).all() and 0 <= res.alpha.min() and res.alpha.max() <= 1


def test_rasterize_info(scene):
    rgb, alpha, depth, info = splatbench.rasterize(*params(scene), scene.camera, absgrad=True)
    assert info.means2d_grad is None  # only after backward
    rgb.sum().backward()
    assert info.means2d_grad.shape == (300, 2) and info.means2d_absgrad.shape == (300, 2)
    # |sum of per-pixel terms| <= sum of |per-pixel terms|
    assert (info.means2d_grad.abs() <= info.means2d_absgrad + 1e-6).all()
    assert (info.means2d_grad[~info.visible] == 0).all()


def test_empty_scene_renders_background():
    cam = Camera(16, 12, 16.0, 16.0, 8.0, 6.0, np.eye(4))
    g = Gaussians(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0), np.zeros((0, 1, 3)))
    res = splatbench.render(g, cam, background=(0.2, 0.4, 0.6))
    np.testing.assert_allclose(res.rgb, np.broadcast_to([0.2, 0.4, 0.6], (12, 16, 3)), atol=1e-7)
    assert (res.alpha == 0).all() and (res.depth == 0).all()


def test_empty_model_backward_gives_empty_gradients():
    # a training run whose every Gaussian was pruned (reports/initialization: far from 29 SfM
    # points) still steps: its gradients are empty tensors of the parameters' shapes
    cam = Camera(16, 12, 16.0, 16.0, 8.0, 6.0, np.eye(4))
    shapes = ((0, 3), (0, 3), (0, 4), (0,), (0, 16, 3))
    leaves = [torch.zeros(s, requires_grad=True) for s in shapes]
    rgb, alpha, depth, info = splatbench.rasterize(*leaves, cam, background=(0.2, 0.4, 0.6), absgrad=True)
    (rgb.sum() + alpha.sum() + depth.sum()).backward()
    assert [tuple(p.grad.shape) for p in leaves] == list(shapes)
    # and densification reads empty screen-space gradients, not None
    assert tuple(info.means2d_grad.shape) == (0, 2) and tuple(info.means2d_absgrad.shape) == (0, 2)


def test_everything_behind_the_camera_gives_zero_gradients(scene):
    g = scene.gaussians
    flipped = [torch.tensor(g.means * np.array([1, 1, -1], np.float32), requires_grad=True)]
    rest = [torch.tensor(getattr(g, k), requires_grad=True) for k in GROUPS[1:]]
    rgb, _, _, info = splatbench.rasterize(*flipped, *rest, scene.camera)
    rgb.sum().backward()
    assert info.num_pairs == 0 and not info.visible.any()
    assert all((p.grad == 0).all() for p in flipped + rest)


@pytest.mark.parametrize("field, bad, message", [
    ("means", np.zeros((300, 2)), "means: expected shape [N, 3]"),
    ("quats", np.zeros((299, 4)), "quats: expected shape [N, 4] with N=300"),
    ("sh", np.zeros((300, 5, 3)), "sh: expected K in (1, 4, 9, 16)"),
])
def test_rasterize_rejects_bad_shapes(scene, field, bad, message):
    tensors = dict(zip(GROUPS, params(scene, requires_grad=False)))
    tensors[field] = torch.tensor(bad, dtype=torch.float32)
    with pytest.raises(InputError) as info:
        splatbench.rasterize(*tensors.values(), scene.camera)
    assert message in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("field", GROUPS)
def test_rasterize_rejects_non_finite_input_naming_the_field(scene, field):
    tensors = dict(zip(GROUPS, params(scene, requires_grad=False)))
    bad = tensors[field].clone()
    bad.view(-1)[7] = float("nan")
    tensors[field] = bad
    with pytest.raises(InputError, match=rf"^{field}: non-finite value nan at index"):
        splatbench.rasterize(*tensors.values(), scene.camera)


@pytest.mark.parametrize("options, message", [
    ({"tile_size": 12}, "tile_size: expected a power of two"),
    ({"alpha_min": 0.995}, "alpha_min: expected a value in (0, alpha_max)"),
    ({"radius": "5sigma"}, "radius: expected one of"),
    ({"eps2d": -1.0}, "eps2d: expected a finite value >= 0"),
    ({"tile_szie": 16}, "tile_szie: unknown key (did you mean 'tile_size'?)"),
    ({"sh_degree": 4}, "sh_degree: expected an int in 0..3, got 4"),
    ({"background": (1, 2)}, "background: expected 3 values in [0, 1]"),
    ({"background": (2, 0, 0)}, "background: expected 3 values in [0, 1], got [2, 0, 0]"),
    ({"near": 10, "far": 1}, "near: expected a value below far (1.0), got 10.0"),  # both given: RasterOptions says so
    ({"near": 2e10}, "near, far: expected near < far, got near=20000000000.0, far=10000000000.0"),
])
def test_render_rejects_bad_options(scene, options, message):
    with pytest.raises(InputError) as info:
        splatbench.render(scene.gaussians, scene.camera, **_split(options))
    assert message in str(info.value)


def _split(options: dict) -> dict:
    """``render``'s keyword arguments from one table: ``sh_degree`` and ``background`` as they are,
    the rest read into the typed ``options`` (`RasterOptions.from_dict`, where bad ones are caught)."""
    render_keys = ("sh_degree", "background")
    raster = {k: v for k, v in options.items() if k not in render_keys}
    return {**{k: v for k, v in options.items() if k in render_keys},
            **({"options": RasterOptions.from_dict(raster)} if raster else {})}


def test_options_are_a_raster_options_record(scene):
    """``options`` is typed: a dict (the keyword arguments of an older splatbench) is one line."""
    for call in (lambda: splatbench.render(scene.gaussians, scene.camera, options={"tile_size": 8}),
                 lambda: splatbench.rasterize(*params(scene), scene.camera, options={"tile_size": 8})):
        with pytest.raises(InputError, match=r"^options: expected splatbench.RasterOptions or None, got dict"):
            call()
    assert inspect.signature(splatbench.render).parameters["options"].annotation == "RasterOptions | None"
    assert inspect.signature(splatbench.rasterize).parameters["options"].annotation == "RasterOptions | None"


def test_sh_degree_larger_than_available_is_an_error(scene):
    g = scene.gaussians.with_sh_degree(1)
    with pytest.raises(InputError, match="sh_degree: 2 needs 9 SH bases, but sh has K=4"):
        splatbench.render(g, scene.camera, sh_degree=2)


def test_unused_sh_bands_get_zero_gradient(scene):
    tensors = params(scene)
    rgb, _, _, _ = splatbench.rasterize(*tensors, scene.camera, sh_degree=1)
    rgb.sum().backward()
    sh_grad = tensors[4].grad
    assert sh_grad[:, :4].abs().sum() > 0 and (sh_grad[:, 4:] == 0).all()


def test_compositing_ops_are_released(scene, monkeypatch):
    """Each call's op (bins, records, forward state) must be freed with its outputs:
    a reference cycle through Dr.Jit's C++ side would leak ~40 MB per call at 100k."""
    alive: list[weakref.ref] = []
    original = composite_module._CompositeOp.eval

    # Dr.Jit names a CustomOp's inputs after eval's parameters: keep them explicit.
    def eval_and_track(self, means2d, conics, opacities, colors, depths, cutoff_sq, state, cfg):
        alive.append(weakref.ref(self))
        return original(self, means2d, conics, opacities, colors, depths, cutoff_sq, state, cfg)

    monkeypatch.setattr(composite_module._CompositeOp, "eval", eval_and_track)
    for _ in range(3):
        rgb, _, _, info = splatbench.rasterize(*params(scene), scene.camera)
        rgb.sum().backward()
        assert info.means2d_grad is not None
        del rgb, info
        splatbench.render(scene.gaussians, scene.camera)
    gc.collect()
    assert len(alive) == 6 and all(ref() is None for ref in alive)


def test_parameters_changed_in_place_before_backward_are_an_error(scene):
    """Dr.Jit reads the parameters' memory in place (DLPack): torch's saved-tensor
    check must reject an in-place change between forward and backward, which would
    otherwise give the gradient of parameters that were never rendered."""
    tensors = params(scene)
    rgb, _, _, _ = splatbench.rasterize(*tensors, scene.camera)
    with torch.no_grad():
        tensors[0].add_(0.1)
    with pytest.raises(RuntimeError, match="modified by an inplace operation"):
        rgb.sum().backward()


def test_gradients_do_not_depend_on_the_input_layout(scene):
    """Non-contiguous and float64 parameters are copied to contiguous float32 before
    Dr.Jit views them; the gradients (returned in the parameters' own dtype by torch)
    equal those of the contiguous float32 case."""
    base = params(scene)
    rgb, _, _, _ = splatbench.rasterize(*base, scene.camera)
    rgb.sum().backward()
    means_t = torch.tensor(scene.gaussians.means.T.copy(), dtype=torch.float64).T.requires_grad_(True)
    assert not means_t.is_contiguous()
    other = [torch.tensor(getattr(scene.gaussians, k), requires_grad=True) for k in GROUPS[1:]]
    rgb2, _, _, _ = splatbench.rasterize(means_t, *other, scene.camera)
    rgb2.sum().backward()
    assert means_t.grad.dtype == torch.float64
    # Same float32 computation on the same values: identical bits (LLVM is deterministic).
    assert torch.equal(means_t.grad.float(), base[0].grad)
    assert all(torch.equal(a.grad, b.grad) for a, b in zip(other, base[1:]))


def test_render_and_rasterize_check_the_camera_the_same_way(scene):
    """One check (`check_view`) at both entry points: not a Camera, an image larger than
    the memory available now (30000² x 256 B per pixel is 230 GB), planes near >= far."""
    from splatbench.guards import image_size_problem

    cases = [({}, {}, r"^camera: expected splatbench.Camera, got dict$"),
             (scene.camera, {"near": 2e10}, r"^near, far: expected near < far")]  # near past the camera's far
    if image_size_problem(30_000, 30_000) is not None:  # always, but on a machine with 230 GB free
        huge = Camera(30_000, 30_000, 3e4, 3e4, 1.5e4, 1.5e4, np.eye(4))
        cases.append((huge, {}, r"^camera width, height: 30000x30000 needs about .* GiB"))
    for camera, options, message in cases:
        with pytest.raises(InputError, match=message) as by_render:
            splatbench.render(scene.gaussians, camera, **_split(options))
        with pytest.raises(InputError) as by_rasterize:
            splatbench.rasterize(*params(scene), camera, **_split(options))
        assert str(by_rasterize.value) == str(by_render.value)
