"""The ``torch`` and ``torch64`` backends: 3DGS written again, readably, in pure PyTorch.

Written from docs/conventions.md (like `reference/`), sharing no code with the Dr.Jit
rasterizer, and differentiated by torch autograd. ``torch`` computes in float32,
``torch64`` in float64: the gradient oracle for scenes too large for finite differences.

Compositing is dense per block of BLOCK x BLOCK pixels: every visible Gaussian whose
screen box touches the block is tested at every pixel of it, in depth order, with the
per-pixel rules of conventions.md (3-sigma cutoff, alpha_min skip, alpha_max clamp,
early stop; radius "opacity" on request). The blocks only bound memory (pixels x
candidates); the per-pixel test decides, so the declared conventions are graphdeco's.
Under autograd each block is checkpointed (recomputed in the backward pass), so memory
stays one block's worth.
"""

from __future__ import annotations

from typing import NamedTuple

from splatbench.backends.base import AXES, GRAPHDECO, Backend, BackendInfo
from splatbench.errors import InputError

BLOCK = 16  # pixels per block side (memory bound: BLOCK^2 x candidates per block)
LOG_SCALE_CLIP = 20.0
QUAT_MIN = 1e-20
JACOBIAN_GUARD = 0.3
BIG_FACTOR = 1e4
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
      1.445305721320277, -0.5900435899266435)
DTYPES = {"float32": "torch", "float64": "torch64"}


class Settings(NamedTuple):
    alpha_min: float = 1.0 / 255.0
    alpha_max: float = 0.99
    transmittance_min: float = 1e-4
    eps2d: float = 0.3
    radius: str = "3sigma"  # or "opacity": R² = 2 ln(o / alpha_min), culling o <= alpha_min


class Projected(NamedTuple):
    """Per-Gaussian screen quantities of the visible Gaussians only (M of them), depth-sorted."""

    index: object    # [M] int64 into the N inputs
    means2d: object  # [M, 2]
    conics: object   # [M, 3] (A, B, C) of inverse(Σ2D)
    opacity: object  # [M]
    depth: object    # [M] camera z
    extent: object   # [M, 2] (rx, ry) half sizes of the box of the ellipse d² <= R²
    cutoff_sq: object  # [M] R², the Mahalanobis cutoff


def _unit_rows(v, smallest: float):
    """Rows of v scaled to unit length overflow-safely (v / max|v_i|, then / length); rows whose
    largest entry is below ``smallest`` become zero."""
    import torch

    big = v.abs().amax(dim=1, keepdim=True)
    ok = big >= smallest if smallest > 0 else big > 0
    v = torch.where(ok, v / torch.where(ok, big, torch.ones_like(big)), torch.zeros_like(v))
    square = v.square().sum(dim=1, keepdim=True)
    ok = square > 0  # sqrt only of positive values: its derivative at 0 is infinite
    length = torch.where(ok, square, torch.ones_like(square)).sqrt()
    return torch.where(ok, v / length, torch.zeros_like(v))


def covariance(log_scales, quats):
    """Σ = R S Sᵀ Rᵀ: [N, 3] log scales (clipped to ±20), [N, 4] wxyz quats -> [N, 3, 3]."""
    import torch

    w, x, y, z = _unit_rows(quats, QUAT_MIN).unbind(1)
    R = torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                     2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                     2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], dim=1).reshape(-1, 3, 3)
    M = R * log_scales.clamp(-LOG_SCALE_CLIP, LOG_SCALE_CLIP).exp()[:, None, :]
    return M @ M.transpose(1, 2)


class Screen(NamedTuple):
    """Per-Gaussian screen quantities (conventions.md "project"), for all N given."""

    keep: object     # [N] bool: not culled
    means2d: object  # [N, 2]
    conics: object   # [N, 3] (A, B, C) of inverse(Σ2D)
    opacity: object  # [N]
    depth: object    # [N] camera z
    extent: object   # [N, 2] (rx, ry) half sizes of the box of the ellipse d² <= R²
    cutoff_sq: object  # [N] R²


