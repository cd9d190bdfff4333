"""A small dense PyTorch 3DGS rasterizer written from docs/conventions.md, as a new user would write one,
with a switch for exactly one classic convention bug.

Dense: every Gaussian is evaluated at every pixel (no tiles, no radius cutoff, no early
termination; declared in its `BackendInfo`), otherwise graphdeco's conventions: exp / sigmoid /
normalised (w, x, y, z) quaternions, the EWA Jacobian clamped at 1.3 x the half field of view,
eps2d = 0.3, alpha = min(0.99, o exp(-sigma)) skipped below 1/255, SH colour max(SH + 0.5, 0)
seen along normalize(mean - camera centre), background weighted by the final transmittance,
depth = expected camera z / alpha. Autograd does the backward.

    make(bug)          a `Backend`; bug None (correct) or one of BUGS
    correct, half_pixel, sh_origin, background_added, raw_opacity
                       the same as module attributes, for `splatbench conform tests.dense_backends:sh_origin`

tests/broken_backends.py holds the larger set of deliberately broken renderers (one per probe);
this one is separate on purpose: it was not written against the probes.
"""

from __future__ import annotations

import torch

from splatbench.backends import Backend, BackendInfo

# bug -> (the convention axis it changes, what the bug does)
BUGS: dict[str, tuple[str, str]] = {
    "half_pixel": ("pixel_centre", "samples pixel (i, j) at (j, i): the half-pixel offset is missing"),
    "sh_origin": ("sh_view_direction", "evaluates the SH along normalize(mean), from the world origin"),
    "background_added": ("background", "adds the background unweighted, not times the final transmittance"),
    "raw_opacity": ("opacity_activation", "uses opacity_logits clamped to [0, 1] as opacities (no sigmoid)"),
}

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
         1.445305721320277, -0.5900435899266435)


def _sh_rgb(sh, d, degree):
    """max(sum_k sh_k basis_k(d) + 0.5, 0): sh [M, K, 3], d [M, 3] unit -> [M, 3]."""
    x, y, z = d.unbind(1)
    b = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        b += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        b += [SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2 * z * z - x * x - y * y), SH_C2[3] * x * z,
              SH_C2[4] * (x * x - y * y)]
    if degree >= 3:
        b += [SH_C3[0] * y * (3 * x * x - y * y), SH_C3[1] * x * y * z, SH_C3[2] * y * (4 * z * z - x * x - y * y),
              SH_C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y), SH_C3[4] * x * (4 * z * z - x * x - y * y),
              SH_C3[5] * z * (x * x - y * y), SH_C3[6] * x * (x * x - 3 * y * y)]
    basis = torch.stack(b, 1)  # [M, k]
    return ((basis[:, :, None] * sh[:, :basis.shape[1], :]).sum(1) + 0.5).clamp_min(0.0)


