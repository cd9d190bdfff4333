"""The built-in backends (splatbench.backends) against the float64 reference, and the registry.

Forward. Every backend renders the parity scenes and is compared with
`reference_render(backend.info, ...)`: the oracle following the approximations the
backend *declares*. A float32 backend gets tests/test_raster_parity.py's derived
tolerance (ATOL = 2e-5 per pixel, strictly outside the boundary band the oracle derives:
the pixels where a discrete decision may flip between float32 and float64, `reference.band`).
``torch64`` computes in float64: (2 L + 20) u64 max|c| with L <= 400 terms, u64 = 1.1e-16
and |c| <= ~2 is ~2e-13, so 1e-12; its band is the float32 one, a superset of where float64
could decide differently (a float64 decision can still sit on a tie).

Gradients (random-cotangent VJPs on rgb, alpha and depth).
  * ``torch64`` against central differences of the exact reference (the
    ``reference-exact`` backend's own backward) on a smooth scene with every threshold
    switched off. FD error: truncation h^2 f'''/6 ~ 1e-12 and rounding u64 |loss| / h
    ~ 1e-10 |loss| for h = 1e-6; the smooth settings drop contributions below alpha 1e-9
    that the exact function keeps (relative ~1e-8). Bound: relative L2 <= 1e-6 (a
    float32 computation would be ~1e-5), cosine >= 1 - 1e-10.
  * ``drjit``, ``torch`` and ``gsplat`` against ``torch64`` built with the same declared
    conventions (`make_torch_matching`): a float32 gradient against the exact-arithmetic
    one is bounded by tests/test_raster_grads.py's float32 derivation (relative L2 <=
    1e-4, cosine >= 1 - 1e-8). Scenes: the standard, overlap and large parity kinds;
    the needle and tiny kinds have conics with condition numbers up to ~1e3, which
    multiplies the float32 error of the quaternion and mean gradients by as much.
"""

from __future__ import annotations

import importlib.util
import sys
from importlib import metadata

import numpy as np
import pytest
import torch

from splatbench.backends import Backend, BackendInfo, as_backend, available, get_backend
from splatbench.backends import registry
from splatbench.backends.builtins.reference_backend import reference_render
from splatbench.backends.builtins.torch_backend import make_torch_backend, make_torch_matching
from tests.assertions import one_line_error
from tests.compare import assert_grads_agree, assert_images_close, assert_render_close
from tests.gradcheck import GROUPS, Cotangents
from tests.scenes import parity_scene, smooth_scene
from tests.test_raster_parity import ATOL

ATOL64 = 1e-12
REL_L2, COSINE = 1e-4, 1 - 1e-8          # float32 vs float64 (tests/test_raster_grads.py)
REL_L2_FD, COSINE_FD = 1e-6, 1 - 1e-10   # float64 vs float64 finite differences
FORWARD_SEEDS = (0, 1, 3, 4, 7)          # standard, overlap, tiny, large, needles
GRAD_SEEDS = (0, 1, 4, 9)                # standard, overlap, large (SH degree 0), large (degree 1)

HAS_GSPLAT = importlib.util.find_spec("gsplat") is not None
needs_gsplat = pytest.mark.skipif(not HAS_GSPLAT, reason="gsplat not installed (pip install -e '.[gsplat]')")
FAST = ["drjit", "torch", "torch64", pytest.param("gsplat", marks=needs_gsplat)]


def tensors(workload, dtype=torch.float32, grad=False):
    g = workload.gaussians
    return [torch.tensor(getattr(g, k), dtype=dtype, requires_grad=grad) for k in GROUPS]


def vjp(backend: Backend, workload, v: Cotangents, background=None, dtype=torch.float32):
    params = tensors(workload, dtype, grad=True)
    outputs = backend(*params, workload.camera, background=background)
    v.loss(*outputs).backward()
    return [o.detach().double().numpy() for o in outputs], {k: p.grad.double().numpy() for k, p in
                                                            zip(GROUPS, params)}


# ------------------------------------------------------------------------------ forward
@pytest.mark.parametrize("seed", FORWARD_SEEDS)
@pytest.mark.parametrize("name", FAST)
def test_forward_matches_reference_under_declared_conventions(name, seed):
    backend = get_backend(name)
    workload, background = parity_scene(seed)
    with torch.no_grad():
        rgb, alpha, depth = (o.double().numpy() for o in backend(*tensors(workload), workload.camera,
                                                                  background=background))
    ref = reference_render(backend.info, *tensors(workload), workload.camera, background=background, band=True)
    # float64 backends: the float32 band is a superset of where float64 could decide differently
    atol = ATOL64 if backend.info.dtype == "float64" else ATOL
    assert_render_close(f"backend-{name}-{workload.name}", rgb, alpha, depth, ref, atol)


