"""Deliberately broken rasterizers for `splatbench conform`'s tests.

`dense(bug)` is a small dense PyTorch 3DGS renderer written from docs/conventions.md: every
Gaussian is tested at every pixel, with no radius cutoff, no tiles and no early termination
(the approximations conform reports as warnings), and otherwise graphdeco's conventions.
``bug=None`` is the correct renderer; each key of `BUGS` switches on one classic bug (several
of them found in a widely used CPU port of 3DGS), and names the probe that must catch it.
"""

from __future__ import annotations

import torch

from splatbench.backends import Backend, BackendInfo
from splatbench.backends.builtins.torch_backend import C0, C1, C2, C3

# bug -> (the probe that must fail, what the bug is)
BUGS: dict[str, tuple[str, str]] = {
    "sort_strided": ("depth_order", "sorts on a strided view of the camera points read as contiguous"),
    "sort_world_z": ("depth_order", "sorts on world z instead of camera z"),
    "sort_index": ("depth_order", "composites in input order"),
    "sort_camera_x": ("depth_order", "sorts on camera-space x instead of camera z (depth)"),
    "alpha_clamp_0999_fwd": ("alpha_max", "clamps alpha at 0.999 in the forward, 0.99 in the backward"),
    "alpha_clamp_0999_bwd": ("alpha_max_grad", "clamps alpha at 0.99 in the forward, 0.999 in the backward"),
    "conic_b_grad_half": ("conic_B", "halves the gradient of the off-diagonal conic term"),
    "sh_dir_detached": ("sh_viewdir_grad", "detaches the SH view direction from the means"),
    "sh_dir_origin": ("sh_viewdir", "takes the SH view direction from the world origin"),
    "quat_xyzw": ("quat_order", "reads quaternions as (x, y, z, w)"),
    "quat_transposed": ("quat_order", "builds R transposed from the quaternion"),
    "quat_unnormalised": ("quat_norm", "does not normalise quaternions"),
    "pixel_integer": ("pixel_centre", "samples pixels at integer coordinates"),
    "no_eps2d": ("eps2d", "adds no eps2d low-pass"),
    "scales_raw": ("scale_activation", "uses log_scales as scales"),
    "opacity_raw": ("opacity_activation", "uses opacity_logits (clamped to [0, 1]) as opacities"),
    "opacity_grad_at_zero": ("grad_opacity_logits", "sigmoid through exp(-|x|): no derivative at logit 0"),
    "sh1_sign": ("sh_degree1", "flips the sign of the first degree-1 basis"),
    "sh2_order": ("sh_degree2", "swaps two degree-2 bases"),
    "sh3_sign": ("sh_degree3", "flips the sign of one degree-3 basis"),
    "sh_degree_ignored": ("sh_degree_arg", "evaluates every SH band, ignoring sh_degree"),
    "no_colour_clamp": ("colour_clamp", "does not clamp SH colours at 0"),
    "colour_clamp_1": ("colour_clamp", "clamps SH colours to [0, 1]"),
    "background_unblended": ("background", "adds the background without the final transmittance"),
    "depth_unnormalised": ("expected_depth", "returns sum T a z, not normalised by alpha"),
    "depth_distance": ("expected_depth", "uses the distance to the camera as depth"),
    "no_near_cull": ("near_plane", "culls only Gaussians at z <= 0, not those before camera.near"),
    "no_jacobian_clamp": ("jacobian_clamp", "evaluates the EWA Jacobian at the unclamped point"),
    "no_alpha_min": ("alpha_min", "composites alpha < 1/255"),
    "fy_is_fx": ("intrinsics", "uses fx for both axes"),
    "tile_centre_only": ("tiles", "draws each Gaussian only in the 16x16 tile holding its centre"),
    "cutoff_2sigma": ("radius", "cuts footprints at 2 sigma"),
}

GUARD = 0.3  # graphdeco's Jacobian clamp: 1.3 x the half field of view


def _sh_colour(sh, dirs, degree: int, bug: str | None):
    x, y, z = dirs.unbind(1)
    basis = [torch.full_like(x, C0)]
    if degree >= 1:
        basis += [(C1 if bug == "sh1_sign" else -C1) * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        b2 = [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy)]
        if bug == "sh2_order":
            b2[1], b2[3] = b2[3], b2[1]
        basis += b2
    if degree >= 3:
        b3 = [C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
              C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy), C3[5] * z * (xx - yy),
              C3[6] * x * (xx - 3 * yy)]
        if bug == "sh3_sign":
            b3[4] = -b3[4]
        basis += b3
    k = len(basis)
    colour = (torch.stack(basis, 1)[:, :, None] * sh[:, :k, :]).sum(1) + 0.5
    return colour if bug == "no_colour_clamp" else colour.clamp(0.0, 1.0 if bug == "colour_clamp_1" else None)


