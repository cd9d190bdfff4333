"""The ``gsplat`` backend: gsplat 1.5.3 (Apache-2.0, optional extra ``pip install -e '.[gsplat]'``).

On a CUDA device: its fused `gsplat.rasterization` (``render_mode="RGB+ED"``).
On the CPU: its own PyTorch implementation, `gsplat.cuda._torch_impl` --
`_quat_scale_to_covar_preci`, `_fully_fused_projection`, `_spherical_harmonics`,
`_isect_tiles`, `_isect_offset_encode`, `_rasterize_to_pixels` -- with CPU versions of
the three pieces it takes from elsewhere: `rasterize_to_indices_in_range` (a CUDA
kernel of gsplat's extension) and nerfacc's `render_weight_from_alpha` and
`accumulate_along_rays` (packed volume rendering). They are installed only for the
duration of a call (`_cpu_pieces`).

Conventions (read from gsplat 1.5.3's code, `cuda/_torch_impl.py` and
`cuda/csrc/RasterizeToIndices3DGS.cu`, `include/Common.h`):
  * inputs: activated ``scales = exp(log_scales)`` (no clip), ``opacities = sigmoid(logits)``,
    quats (w, x, y, z) normalised by `F.normalize`; ``viewmats = world_to_camera``, ``Ks = K``;
  * SH: graphdeco's bases and signs, colour ``max(sh(dir) + 0.5, 0)``, dir = mean - camera centre;
  * eps2d 0.3 and graphdeco's Jacobian clamp; no "too large" cull;
  * per pixel: ``alpha = min(0.999, o·exp(-sigma))`` (alpha_max 0.999), skipped when
    ``alpha < 1/255``, stop when ``T·(1 - alpha) <= 1e-4`` (exclusive);
  * no per-pixel radius test: a Gaussian reaches the 16-pixel tiles its box of
    ``ceil(3.33·sqrt(Σ2D_xx))`` x ``ceil(3.33·sqrt(Σ2D_yy))`` touches (CUDA: 3.33 capped at
    ``sqrt(2 ln(o·255))``). Every pixel with ``o·exp(-sigma) >= 1/255`` lies inside that box
    (``sqrt(2 ln 255) = 3.329 < 3.33``), so the image is the alpha_min rule alone: the
    reference's ``radius="opacity"``.
  * depth: the fourth channel accumulates camera z and is divided by alpha ("ED").

A bug of gsplat 1.5.3's PyTorch path, worked around on the CPU (`_render_cpu`): its
`_rasterize_to_pixels` walks each tile's list in steps of ``batch_per_iter`` (100) x 256 =
25,600 Gaussians and starts each step from ``T = 1 - alpha`` with no record of the pixels that
had stopped (the kernel's ``done`` flag lives for one call), so a pixel that stopped in one step
composites what lies behind the stop in the next; it also ends the walk after a step that
contributed nothing. Its CUDA kernel keeps the flag for the whole tile. Here every tile is
walked in one step (``batch_per_iter`` = the deepest tile's batches), as CUDA does. It showed
on the guitar model, whose deepest tile holds 39,704 Gaussians at 128x128 (reports/compare_models:
14-22 pixels outside the band before; `tests/test_backends.py`, the deep-tile case).
"""

from __future__ import annotations

import contextlib
import sys
import types

from splatbench.backends.base import Backend, BackendInfo
from splatbench.devices import torch_device
from splatbench.errors import InputError

VERSION = "1.5.3"
TILE = 16
ALPHA_MIN = 1.0 / 255.0  # gsplat include/Common.h ALPHA_THRESHOLD
ALPHA_MAX = 0.999        # RasterizeToIndices3DGS.cu: min(0.999f, opac * exp(-sigma))
T_STOP = 1e-4            # next_trans <= 1e-4: the pixel is done, this Gaussian excluded
EPS2D = 0.3
INSTALL = "backend: gsplat is not installed; run: pip install -e '.[gsplat]'"


