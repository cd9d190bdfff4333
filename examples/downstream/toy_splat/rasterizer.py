"""A dense 3DGS rasterizer in PyTorch: graphdeco's conventions, no tiles, no radius cutoff, no early
stop (declared below, so splatbench judges it against what it does on purpose). Autograd does the
backward. Small scenes only: it evaluates every Gaussian at every pixel."""

from __future__ import annotations

import torch

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
      1.445305721320277, -0.5900435899266435)


def _colour(sh, d, degree):
    x, y, z = d.unbind(1)
    b = [torch.full_like(x, C0)]
    if degree >= 1:
        b += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        b += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * z * z - x * x - y * y), C2[3] * x * z, C2[4] * (x * x - y * y)]
    if degree >= 3:
        b += [C3[0] * y * (3 * x * x - y * y), C3[1] * x * y * z, C3[2] * y * (4 * z * z - x * x - y * y),
              C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y), C3[4] * x * (4 * z * z - x * x - y * y),
              C3[5] * z * (x * x - y * y), C3[6] * x * (x * x - 3 * y * y)]
    basis = torch.stack(b, 1)
    return ((basis[:, :, None] * sh[:, :basis.shape[1], :]).sum(1) + 0.5).clamp_min(0.0)


def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
    """rgb [H, W, 3], alpha [H, W], depth [H, W] (splatbench's backend signature)."""
    dt = means.dtype
    view = torch.tensor(camera.world_to_camera, dtype=dt)
    R, tr = view[:3, :3], view[:3, 3]
    t = means @ R.T + tr
    keep = (t[:, 2] >= camera.near) & (t[:, 2] <= camera.far)
    t, z = t[keep], t[keep, 2]
    fx, fy, cx, cy, W, H = camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height
    lim_x = (-(cx + 0.3 * W / 2) / fx, (W - cx + 0.3 * W / 2) / fx)  # EWA Jacobian clamp: 1.3 x half FoV
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
    cov = JW @ RS @ RS.transpose(1, 2) @ JW.transpose(1, 2)
    a, b, c = cov[:, 0, 0] + 0.3, cov[:, 0, 1], cov[:, 1, 1] + 0.3
    det = a * c - b * b
    A = c / det
    B = -b / det  # the conic's off-diagonal term
    C = a / det
    opacity = torch.sigmoid(opacity_logits[keep])

    eye = -R.T @ tr
    d = means[keep] - eye
    degree = {1: 0, 4: 1, 9: 2, 16: 3}[sh.shape[1]] if sh_degree is None else sh_degree
    colour = _colour(sh[keep], d / d.norm(dim=1, keepdim=True), degree)

    py, px = torch.meshgrid(torch.arange(H, dtype=dt) + 0.5, torch.arange(W, dtype=dt) + 0.5, indexing="ij")
    dx, dy = px.reshape(-1, 1) - uv[:, 0], py.reshape(-1, 1) - uv[:, 1]
    power = 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy
    alpha = (opacity * torch.exp(-power)).clamp(max=0.99)
    alpha = alpha * (alpha.detach() >= 1.0 / 255.0)
    order = torch.argsort(z.detach(), stable=True)
    alpha, colour, zs = alpha[:, order], colour[order], z[order]
    T = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1.0 - alpha], 1), 1)
    weight = T[:, :-1] * alpha
    bg = torch.zeros(3, dtype=dt) if background is None else torch.as_tensor(background, dtype=dt)
    rgb = weight @ colour + T[:, -1:] * bg
    acc = 1.0 - T[:, -1]
    D = weight @ zs
    depth = torch.where(acc > 0, D / torch.where(acc > 0, acc, torch.ones_like(acc)), torch.zeros_like(acc))
    return rgb.reshape(H, W, 3), acc.reshape(H, W), depth.reshape(H, W)


try:  # what it departs from on purpose, declared for splatbench (optional: toy_splat runs without it)
    from splatbench.backends import BackendInfo

    render.backend_info = BackendInfo(name="toy-splat", version="0.1.0", radius="none", transmittance_min=0.0,
                                      tile_size=0, description="dense toy rasterizer (examples/downstream)")
except ImportError:
    pass