def _rotation(q, bug):
    if bug == "quat_xyzw":
        q = q[:, [3, 0, 1, 2]]
    if bug != "quat_unnormalised":
        q = q / q.norm(dim=1, keepdim=True)
    w, x, y, z = q.unbind(1)
    R = torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                     2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                     2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)
    return R.transpose(1, 2) if bug == "quat_transposed" else R


def _sigmoid(x, bug):
    if bug == "opacity_raw":
        return x.clamp(0.0, 1.0)
    if bug == "opacity_grad_at_zero":
        e = torch.exp(-x.abs())
        e = e.detach() + (e - e.detach()) * (x != 0)  # d|x|/dx = sign(x) = 0 at 0, as in Dr.Jit
        return torch.where(x >= 0, 1 / (1 + e), e / (1 + e))
    return torch.sigmoid(x)


def _clamp_alpha(raw, bug):
    """min(alpha_max, raw) in the forward; the backward lets gradients through where raw <= its own clamp."""
    fwd, bwd = {"alpha_clamp_0999_fwd": (0.999, 0.99), "alpha_clamp_0999_bwd": (0.99, 0.999)}.get(bug, (0.99, 0.99))
    value = raw.clamp(max=fwd).detach()
    return value + (raw - raw.detach()) * (raw.detach() <= bwd)