def test_drjit_backend_declares_the_options_it_was_made_with():
    from splatbench.backends.builtins.drjit_backend import make_drjit_backend

    backend = make_drjit_backend(radius="opacity", alpha_min=0.05, transmittance_min=0.05, tile_size=8)
    assert (backend.info.radius, backend.info.alpha_min, backend.info.tile_size) == ("opacity", 0.05, 8)
    workload, background = parity_scene(6)
    with torch.no_grad():
        rgb = backend(*tensors(workload), workload.camera, background=background)[0].double().numpy()
    ref = reference_render(backend.info, *tensors(workload), workload.camera, background=background, band=True)
    assert_images_close("backend-drjit-options", rgb, ref.rgb, ATOL, band=ref.band, slack=ref.tie_slack)


def test_declared_conventions_matter():
    """gsplat's declared alpha clamp (0.999) and radius rule differ from graphdeco's, and the
    comparison above would notice a wrong declaration: on the opaque overlap scene the
    graphdeco reference differs from the one following gsplat's declaration by far more than ATOL."""
    workload, background = parity_scene(1)
    gs_like = BackendInfo(name="x", alpha_max=0.999, radius="opacity")
    a = reference_render(gs_like, *tensors(workload), workload.camera, background=background)
    b = reference_render(None, *tensors(workload), workload.camera, background=background)
    assert np.abs(a.rgb - b.rgb).max() > 100 * ATOL


def test_reference_backends_are_the_oracle():
    workload, background = parity_scene(3)
    params = tensors(workload)
    for name, mode in (("reference", "matched"), ("reference-exact", "exact")):
        backend = get_backend(name)
        rgb, alpha, depth = backend(*params, workload.camera, background=background)
        ref = reference_render(backend.info, *params, workload.camera, mode=mode, background=background)
        np.testing.assert_array_equal(rgb.numpy(), ref.rgb)
        np.testing.assert_array_equal(depth.numpy(), ref.depth)
        assert backend.info.dtype == "float64" and backend.info.slow_gradients
    assert get_backend("reference-exact").info.exact and not get_backend("reference").info.exact


def test_reference_render_takes_raster_options():
    """The parity tests and the raster run kind pass `RasterOptions` fields: accelerations are
    dropped, a None near/far means the camera's, and anything else is named."""
    workload, _ = parity_scene(0)
    params = tensors(workload)
    a = reference_render({"tile_size": 8, "device": "cpu", "near": None, "radius": "opacity"}, *params,
                         workload.camera)
    b = reference_render(BackendInfo(name="x", radius="opacity"), *params, workload.camera)
    np.testing.assert_array_equal(a.rgb, b.rgb)
    one_line_error(lambda: reference_render({"tile": 8}, *params, workload.camera), "tile")
    one_line_error(lambda: reference_render(None, *params, workload.camera, mode="fast"), "mode")


# ---------------------------------------------------------------------------- gradients
def test_torch64_gradients_match_finite_differences():
    workload = smooth_scene(0)
    c = workload.camera
    v = Cotangents.standard_normal(100, c.height, c.width)
    # depth = sum / alpha: where alpha is tiny the dropped tails (alpha < 1e-9) are amplified by
    # 1 / alpha, so depth is weighted only where splats cover the pixel (as in test_raster_grads).
    exact = reference_render(None, *tensors(workload, torch.float64), c, mode="exact")
    v = Cotangents(v.rgb, v.alpha, v.depth * (exact.alpha > 0.05))
    smooth = make_torch_backend("float64", alpha_min=1e-9, radius="opacity", transmittance_min=0.0)
    exact_out, fd = vjp(get_backend("reference-exact"), workload, v, dtype=torch.float64)
    out, grads = vjp(smooth, workload, v, dtype=torch.float64)
    np.testing.assert_allclose(out[0], exact_out[0], atol=1e-8)  # the same smooth function (alpha tails < 1e-9)
    for k in GROUPS:
        assert_grads_agree(f"torch64 {k}", grads[k], fd[k], rel_l2=REL_L2_FD, cosine=COSINE_FD)