def screen(means, log_scales, quats, opacity_logits, camera, s: Settings) -> Screen:
    """conventions.md "project", steps 1-10 (culled entries may hold garbage)."""
    import torch

    dt = means.dtype
    W = torch.tensor(camera.world_to_camera, dtype=dt)  # a copy: a Camera's arrays are read-only
    Wr, Wt = W[:3, :3], W[:3, 3]
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    w_img, h_img = camera.width, camera.height
    t = means @ Wr.T + Wt                                                    # 1. camera space
    z = t[:, 2]
    keep = (z >= camera.near) & (z <= camera.far)                            # 2. depth cull
    zs = torch.where(keep, z, torch.ones_like(z))                            # safe divisor for culled ones
    lim_x = ((w_img - cx) / fx + JACOBIAN_GUARD * w_img / 2 / fx, cx / fx + JACOBIAN_GUARD * w_img / 2 / fx)
    lim_y = ((h_img - cy) / fy + JACOBIAN_GUARD * h_img / 2 / fy, cy / fy + JACOBIAN_GUARD * h_img / 2 / fy)
    tx = zs * (t[:, 0] / zs).clamp(-lim_x[1], lim_x[0])                      # 3. clamped Jacobian
    ty = zs * (t[:, 1] / zs).clamp(-lim_y[1], lim_y[0])
    zero = torch.zeros_like(zs)
    J = torch.stack([fx / zs, zero, -fx * tx / zs**2, zero, fy / zs, -fy * ty / zs**2], 1).reshape(-1, 2, 3)
    means2d = torch.stack([fx * t[:, 0] / zs + cx, fy * t[:, 1] / zs + cy], 1)  # unclamped
    T = J @ Wr
    cov2d = T @ covariance(log_scales, quats) @ T.transpose(1, 2)            # 4. Σ2D
    xx, xy, yy = cov2d[:, 0, 0] + s.eps2d, cov2d[:, 0, 1], cov2d[:, 1, 1] + s.eps2d
    det = xx * yy - xy * xy
    finite = torch.isfinite(means2d).all(1) & torch.isfinite(xx) & torch.isfinite(yy) & torch.isfinite(xy)
    keep = keep & finite & torch.isfinite(det) & (det > 0)                   # 5. degenerate, huge
    keep = keep & (torch.maximum(xx, yy) <= (BIG_FACTOR * max(w_img, h_img)) ** 2)
    conics = torch.stack([yy / det, -xy / det, xx / det], 1)                 # 6. conic
    opacity = torch.sigmoid(opacity_logits)                                  # 7. opacity
    if s.radius == "3sigma":                                                 # 8. cutoff R²
        cutoff_sq = torch.full_like(opacity, 9.0)
    else:
        keep = keep & (opacity > s.alpha_min)
        cutoff_sq = 2.0 * torch.log(opacity / s.alpha_min)
    R = cutoff_sq.clamp_min(0).sqrt()
    rx, ry = R * xx.abs().sqrt(), R * yy.abs().sqrt()                        # 9. screen box
    u, v = means2d[:, 0], means2d[:, 1]
    keep = keep & (u + rx >= 0) & (u - rx <= w_img) & (v + ry >= 0) & (v - ry <= h_img)
    keep = keep & torch.isfinite(conics).all(1)
    return Screen(keep, means2d, conics, opacity, z, torch.stack([rx, ry], 1), cutoff_sq)


def project(means, log_scales, quats, opacity_logits, camera, s: Settings) -> Projected:
    """The visible Gaussians, depth-sorted (ties by index). Culling is decided without autograd;
    only the visible ones are then differentiated, so a culled degenerate Gaussian (overflow,
    zero quaternion) can never put NaN into a gradient."""
    import torch

    with torch.no_grad():
        keep = screen(means, log_scales, quats, opacity_logits, camera, s).keep
    index = torch.nonzero(keep).squeeze(1)
    q = screen(means[index], log_scales[index], quats[index], opacity_logits[index], camera, s)
    order = torch.sort(q.depth.detach(), stable=True).indices                # by depth, ties by index
    return Projected(index[order], q.means2d[order], q.conics[order], q.opacity[order], q.depth[order],
                     q.extent[order].detach(), q.cutoff_sq[order].detach())