def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None, bug=None,
           tile_box=False):
    """rgb [H, W, 3], alpha [H, W], depth [H, W] of the dense renderer with ``bug`` switched on.

    ``tile_box``: graphdeco's own footprint rule instead of none: a Gaussian reaches the 16x16
    tiles its box of half side ceil(3 sqrt(largest eigenvalue of Σ2D)) touches, with no per-pixel
    cutoff (a declared approximation, not a bug)."""
    dt = means.dtype
    Wm = torch.tensor(camera.world_to_camera, dtype=dt)  # a copy: Camera arrays are read-only
    Wr, Wt = Wm[:3, :3], Wm[:3, 3]
    t = means @ Wr.T + Wt
    z = t[:, 2]
    keep = (z.abs() > 1e-6) if bug == "no_near_cull" else (z >= camera.near) & (z <= camera.far)
    idx = torch.nonzero(keep).squeeze(1)
    t, z = t[idx], z[idx]
    fx, cx, cy = camera.fx, camera.cx, camera.cy
    fy = fx if bug == "fy_is_fx" else camera.fy
    W, H = camera.width, camera.height
    if bug == "no_jacobian_clamp":
        tx, ty = t[:, 0], t[:, 1]
    else:
        tx = z * (t[:, 0] / z).clamp(-(cx / fx + GUARD * W / 2 / fx), (W - cx) / fx + GUARD * W / 2 / fx)
        ty = z * (t[:, 1] / z).clamp(-(cy / fy + GUARD * H / 2 / fy), (H - cy) / fy + GUARD * H / 2 / fy)
    zero = torch.zeros_like(z)
    J = torch.stack([fx / z, zero, -fx * tx / z**2, zero, fy / z, -fy * ty / z**2], 1).reshape(-1, 2, 3)
    mean2d = torch.stack([fx * t[:, 0] / z + cx, fy * t[:, 1] / z + cy], 1)
    scales = log_scales[idx] if bug == "scales_raw" else log_scales[idx].clamp(-20, 20).exp()
    M = _rotation(quats[idx], bug) * scales[:, None, :]
    T = J @ Wr
    cov = T @ (M @ M.transpose(1, 2)) @ T.transpose(1, 2)
    eps = 0.0 if bug == "no_eps2d" else 0.3
    xx, xy, yy = cov[:, 0, 0] + eps, cov[:, 0, 1], cov[:, 1, 1] + eps
    det = xx * yy - xy * xy
    A, B, C = yy / det, -xy / det, xx / det
    if bug == "conic_b_grad_half":
        B = B.detach() + 0.5 * (B - B.detach())
    opacity = _sigmoid(opacity_logits[idx], bug)

    centre = -Wr.T @ Wt
    m = means[idx].detach() if bug == "sh_dir_detached" else means[idx]
    dirs = m if bug == "sh_dir_origin" else m - centre
    dirs = dirs / dirs.norm(dim=1, keepdim=True)
    k = sh.shape[1]
    degree = {1: 0, 4: 1, 9: 2, 16: 3}[k] if sh_degree is None or bug == "sh_degree_ignored" else sh_degree
    colour = _sh_colour(sh[idx], dirs, degree, bug)

    shift = 0.0 if bug == "pixel_integer" else 0.5
    ys, xs = torch.meshgrid(torch.arange(H, dtype=dt) + shift, torch.arange(W, dtype=dt) + shift, indexing="ij")
    dx = xs.reshape(-1, 1) - mean2d[None, :, 0]
    dy = ys.reshape(-1, 1) - mean2d[None, :, 1]
    sigma = 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy  # [P, M]
    alpha = _clamp_alpha(opacity * torch.exp(-sigma), bug)
    alpha = alpha * (alpha.detach() >= (0.0 if bug == "no_alpha_min" else 1 / 255))
    if bug == "cutoff_2sigma":
        alpha = alpha * (sigma.detach() <= 2.0)
    if tile_box:
        with torch.no_grad():
            half_tr, det_ = (xx + yy) / 2, xx * yy - xy * xy
            r = torch.ceil(3 * torch.sqrt(half_tr + torch.sqrt((half_tr * half_tr - det_).clamp_min(0.1))))
            lo = ((mean2d - r[:, None]) / 16).floor().clamp_min(0)
            hi = ((mean2d + r[:, None] + 15) / 16).floor()
            tx_, ty_ = (xs.reshape(-1, 1) / 16).floor(), (ys.reshape(-1, 1) / 16).floor()
            inside = (tx_ >= lo[:, 0]) & (tx_ < hi[:, 0]) & (ty_ >= lo[:, 1]) & (ty_ < hi[:, 1])
        alpha = alpha * inside
    if bug == "tile_centre_only":
        tile = lambda u, v: (u // 16) * 1000 + v // 16  # noqa: E731
        alpha = alpha * (tile(xs.reshape(-1, 1).floor(), ys.reshape(-1, 1).floor())
                         == tile(mean2d[None, :, 0].detach().floor(), mean2d[None, :, 1].detach().floor()))

    if bug == "sort_strided":   # camera points [x0 y0 z0 x1 ...]: "z" read contiguously from z0's address
        key = t.detach().reshape(-1)[2:2 + len(idx)]
    elif bug == "sort_world_z":
        key = means[idx, 2].detach()
    elif bug == "sort_index":
        key = torch.arange(len(idx), dtype=dt)
    elif bug == "sort_camera_x":
        key = t[:, 0].detach()
    else:
        key = z.detach()
    order = torch.sort(key, stable=True).indices
    alpha, colour = alpha[:, order], colour[order]
    depth_of = t.norm(dim=1) if bug == "depth_distance" else z
    depth_of = depth_of[order]
    ones = torch.ones(alpha.shape[0], 1, dtype=dt)
    trans = torch.cumprod(torch.cat([ones, 1 - alpha], 1), 1)
    weights = trans[:, :-1] * alpha
    bg = torch.zeros(3, dtype=dt) if background is None else torch.as_tensor(background, dtype=dt)
    final = 1.0 if bug == "background_unblended" else trans[:, -1:]
    rgb = weights @ colour + final * bg
    a = 1 - trans[:, -1]
    D = weights @ depth_of
    depth = D if bug == "depth_unnormalised" else torch.where(a > 0, D / torch.where(a > 0, a, 1.0), 0.0)
    return rgb.reshape(H, W, 3), a.reshape(H, W), depth.reshape(H, W)


def dense(bug: str | None = None, *, tile_box: bool = False) -> Backend:
    """The dense renderer as a `Backend` (declares nothing: graphdeco's conventions are assumed)."""
    if bug is not None and bug not in BUGS:
        raise KeyError(f"unknown bug {bug!r}")

    def fn(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
        return render(means, log_scales, quats, opacity_logits, sh, camera, sh_degree=sh_degree,
                      background=background, bug=bug, tile_box=tile_box)

    label = bug or ("tile_box" if tile_box else "correct")
    return Backend(fn, BackendInfo(name=f"dense[{label}]",
                                   description=BUGS[bug][1] if bug else "dense, every convention, no approximation"))


# One broken backend as a module attribute, for `splatbench conform tests.broken_backends:dense_sort_strided`.
dense_sort_strided = dense("sort_strided")
dense_conic_b_grad_half = dense("conic_b_grad_half")  # the pytest plugin's one-bug backend (tests/test_pytest_plugin.py)