def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None, bug=None):
    """rgb [H, W, 3], alpha [H, W], depth [H, W]; inputs as in splatbench/backends/base.py."""
    dt = means.dtype
    view = torch.tensor(camera.world_to_camera, dtype=dt)  # a copy: Camera arrays are read-only
    R, tr = view[:3, :3], view[:3, 3]
    t = means @ R.T + tr
    keep = (t[:, 2] >= camera.near) & (t[:, 2] <= camera.far)
    t, z = t[keep], t[keep, 2]
    fx, fy, cx, cy, W, H = camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height

    # EWA Jacobian at the point clamped to 1.3 x the half field of view; the 2D mean is unclamped.
    lim_x = (-(cx + 0.3 * W / 2) / fx, (W - cx + 0.3 * W / 2) / fx)
    lim_y = (-(cy + 0.3 * H / 2) / fy, (H - cy + 0.3 * H / 2) / fy)
    tx, ty = z * (t[:, 0] / z).clamp(*lim_x), z * (t[:, 1] / z).clamp(*lim_y)
    o = torch.zeros_like(z)
    J = torch.stack([fx / z, o, -fx * tx / z ** 2, o, fy / z, -fy * ty / z ** 2], 1).reshape(-1, 2, 3)
    uv = torch.stack([fx * t[:, 0] / z + cx, fy * t[:, 1] / z + cy], 1)

    q = quats[keep] / quats[keep].norm(dim=1, keepdim=True)
    w, x, y, qz = q.unbind(1)
    rot = torch.stack([1 - 2 * (y * y + qz * qz), 2 * (x * y - w * qz), 2 * (x * qz + w * y),
                       2 * (x * y + w * qz), 1 - 2 * (x * x + qz * qz), 2 * (y * qz - w * x),
                       2 * (x * qz - w * y), 2 * (y * qz + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)
    RS = rot * log_scales[keep].clamp(-20, 20).exp()[:, None, :]
    JW = J @ R
    cov2d = JW @ RS @ RS.transpose(1, 2) @ JW.transpose(1, 2)
    a, b, c = cov2d[:, 0, 0] + 0.3, cov2d[:, 0, 1], cov2d[:, 1, 1] + 0.3
    det = a * c - b * b
    A, B, C = c / det, -b / det, a / det

    logits = opacity_logits[keep]
    opacity = logits.clamp(0.0, 1.0) if bug == "raw_opacity" else torch.sigmoid(logits)

    eye = -R.T @ tr
    d = means[keep] if bug == "sh_origin" else means[keep] - eye
    d = d / d.norm(dim=1, keepdim=True)
    degree = {1: 0, 4: 1, 9: 2, 16: 3}[sh.shape[1]] if sh_degree is None else sh_degree
    colour = _sh_rgb(sh[keep], d, degree)

    offset = 0.0 if bug == "half_pixel" else 0.5
    py, px = torch.meshgrid(torch.arange(H, dtype=dt) + offset, torch.arange(W, dtype=dt) + offset, indexing="ij")
    dx, dy = px.reshape(-1, 1) - uv[:, 0], py.reshape(-1, 1) - uv[:, 1]  # [P, M]
    power = 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy
    alpha = (opacity * torch.exp(-power)).clamp(max=0.99)
    alpha = alpha * (alpha.detach() >= 1.0 / 255.0)

    order = torch.argsort(z.detach(), stable=True)
    alpha, colour, zs = alpha[:, order], colour[order], z[order]
    T = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1.0 - alpha], 1), 1)
    weight = T[:, :-1] * alpha
    bg = torch.zeros(3, dtype=dt) if background is None else torch.as_tensor(background, dtype=dt)
    rgb = weight @ colour + (1.0 if bug == "background_added" else T[:, -1:]) * bg
    acc = 1.0 - T[:, -1]
    D = weight @ zs
    depth = torch.where(acc > 0, D / torch.where(acc > 0, acc, torch.ones_like(acc)), torch.zeros_like(acc))
    return rgb.reshape(H, W, 3), acc.reshape(H, W), depth.reshape(H, W)


def make(bug: str | None = None) -> Backend:
    """The dense renderer as a `Backend`, with ``bug`` (a key of BUGS) switched on, or none.

    It declares what it does on purpose (no cutoff, no early stop, no tiles) and nothing else."""
    if bug is not None and bug not in BUGS:
        raise KeyError(f"unknown bug {bug!r} (known: {', '.join(BUGS)})")

    def fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        return render(means, log_scales, quats, opacity_logits, sh, camera, sh_degree=sh_degree,
                      background=background, bug=bug)

    what = BUGS[bug][1] if bug else "dense, graphdeco's conventions, no approximation"
    return Backend(fn, BackendInfo(name=f"dense-{bug or 'correct'}", radius="none", transmittance_min=0.0,
                                   tile_size=0, description=what))


correct = make()
half_pixel = make("half_pixel")
sh_origin = make("sh_origin")
background_added = make("background_added")
raw_opacity = make("raw_opacity")
