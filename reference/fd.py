"""Central finite differences of a scalar loss of `render` (the oracle for splatbench's
backward pass, ``splatbench.raster.render``'s gradients)."""

from __future__ import annotations

import numpy as np

from reference.render import render

GROUPS = ("means", "log_scales", "quats", "opacity_logits", "sh")


def finite_difference_grad(loss, means, log_scales, quats, opacity_logits, sh, *, wrt,
                           indices=None, eps=1e-6, **render_kwargs) -> np.ndarray:
    """d loss(render(...)) / d ``wrt`` by central differences in float64.

    Args:
        loss: callable RenderOutput -> float.
        means: [N, 3]; log_scales: [N, 3]; quats: [N, 4]; opacity_logits: [N]; sh: [N, K, 3].
        wrt: the parameter group, one of "means", "log_scales", "quats", "opacity_logits", "sh".
        indices: optional flat indices into that group (its C-order ``ravel()``).
        eps: half step. The step actually taken, (x + eps) - (x - eps) as rounded, is
            the divisor.
        **render_kwargs: passed to `render` (K, world_to_camera, width, height, mode, ...).
            Use mode="exact" for a derivative of the smooth function.

    Returns:
        The gradient with the group's shape, or [len(indices)] when ``indices`` is given.
    """
    if wrt not in GROUPS:
        raise ValueError(f"wrt: expected one of {list(GROUPS)}, got {wrt!r}")
    eps = float(eps)
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps: expected a finite positive number, got {eps!r}")
    params = {name: np.array(value, dtype=np.float64) for name, value in
              zip(GROUPS, (means, log_scales, quats, opacity_logits, sh))}
    flat = params[wrt].reshape(-1)  # a view: editing it edits params[wrt]
    picked = range(flat.size) if indices is None else [int(i) for i in indices]
    for i in picked:
        if not 0 <= i < flat.size:
            raise ValueError(f"indices: {i} is out of range for {wrt} with {flat.size} entries")

    grad = np.empty(len(picked))
    for k, i in enumerate(picked):
        x = flat[i]
        flat[i] = x + eps
        f_plus, x_plus = float(loss(render(**params, **render_kwargs))), flat[i]
        flat[i] = x - eps
        f_minus, x_minus = float(loss(render(**params, **render_kwargs))), flat[i]
        flat[i] = x
        grad[k] = (f_plus - f_minus) / (x_plus - x_minus)
    return grad.reshape(params[wrt].shape) if indices is None else grad