@pytest.mark.parametrize("seed", GRAD_SEEDS)
@pytest.mark.parametrize("name", ["drjit", "torch", pytest.param("gsplat", marks=needs_gsplat)])
def test_gradients_match_torch64(name, seed):
    backend = get_backend(name)
    oracle = make_torch_matching(backend.info, "float64")
    workload, background = parity_scene(seed)
    c = workload.camera
    v = Cotangents.standard_normal(seed, c.height, c.width)
    _, grads = vjp(backend, workload, v, background)
    _, exact = vjp(oracle, workload, v, background, dtype=torch.float64)
    for k in GROUPS:
        assert_grads_agree(f"{name} {workload.name} {k}", grads[k], exact[k], rel_l2=REL_L2, cosine=COSINE)


def test_torch_backend_gradients_stay_finite_for_culled_degenerate_gaussians():
    """A Gaussian behind the camera, one with a zero quaternion and one with an overflowing
    scale are culled or drawn without NaN in any gradient (culling decided before autograd)."""
    workload, _ = parity_scene(0)
    params = tensors(workload)
    with torch.no_grad():
        W = torch.tensor(workload.camera.world_to_camera, dtype=torch.float32)
        params[0][0] = -W[:3, :3].T @ W[:3, 3]  # at the camera centre: z = 0
        params[2][1] = 0.0                      # zero quaternion
        params[1][2] = 30.0                     # scale e^30, clipped at e^20, "too large" cull
    for p in params:
        p.requires_grad_(True)
    rgb, alpha, depth = get_backend("torch")(*params, workload.camera)
    (rgb.sum() + alpha.sum() + depth.sum()).backward()
    for k, p in zip(GROUPS, params):
        assert torch.isfinite(p.grad).all(), k


# ----------------------------------------------------------------------------- registry
def plain_rasterizer(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
    """A user backend: a flat grey image (enough to check the plumbing)."""
    H, W = camera.height, camera.width
    return torch.full((H, W, 3), 0.5), torch.ones(H, W), torch.zeros(H, W)


def test_builtins_are_listed_and_load():
    names = available()
    for name in ("drjit", "reference", "reference-exact", "torch", "torch64", "gsplat", "mitsuba"):
        assert name in names
    for name in ("drjit", "torch", "torch64", "reference"):
        backend = get_backend(name)
        assert isinstance(backend, Backend) and backend.name == name


def test_module_function_and_plain_callable():
    backend = get_backend("tests.test_backends:plain_rasterizer")
    assert backend.name == "tests.test_backends:plain_rasterizer" and backend.info.declared == ()
    workload, _ = parity_scene(0)
    rgb, _, _ = backend(*tensors(workload), workload.camera)
    assert rgb.shape == (workload.camera.height, workload.camera.width, 3)
    assert get_backend(plain_rasterizer).name.endswith("plain_rasterizer")
    assert as_backend(backend) is backend


def test_entry_point(monkeypatch):
    ep = metadata.EntryPoint(name="mine", value="tests.test_backends:plain_rasterizer",
                             group=registry.ENTRY_POINT_GROUP)
    real = metadata.entry_points

    def fake(**kwargs):
        return [ep] if kwargs.get("group") == registry.ENTRY_POINT_GROUP else real(**kwargs)

    monkeypatch.setattr(registry.metadata, "entry_points", fake)
    assert "mine" in available()
    backend = get_backend("mine")
    assert backend.name == "mine" and backend.fn is plain_rasterizer


def test_unknown_names_give_one_line():
    one_line_error(lambda: get_backend("nosuch"), "nosuch", "drjit", "module:function")
    one_line_error(lambda: get_backend("tests.test_backends:nosuch"), "nosuch")
    one_line_error(lambda: get_backend("no_such_module_xyz:fn"), "no_such_module_xyz")


def test_missing_gsplat_gives_the_install_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "gsplat", None)  # makes `import gsplat` raise ImportError
    msg = one_line_error(lambda: get_backend("gsplat"))
    assert msg == "backend: gsplat is not installed; run: pip install -e '.[gsplat]'"


@pytest.mark.parametrize("name", ["torch", pytest.param("gsplat", marks=needs_gsplat)])
def test_bad_input_names_the_field(name):
    workload, _ = parity_scene(0)
    params = tensors(workload)
    params[0][3, 1] = float("nan")
    one_line_error(lambda: get_backend(name)(*params, workload.camera), "means", "[3, 1]")
    params = tensors(workload)
    one_line_error(lambda: get_backend(name)(*params, workload.camera, sh_degree=3), "sh_degree")