def _import_gsplat():
    try:
        import gsplat
    except ImportError:
        raise InputError(INSTALL) from None
    return gsplat


# ----------------------------------------------------------------------------
# CPU versions of the pieces `_rasterize_to_pixels` imports from CUDA code
# ----------------------------------------------------------------------------

def _rasterize_to_indices_in_range(range_start, range_end, transmittances, means2d, conics, opacities,
                                   image_width, image_height, tile_size, isect_offsets, flatten_ids):
    """CPU `gsplat.cuda._wrapper.rasterize_to_indices_in_range` (the RasterizeToIndices3DGS kernel):
    the (gaussian, pixel, image) pairs that contribute, front to back, for the Gaussians of
    batches [range_start, range_end) of each tile, starting from ``transmittances``."""
    import torch

    with torch.no_grad():
        I = transmittances.reshape(-1, image_height, image_width).shape[0]
        th, tw = isect_offsets.shape[-2:]
        N = means2d.shape[-2]
        m2 = means2d.reshape(I * N, 2)
        con = conics.reshape(I * N, 3)
        opa = opacities.reshape(I * N)
        trans = transmittances.reshape(I, image_height * image_width)
        offsets = isect_offsets.reshape(-1).tolist() + [len(flatten_ids)]
        block = tile_size * tile_size
        out_g, out_p, out_i = [], [], []
        for tile in range(I * th * tw):
            image, rest = divmod(tile, th * tw)
            ty, tx = divmod(rest, tw)
            lo = offsets[tile] + range_start * block
            hi = min(offsets[tile + 1], offsets[tile] + range_end * block)
            if lo >= hi:
                continue
            ids = flatten_ids[lo:hi].long()  # depth-sorted flat ids in [I * N]
            ys = torch.arange(ty * tile_size, min((ty + 1) * tile_size, image_height))
            xs = torch.arange(tx * tile_size, min((tx + 1) * tile_size, image_width))
            if len(ys) == 0 or len(xs) == 0:
                continue
            pix = (ys[:, None] * image_width + xs[None, :]).reshape(-1)
            px = (pix % image_width).float() + 0.5
            py = (pix // image_width).float() + 0.5
            dx = m2[ids, 0][None, :] - px[:, None]
            dy = m2[ids, 1][None, :] - py[:, None]
            sigma = 0.5 * (con[ids, 0] * dx * dx + con[ids, 2] * dy * dy) + con[ids, 1] * dx * dy
            alpha = torch.clamp_max(opa[ids] * torch.exp(-sigma), ALPHA_MAX)
            used = ~((sigma < 0) | (alpha < ALPHA_MIN))
            a = torch.where(used, alpha, torch.zeros_like(alpha))
            next_T = trans[image, pix][:, None] * torch.cumprod(1 - a, dim=1)
            used &= ~(torch.cummax((next_T <= T_STOP).int(), dim=1).values.bool())  # done is sticky
            p_idx, k_idx = torch.nonzero(used, as_tuple=True)  # row-major: per pixel, front to back
            out_g.append(ids[k_idx] % N)
            out_p.append(pix[p_idx])
            out_i.append(torch.full_like(p_idx, image))
        if not out_g:
            empty = torch.zeros(0, dtype=torch.int64)
            return empty, empty, empty
        return torch.cat(out_g), torch.cat(out_p), torch.cat(out_i)


def _render_weight_from_alpha(alphas, ray_indices=None, n_rays=None):
    """CPU nerfacc.render_weight_from_alpha for packed samples (each ray's samples contiguous,
    front to back): trans = exclusive product of (1 - alpha) along the ray, weights = trans·alpha."""
    import torch

    order = torch.argsort(ray_indices, stable=True)
    rays = ray_indices[order]
    starts = torch.searchsorted(rays, rays, side="left")
    pos = torch.arange(len(rays)) - starts
    length = int(pos.max()) + 1 if len(rays) else 1
    dense = torch.ones(n_rays, length + 1, dtype=alphas.dtype)
    dense = dense.index_put((rays, pos + 1), 1 - alphas[order])
    trans_sorted = torch.cumprod(dense, dim=1)[rays, pos]
    trans = torch.empty_like(trans_sorted).scatter(0, order, trans_sorted)
    return trans * alphas, trans


def _accumulate_along_rays(weights, values=None, ray_indices=None, n_rays=None):
    """CPU nerfacc.accumulate_along_rays: per ray, the sum of weights·values ([n_rays, D])."""
    import torch

    src = weights[:, None] if values is None else weights[:, None] * values
    out = torch.zeros(n_rays, src.shape[-1], dtype=src.dtype)
    return out.index_add(0, ray_indices, src)


@contextlib.contextmanager
def _cpu_pieces():
    """Install the CPU pieces where `_rasterize_to_pixels` looks them up, for one call."""
    from gsplat.cuda import _wrapper

    shim = types.ModuleType("nerfacc")
    shim.render_weight_from_alpha = _render_weight_from_alpha
    shim.accumulate_along_rays = _accumulate_along_rays
    saved_fn = _wrapper.rasterize_to_indices_in_range
    saved_mod = sys.modules.get("nerfacc")
    _wrapper.rasterize_to_indices_in_range = _rasterize_to_indices_in_range
    sys.modules["nerfacc"] = shim
    try:
        yield
    finally:
        _wrapper.rasterize_to_indices_in_range = saved_fn
        if saved_mod is None:
            sys.modules.pop("nerfacc", None)
        else:
            sys.modules["nerfacc"] = saved_mod


# ----------------------------------------------------------------------------
# The two paths
# ----------------------------------------------------------------------------

def _render_cpu(means, scales, quats, opacities, sh, camera, degree, background):
    import torch
    from gsplat.cuda import _torch_impl as gs

    W, H = camera.width, camera.height
    viewmats = torch.tensor(camera.world_to_camera, dtype=torch.float32)[None]  # [1, 4, 4]
    Ks = torch.tensor(camera.K, dtype=torch.float32)[None]                       # [1, 3, 3]
    covars, _ = gs._quat_scale_to_covar_preci(quats, scales, compute_preci=False, triu=False)
    radii, means2d, depths, conics, _ = gs._fully_fused_projection(
        means, covars, viewmats, Ks, W, H, eps2d=EPS2D, near_plane=camera.near, far_plane=camera.far)
    campos = torch.tensor(camera.center, dtype=torch.float32)
    colors = torch.clamp_min(gs._spherical_harmonics(degree, means - campos, sh) + 0.5, 0.0)  # [N, 3]
    features = torch.cat([colors[None], depths[..., None]], dim=-1)                              # [1, N, 4]
    tw, th = (W + TILE - 1) // TILE, (H + TILE - 1) // TILE
    _, isect_ids, flatten_ids = gs._isect_tiles(means2d, radii, depths, TILE, tw, th)
    offsets = gs._isect_offset_encode(isect_ids, 1, tw, th)                                      # [1, th, tw]
    bg = torch.tensor([*background, 0.0], dtype=torch.float32)[None]
    # every tile in one step: gsplat's stepping loses the early stop between steps (module doc)
    depth = torch.diff(torch.cat([offsets.flatten(), torch.tensor([len(flatten_ids)])]))
    batches = max(1, -(-int(depth.max()) // (TILE * TILE))) if len(depth) else 1
    with _cpu_pieces():
        render, alphas = gs._rasterize_to_pixels(means2d, conics, features, opacities[None], W, H, TILE,
                                                 offsets, flatten_ids, backgrounds=bg, batch_per_iter=batches)
    return render[0], alphas[0, ..., 0]


def _render_cuda(means, scales, quats, opacities, sh, camera, degree, background):
    import torch
    from gsplat import rasterization

    dev = torch.device("cuda")
    args = [x.to(dev) for x in (means, quats, scales, opacities, sh)]
    viewmats = torch.tensor(camera.world_to_camera, dtype=torch.float32, device=dev)[None]
    Ks = torch.tensor(camera.K, dtype=torch.float32, device=dev)[None]
    bg = torch.tensor(background, dtype=torch.float32, device=dev)[None]
    render, alphas, _ = rasterization(*args, viewmats, Ks, camera.width, camera.height, near_plane=camera.near,
                                      far_plane=camera.far, eps2d=EPS2D, sh_degree=degree, tile_size=TILE,
                                      backgrounds=bg, render_mode="RGB+ED",
                                      # packed=False: gsplat 1.5.3 asserts on backgrounds when packed
                                      # (nerfstudio-project/gsplat#764; hit on the H100, reports/cuda)
                                      packed=False)
    render, alpha = render[0].to(means.device), alphas[0, ..., 0].to(means.device)
    # gsplat returns depth = D / max(alpha, 1e-10); turn it back into D for one code path below.
    return torch.cat([render[..., :3], render[..., 3:] * alpha.clamp(min=1e-10)[..., None]], -1), alpha


def make_gsplat_backend(device: str = "auto") -> Backend:
    """``gsplat``: gsplat 1.5.3 on ``device`` ("cpu": its PyTorch implementation, "cuda": its fused
    kernels, "auto": CUDA when torch sees a GPU). Raises a one-line `InputError` when gsplat
    is not installed."""
    import torch

    gsplat = _import_gsplat()
    from splatbench.backends.builtins.inputs import check_inputs

    use_cuda = torch_device(device) == "cuda"
    has_cuda = torch.cuda.is_available()
    render = _render_cuda if use_cuda else _render_cpu

    def fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        checked = check_inputs(means, log_scales, quats, opacity_logits, sh, camera, sh_degree=sh_degree,
                               background=background)
        f32 = [x.to(torch.float32) for x in (means, log_scales, quats, opacity_logits, sh)]
        means, log_scales, quats, logits, sh = f32
        # gsplat culls depth <= near itself; dropping those Gaussians first keeps its
        # projection from dividing by z ~ 0, whose 0·inf would put NaN in their (zero) gradients.
        with torch.no_grad():
            Wc = torch.tensor(camera.world_to_camera, dtype=torch.float32, device=means.device)
            z = means @ Wc[2, :3] + Wc[2, 3]
            keep = torch.nonzero((z > camera.near) & (z < camera.far)).squeeze(1)
        rgbd, alpha = render(means[keep], log_scales[keep].exp(), quats[keep], torch.sigmoid(logits[keep]),
                             sh[keep], camera, checked.sh_degree, checked.background)
        rgb, D = rgbd[..., :3], rgbd[..., 3]
        depth = torch.where(alpha > 0, D / torch.where(alpha > 0, alpha, torch.ones_like(alpha)),
                            torch.zeros_like(D))
        return rgb, alpha, depth

    info = BackendInfo(
        name="gsplat", version=getattr(gsplat, "__version__", VERSION),
        devices=("cpu", "cuda") if has_cuda else ("cpu",),
        alpha_min=ALPHA_MIN, alpha_max=ALPHA_MAX, transmittance_min=T_STOP, eps2d=EPS2D, radius="opacity",
        tile_size=TILE, antialiased=False,
        description=("gsplat 1.5.3 " + ("fused CUDA rasterization" if use_cuda else
                     "PyTorch implementation (gsplat.cuda._torch_impl) on the CPU, autograd backward")
                     + "; alpha clamp 0.999, stop at T <= 1e-4, tile box 3.33 sigma (the alpha_min rule decides),"
                     " no log-scale clip, no 'too large' cull"))
    return Backend(fn, info)