def eval_sh(sh, means, camera, degree: int):
    """Colours [N, 3] = max(SH(dir) + 0.5, 0) with dir = normalize(mean - camera centre)."""
    import torch

    W = torch.tensor(camera.world_to_camera, dtype=means.dtype)
    centre = -W[:3, :3].T @ W[:3, 3]
    x, y, z = _unit_rows(means - centre, 0.0).unbind(1)
    basis = [torch.full_like(x, C0)]
    if degree >= 1:
        basis += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        basis += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy)]
    if degree >= 3:
        basis += [C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
                  C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy),
                  C3[5] * z * (xx - yy), C3[6] * x * (xx - 3 * yy)]
    k = len(basis)
    rgb = (torch.stack(basis, 1)[:, :, None] * sh[:, :k, :]).sum(1)
    return (rgb + 0.5).clamp_min(0.0)


def composite_block(pix, p: Projected, colors, s: Settings, background):
    """conventions.md "composite" at pixel centres ``pix`` [P, 2] over the candidates ``p`` (depth order).

    Returns rgb [P, 3], alpha [P], depth [P].
    """
    import torch

    d = pix[:, None, :] - p.means2d[None, :, :]                              # [P, M, 2]
    A, B, C = p.conics.unbind(1)
    sigma = 0.5 * (A * d[..., 0] ** 2 + C * d[..., 1] ** 2) + B * d[..., 0] * d[..., 1]
    alpha = (p.opacity * torch.exp(-sigma)).clamp(max=s.alpha_max)
    with torch.no_grad():  # the discrete decisions: cutoff, skip, then the early stop
        used = (sigma <= 0.5 * p.cutoff_sq) & (alpha >= s.alpha_min)
        T_next = torch.cumprod(1 - torch.where(used, alpha, torch.zeros_like(alpha)), dim=1)
        used &= T_next >= s.transmittance_min
    a = torch.where(used, alpha, torch.zeros_like(alpha))
    ones = torch.ones(a.shape[0], 1, dtype=a.dtype)
    T = torch.cumprod(torch.cat([ones, 1 - a], dim=1), dim=1)                # T before each, then T_final
    weights = T[:, :-1] * a                                                  # T·α
    T_final = T[:, -1]
    rgb = weights @ colors + T_final[:, None] * background
    alpha_out = 1 - T_final
    D = weights @ p.depth
    depth = torch.where(alpha_out > 0, D / torch.where(alpha_out > 0, alpha_out, torch.ones_like(alpha_out)),
                        torch.zeros_like(D))
    return rgb, alpha_out, depth


def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree: int, background, s: Settings):
    """Validated inputs (any float dtype; computes in that dtype) -> rgb [H, W, 3], alpha [H, W], depth [H, W]."""
    import torch
    from torch.utils.checkpoint import checkpoint

    dt = means.dtype
    H, W = camera.height, camera.width
    p = project(means, log_scales, quats, opacity_logits, camera, s)
    colors = eval_sh(sh[p.index], means[p.index], camera, sh_degree)
    bg = torch.tensor(background, dtype=dt)
    rows, alphas, depths = [], [], []
    for y0 in range(0, H, BLOCK):
        row_rgb, row_alpha, row_depth = [], [], []
        for x0 in range(0, W, BLOCK):
            ys = torch.arange(y0, min(y0 + BLOCK, H), dtype=dt) + 0.5
            xs = torch.arange(x0, min(x0 + BLOCK, W), dtype=dt) + 0.5
            # Candidates: boxes touching the block, padded by a pixel (an acceleration only).
            lo_x, hi_x, lo_y, hi_y = float(xs[0]) - 1, float(xs[-1]) + 1, float(ys[0]) - 1, float(ys[-1]) + 1
            m2 = p.means2d.detach()
            sel = ((m2[:, 0] + p.extent[:, 0] >= lo_x) & (m2[:, 0] - p.extent[:, 0] <= hi_x)
                   & (m2[:, 1] + p.extent[:, 1] >= lo_y) & (m2[:, 1] - p.extent[:, 1] <= hi_y))
            k = torch.nonzero(sel).squeeze(1)
            cand = Projected(*(f[k] for f in p))
            pix = torch.stack(torch.meshgrid(xs, ys, indexing="xy"), -1).reshape(-1, 2)
            if torch.is_grad_enabled():  # keep only the block's inputs; recompute it in backward
                rgb, alpha, depth = checkpoint(composite_block, pix, cand, colors[k], s, bg, use_reentrant=False)
            else:
                rgb, alpha, depth = composite_block(pix, cand, colors[k], s, bg)
            shape = (len(ys), len(xs))
            row_rgb.append(rgb.reshape(*shape, 3))
            row_alpha.append(alpha.reshape(shape))
            row_depth.append(depth.reshape(shape))
        rows.append(torch.cat(row_rgb, 1))
        alphas.append(torch.cat(row_alpha, 1))
        depths.append(torch.cat(row_depth, 1))
    return torch.cat(rows, 0), torch.cat(alphas, 0), torch.cat(depths, 0)