# ------------------------------------------------------------------------------ mitsuba
def test_mitsuba_forward_is_the_validated_ray_tracer():
    """The backend renders what `splatbench.validate.mitsuba.render_traced` renders (the dedup
    integrator), and its alpha and depth are those of the same ray tracer: with a white
    constant colour the image is alpha. Tolerance: the backend's parameters reach Mitsuba through
    exp(log_scales) and a renormalised quaternion, a few float32 ulps (relative ~2.4e-7) from
    render_traced's, which moves a pixel by |d pixel / d parameter| ~ 10 times that: 1e-5."""
    from splatbench.validate import mitsuba as vm

    case = vm.overlap_cases(32)[2]
    g, c = case.gaussians, case.camera
    backend = get_backend("mitsuba")
    with torch.no_grad():
        params = tensors(case)
        rgb, alpha, depth = backend(*params, c)
        np.testing.assert_allclose(rgb.numpy(), vm.render_traced(g, c), rtol=0, atol=1e-5)
        params[4][:, 0, :] = 0.5 / 0.28209479177387814  # SH DC of colour 1: C0 * dc + 0.5
        white, alpha2, _ = backend(*params, c)
    np.testing.assert_allclose(white.numpy(), np.repeat(alpha.numpy()[..., None], 3, -1), rtol=0, atol=1e-5)
    np.testing.assert_array_equal(alpha2.numpy(), alpha.numpy())
    covered = alpha.numpy() > 0.05  # expected depth lies within the Gaussians' depth range where covered
    z = case.camera.project(g.means)[1]
    assert (depth.numpy()[covered] >= z.min() - 1e-3).all() and (depth.numpy()[covered] <= z.max() + 1e-3).all()
    assert backend.info.declared and "ray" in backend.info.description


@pytest.mark.slow
def test_mitsuba_gradients_match_its_finite_differences():
    """Mitsuba AD for SH (the image is linear in SH where colours are unclamped: central differences
    have no truncation error) and opacity logits (smooth; h = 1e-2 gives relative truncation
    ~h^2/6 ~ 2e-5) against central differences of the backend's own float32 forward. The FD noise
    is the forward's float32 rounding, ~1e-6 per pixel over 32x32x3 terms (~5e-5 in the loss),
    divided by 2h: ~5e-4 absolute for gradients of magnitude 0.1 to 30, so relative L2 <= 1e-2
    and cosine >= 1 - 1e-4. Means are not checked: AD leaves out the jump at the 3-sigma shell."""
    from splatbench.validate import mitsuba as vm

    case = vm.overlap_cases(32)[2]
    c = case.camera
    backend = get_backend("mitsuba")
    v = Cotangents.standard_normal(0, c.height, c.width)
    _, grads = vjp(backend, case, v)
    rng = np.random.default_rng(0)
    for group, h in (("sh", 0.05), ("opacity_logits", 0.01)):
        picked = rng.choice(grads[group].size, 8, replace=False)
        fd = []
        for i in picked:
            values = []
            for step in (h, -h):
                params = tensors(case)
                params[GROUPS.index(group)].view(-1)[int(i)] += step
                with torch.no_grad():
                    values.append(v.loss(*backend(*params, c)).item())
            fd.append((values[0] - values[1]) / (2 * h))
        assert_grads_agree(f"mitsuba {group}", grads[group].reshape(-1)[picked], np.array(fd), rel_l2=1e-2,
                           cosine=1 - 1e-4)


@needs_gsplat
def test_gsplat_cpu_pieces_are_installed_only_during_a_call():
    """The CPU stand-ins for gsplat's CUDA indexer and nerfacc are put back after each call."""
    from gsplat.cuda import _wrapper

    original = _wrapper.rasterize_to_indices_in_range
    had_nerfacc = "nerfacc" in sys.modules
    workload, _ = parity_scene(0)
    with torch.no_grad():
        get_backend("gsplat")(*tensors(workload), workload.camera)
    assert _wrapper.rasterize_to_indices_in_range is original
    assert ("nerfacc" in sys.modules) == had_nerfacc


