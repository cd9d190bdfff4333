"""Per-pixel front-to-back alpha compositing (mirrors ``splatbench.raster.composite``).

Written from ``docs/conventions.md`` ("composite" and "exact mode"). One pixel at a
time in matched mode, one image row at a time in exact mode; float64 throughout.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from reference.band import pixel_bands, sigma_slack
from reference.project import MODES, _as_array, _as_choice, _as_scalar, _as_size

# The bounding-box prefilter is padded by this relative amount (plus as much in
# pixels) so rounding can never drop a pixel that the exact sigma test would keep.
BOX_PAD = 1e-9
BACKGROUND_MODES = ("weighted", "added", "ignored")


class Composite(NamedTuple):
    """Composited image."""

    rgb: np.ndarray  # [H, W, 3] Σ T·α·c + T_final·background
    alpha: np.ndarray  # [H, W] 1 - T_final
    depth: np.ndarray  # [H, W] expected camera z, D / alpha where alpha > 0, else 0
    band: np.ndarray | None = None  # [H, W] bool, the boundary band (reference.band); None unless asked
    tie_slack: np.ndarray | None = None  # [H, W] how far depth ties may move the pixel (reference.band)
    grad_band: np.ndarray | None = None  # [N] bool, the Gaussians in the gradient band (reference.band)
    grad_weight: np.ndarray | None = None  # [H, W] relative change of the other gradient terms (reference.band)


def _half_mahalanobis(A, B, C, dx, dy):
    """sigma = d²/2 = 0.5·(A·dx² + C·dy²) + B·dx·dy, as written in conventions.md."""
    return 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy


def _blend(alphas, colors, depths, background, background_mode="weighted", normalise_depth=True):
    """Front-to-back 'over' of the given contributions, all of which are kept.

    Args:
        alphas: [P, M] alpha of each of M Gaussians (in compositing order) at P pixels.
        colors: [M, 3]; depths: [M]; background: [3].

    Returns:
        rgb [P, 3], alpha [P], depth [P].
    """
    # T after each Gaussian. np.cumprod multiplies left to right, so this is the same
    # sequence of roundings as the loop `T = T * (1 - alpha)`.
    T_after = np.cumprod(1.0 - alphas, axis=1)
    T_before = np.concatenate([np.ones_like(alphas[:, :1]), T_after[:, :-1]], axis=1)
    T_final = T_after[:, -1] if alphas.shape[1] else np.ones(alphas.shape[0])
    weights = T_before * alphas  # [P, M]  T·α
    behind = {"weighted": T_final, "added": np.ones_like(T_final), "ignored": np.zeros_like(T_final)}
    rgb = weights @ colors + behind[background_mode][:, None] * background
    alpha = 1.0 - T_final
    D = weights @ depths
    depth = np.where(alpha > 0, D / np.where(alpha > 0, alpha, 1.0), 0.0) if normalise_depth else D
    return rgb, alpha, depth


def composite(means2d, conics, opacities, colors, depths, cutoff_sq, visible, width, height, *,
              mode="matched", background=(0.0, 0.0, 0.0), alpha_min=1 / 255, alpha_max=0.99,
              transmittance_min=1e-4, pixel_offset=0.5, sort_keys=None, background_mode="weighted",
              normalise_depth=True, errors=None) -> Composite:
    """Alpha-composite projected Gaussians (mirrors ``splatbench.raster.composite``).

    For every pixel centre p = (j + 0.5, i + 0.5), visible Gaussians in ascending depth
    (ties: ascending index) are blended front to back:

        sigma = 0.5·(A·dx² + C·dy²) + B·dx·dy      d = p - mean2d
        skip if sigma > 0.5·R²
        alpha = min(alpha_max, o·exp(-sigma));  skip if alpha < alpha_min
        T_next = T·(1 - alpha);  stop (without this Gaussian) if T_next < transmittance_min
        rgb += T·alpha·colour;  D += T·alpha·z;  T = T_next

    In exact mode every visible Gaussian contributes alpha = o·exp(-sigma) to every
    pixel: no cutoff, no alpha_min skip, no alpha_max clamp, no early stop.

    Args:
        means2d: [N, 2] pixel coordinates (origin top-left corner).
        conics: [N, 3] (A, B, C) of inverse(Σ2D).
        opacities: [N] in [0, 1].
        colors: [N, 3].
        depths: [N] camera z, the sort key.
        cutoff_sq: [N] R² (may be inf; ignored in exact mode).
        visible: [N] bool; only these are drawn.
        width, height: image size.
        mode: "matched" or "exact".
        background: [3] colour behind everything.
        alpha_min, alpha_max, transmittance_min: the matched-mode thresholds.
        Convention alternatives (graphdeco's by default): pixel_offset, where pixel (i, j) is
            sampled (0.5: its centre; 0: integer coordinates); sort_keys [N], the compositing
            order (default: depths); background_mode "weighted" (by T_final), "added" (as is)
            or "ignored"; normalise_depth False returns D itself, not D / alpha.
        errors: a `reference.band.ProjectionError` of the projection (matched mode only):
            also return the boundary band and the tie slack.

    Returns:
        `Composite` (rgb [H, W, 3], alpha [H, W], depth [H, W], band [H, W] bool and
        tie_slack [H, W], both None unless ``errors`` is given).
    """
    sizes = {}
    means2d = _as_array("means2d", means2d, ("N", 2), sizes)
    conics = _as_array("conics", conics, ("N", 3), sizes)
    opacities = _as_array("opacities", opacities, ("N",), sizes)
    colors = _as_array("colors", colors, ("N", 3), sizes)
    depths = _as_array("depths", depths, ("N",), sizes)
    cutoff_sq = _as_array("cutoff_sq", cutoff_sq, ("N",), sizes, allow_inf=True)
    visible = np.asarray(visible, dtype=bool)
    if visible.shape != (sizes["N"],):
        raise ValueError(f"visible: expected shape [{sizes['N']}], got {list(visible.shape)}")
    width, height = _as_size("width", width), _as_size("height", height)
    exact = _as_choice("mode", mode, MODES) == "exact"
    background = _as_array("background", background, (3,), {})
    alpha_min = _as_scalar("alpha_min", alpha_min, low=0.0)
    alpha_max = _as_scalar("alpha_max", alpha_max, low=0.0)
    transmittance_min = _as_scalar("transmittance_min", transmittance_min, low=0.0)
    pixel_offset = _as_scalar("pixel_offset", pixel_offset)
    keys = depths if sort_keys is None else _as_array("sort_keys", sort_keys, ("N",), sizes)
    blend = dict(background_mode=_as_choice("background_mode", background_mode, BACKGROUND_MODES),
                 normalise_depth=bool(normalise_depth))
    if errors is not None and exact:
        raise ValueError("errors: the boundary band is a matched-mode notion (exact mode takes no decisions)")

    # Candidates: visible Gaussians by ascending depth, ties by ascending index.
    index = np.flatnonzero(visible)
    index = index[np.lexsort((index, keys[index]))]
    mx, my = means2d[index, 0], means2d[index, 1]
    A, B, C = conics[index, 0], conics[index, 1], conics[index, 2]
    o, c, z, r2 = opacities[index], colors[index], depths[index], cutoff_sq[index]

    rgb = np.empty((height, width, 3))
    alpha = np.empty((height, width))
    depth = np.empty((height, width))
    px = np.arange(width) + pixel_offset  # pixel-centre u of every column

    if exact:
        for i in range(height):
            dx = px[:, None] - mx[None, :]  # [W, M]
            dy = (i + pixel_offset) - my[None, :]
            with np.errstate(invalid="ignore", over="ignore"):
                sigma = _half_mahalanobis(A, B, C, dx, dy)
            # sigma >= 0 for a positive-definite conic; the max only removes rounding
            # below 0 (so alpha <= o), and inf - inf at absurd distances means "far".
            sigma = np.where(np.isnan(sigma), np.inf, np.maximum(sigma, 0.0))
            rgb[i], alpha[i], depth[i] = _blend(o * np.exp(-sigma), c, z, background, **blend)
        return Composite(rgb, alpha, depth)

    # Matched mode. Screen extent of each ellipse d² <= R², from Σ2D = inverse(conic); for the
    # band, of d² <= R² + 2 slack, where float32 may still keep a contribution.
    band = tie_slack = grad_band = grad_weight = None
    box_r2 = r2
    if errors is not None:
        band = np.zeros((height, width), dtype=bool)
        tie_slack = np.zeros((height, width))
        grad_band = np.zeros(len(visible), dtype=bool)
        grad_weight = np.zeros((height, width))
        box_r2 = r2 + 2 * sigma_slack(errors, conics, cutoff_sq)[index]
    with np.errstate(invalid="ignore", over="ignore"):
        det = A * C - B * B
        rx = np.sqrt(box_r2 * C / det) * (1 + BOX_PAD) + BOX_PAD
        ry = np.sqrt(box_r2 * A / det) * (1 + BOX_PAD) + BOX_PAD
    for i in range(height):
        py = i + pixel_offset
        row = np.flatnonzero(np.abs(py - my) <= ry)  # still in compositing order
        for j in range(width):
            cand = row[np.abs(px[j] - mx[row]) <= rx[row]]
            dx, dy = px[j] - mx[cand], py - my[cand]
            sigma = _half_mahalanobis(A[cand], B[cand], C[cand], dx, dy)
            a_raw = o[cand] * np.exp(-sigma)
            a = np.minimum(alpha_max, a_raw)
            keep = (sigma <= 0.5 * r2[cand]) & (a >= alpha_min)  # the two skips
            every, cand, a = cand, cand[keep], a[keep]
            # Early stop: the first Gaussian whose T_next falls below transmittance_min
            # is dropped together with everything behind it.
            T_next = np.cumprod(1.0 - a)
            stop = np.flatnonzero(T_next < transmittance_min)
            n = stop[0] if stop.size else a.size
            if band is not None:
                here = pixel_bands(
                    errors, index[every], dx, dy, A[every], B[every], C[every], sigma, 0.5 * r2[every], a_raw, keep,
                    a, n, c[cand], z[cand],
                    alpha_min=alpha_min, alpha_max=alpha_max, transmittance_min=transmittance_min)
                band[i, j], tie_slack[i, j], grad_weight[i, j] = here.in_band, here.tie_slack, here.grad_weight
                grad_band[index[every[here.grad_own]]] = True
            out = _blend(a[None, :n], c[cand[:n]], z[cand[:n]], background, **blend)
            rgb[i, j], alpha[i, j], depth[i, j] = out[0][0], out[1][0], out[2][0]
    return Composite(rgb, alpha, depth, band, tie_slack, grad_band, grad_weight)