def make_torch_backend(dtype: str = "float32", **settings) -> Backend:
    """``torch`` (dtype "float32") or ``torch64`` ("float64"); ``settings``: alpha_min, alpha_max,
    transmittance_min, eps2d, radius (graphdeco's by default; other values reproduce another
    backend's conventions, e.g. gsplat's, for gradient comparisons). Outputs are in ``dtype``; gradients flow
    back to the inputs in their own dtype."""
    import torch

    from splatbench.backends.builtins.inputs import check_inputs

    if dtype not in DTYPES:
        raise InputError(f"dtype: expected one of {list(DTYPES)}, got {dtype!r}")
    unknown = sorted(set(settings) - set(Settings._fields))
    if unknown:
        raise InputError(f"{unknown[0]}: not a torch backend setting (known: {', '.join(Settings._fields)})")
    s = Settings(**settings)
    if s.radius not in ("3sigma", "opacity"):
        raise InputError(f"radius: expected '3sigma' or 'opacity', got {s.radius!r}")
    compute = getattr(torch, dtype)

    def fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        checked = check_inputs(means, log_scales, quats, opacity_logits, sh, camera, sh_degree=sh_degree,
                               background=background)
        cast = [x.to(compute) for x in (means, log_scales, quats, opacity_logits, sh)]
        return render(*cast, camera, sh_degree=checked.sh_degree, background=checked.background, s=s)

    info = BackendInfo(name=DTYPES[dtype], version=torch.__version__, dtype=dtype, tile_size=0,
                       alpha_min=s.alpha_min, alpha_max=s.alpha_max, transmittance_min=s.transmittance_min,
                       eps2d=s.eps2d, radius=s.radius, antialiased=False,
                       description=f"pure-PyTorch 3DGS in {dtype} (splatbench/backends/builtins/torch_backend.py), "
                                   f"written from docs/conventions.md; dense compositing per {BLOCK}x{BLOCK}-pixel "
                                   f"block with the per-pixel radius test; torch autograd backward")
    return Backend(fn, info)


def make_torch64_backend() -> Backend:
    """``torch64``: the float64 variant, the gradient oracle for scenes too large for finite differences."""
    return make_torch_backend("float64")


def make_torch_matching(info: BackendInfo, dtype: str = "float64") -> Backend:
    """A ``torch``/``torch64`` backend following another backend's declared conventions
    (alpha_min, alpha_max, transmittance_min, eps2d, radius): the gradient oracle for it."""
    if info.convention("antialiased"):
        raise InputError(f"backend: the torch backend has no antialiased mode to match {info.name!r}")
    other = [a.name for a in AXES if a.name not in GRAPHDECO and info.convention(a.name) != a.graphdeco]
    if other:
        raise InputError(f"backend: the torch backend follows graphdeco's {other[0]}, not {info.name!r}'s "
                         f"{info.convention(other[0])!r}")
    radius = info.convention("radius")
    if radius == "none":  # no cutoff renders as the opacity rule (as `BackendInfo.reference_options` says why)
        radius = "opacity"
    if radius not in ("3sigma", "opacity"):
        raise InputError(f"backend: the torch backend cannot match radius {radius!r} of {info.name!r}")
    return make_torch_backend(dtype, **{**{k: info.convention(k) for k in Settings._fields}, "radius": radius})