def deep_tile_scene(fillers: int):
    """One 16x16 tile seen from the origin down +z: A (opacity 0.99) leaves T = 1e-2; B (0.995)
    would take T to 5e-5 <= 1e-4, so every pixel stops there and B and everything behind it is
    left out; ``fillers`` Gaussians of opacity 0.003 < 1/255 between them and C never contribute
    but sit in the tile's list (gsplat culls no opacity), pushing C (0.5, green) past entry
    25,600; C must not show. Arrays: means, log_scales, quats, opacity_logits, sh (float64)."""
    from splatbench.cameras import Camera

    rng = np.random.default_rng(0)
    big = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 2.1], [0.0, 0.0, 3.0]])             # A, B, C
    z = rng.uniform(2.2, 2.8, fillers)
    means = np.concatenate([big, np.c_[rng.uniform(-0.3, 0.3, (fillers, 2)) * z[:, None], z]])
    log_scales = np.concatenate([np.full((3, 3), np.log(20.0)), np.full((fillers, 3), np.log(0.01))])
    opacity = np.concatenate([[0.99, 0.995, 0.5], np.full(fillers, 0.003)])
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (len(means), 1))
    sh = np.zeros((len(means), 1, 3))
    sh[:, 0, 0] = 1.0
    sh[2, 0] = [-1.7, 1.7, -1.7]
    arrays = (means, log_scales, quats, np.log(opacity / (1 - opacity)), sh)
    return arrays, Camera(16, 16, 16.0, 16.0, 8.0, 8.0, np.eye(4))


@needs_gsplat
def test_gsplat_cpu_keeps_the_early_stop_in_a_tile_deeper_than_its_step():
    """gsplat 1.5.3's PyTorch `_rasterize_to_pixels` walks a tile's list in steps of
    ``batch_per_iter`` x 256 = 25,600 Gaussians and restarts each step from T = 1 - alpha with no
    record of which pixels stopped, so a pixel that stopped in the first step composites what lies
    behind the stop in the second (its CUDA kernel keeps the flag for the whole tile). Found on
    the guitar model (a tile of 39,704; reports/compare_models); the backend walks every tile in
    one step. With the fillers every pixel would otherwise differ by C's contribution (~6e-3 in
    alpha, far outside the float32 bound; the band is empty: no decision here is near a threshold)."""
    from splatbench.compare.measure import image_errors

    backend = get_backend("gsplat")
    for fillers in (0, 25_600):
        arrays, camera = deep_tile_scene(fillers)
        oracle = reference_render(backend.info, *arrays, camera, mode="matched", band=True)
        with torch.no_grad():
            out = backend(*[torch.tensor(a, dtype=torch.float32) for a in arrays], camera)
        errors = image_errors(out, oracle, ["rgb", "alpha", "depth"])
        assert int(oracle.band.sum()) == 0
        assert all(e.outside_band == 0 for e in errors.values()), (fillers, errors)
        assert abs(float(out[1][8, 8]) - oracle.alpha[8, 8]) < 1e-6  # A alone, then the stop


def test_user_module_that_fails_on_import_gives_one_line(tmp_path, monkeypatch):
    (tmp_path / "broken_syntax_rast.py").write_text("def render(:\n", encoding="utf-8")
    (tmp_path / "raising_rast.py").write_text("raise RuntimeError('no licence server')\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    one_line_error(lambda: get_backend("broken_syntax_rast:render"), "broken_syntax_rast", "SyntaxError",
                   "broken_syntax_rast.py:1")
    one_line_error(lambda: get_backend("raising_rast:render"), "raising_rast", "RuntimeError", "no licence server")


def test_no_cutoff_is_matched_by_the_opacity_rule():
    """radius="none" (a dense renderer) is rendered by the oracle with the "opacity" rule, which cuts
    exactly where the alpha_min skip drops a contribution anyway; the reference has no "none"."""
    assert BackendInfo(name="dense", radius="none").reference_options()["radius"] == "opacity"
    assert BackendInfo(name="plain").reference_options()["radius"] == "3sigma"


def test_registry_module_path_calls_a_factory(tmp_path, monkeypatch):
    """``module:callable`` naming a factory (annotated ``-> Backend`` or marked
    ``splatbench_backend_factory``) is called, as for an entry point; a render function is wrapped."""
    b = registry.get_backend("splatbench.backends.builtins.drjit_backend:make_drjit_backend")
    assert isinstance(b, Backend) and b.info.name == "drjit"
    (tmp_path / "user_factories.py").write_text(
        "from splatbench.backends import Backend, BackendInfo\n"
        "def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):\n"
        "    raise AssertionError('not called here')\n"
        "def marked():\n    return Backend(render, BackendInfo(name='marked'))\n"
        "marked.splatbench_backend_factory = True\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert registry.get_backend("user_factories:marked").info.name == "marked"
    plain = registry.get_backend("user_factories:render")
    assert plain.fn.__name__ == "render" and plain.info.name == "user_factories:render"
