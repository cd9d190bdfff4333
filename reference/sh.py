"""Spherical-harmonics colour (mirrors ``splatbench.raster.eval_sh``).

Constants and signs of graphdeco-inria's 3DGS ``utils/sh_utils.py``, as listed in
``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from reference.project import _as_array

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
      -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435)

MAX_DEGREE = 3
#: "graphdeco": the constants above, Condon-Shortley phase included (odd orders m negative);
#: "no_condon_shortley": the same real SH without that phase (every constant positive).
SH_BASES = ("graphdeco", "no_condon_shortley")
COLOUR_CLAMPS = ("min0", "none", "0_1")  # max(c, 0) (graphdeco), none, clip(c, 0, 1)


def sh_degree_for(num_bases, sh_degree=None, *, name="sh_degree"):
    """The SH degree to evaluate for ``num_bases`` = K coefficients per Gaussian.

    K must be (d+1)² for d in 0..3. ``sh_degree=None`` means every band present; a
    larger degree than K holds raises ValueError naming ``name``.
    """
    available = {1: 0, 4: 1, 9: 2, 16: 3}.get(int(num_bases))
    if available is None:
        raise ValueError(f"sh: expected K in [1, 4, 9, 16] SH coefficients, got K={num_bases}")
    if sh_degree is None:
        return available
    if isinstance(sh_degree, bool) or not isinstance(sh_degree, (int, np.integer)) or sh_degree < 0:
        raise ValueError(f"{name}: expected a non-negative int or None, got {sh_degree!r}")
    if sh_degree > available:
        raise ValueError(f"{name}={sh_degree} needs K={(sh_degree + 1) ** 2} SH coefficients, sh has K={num_bases}")
    return int(sh_degree)


def sh_basis(dirs, degree, convention="graphdeco"):
    """Real SH basis values in graphdeco's order and signs.

    Args:
        dirs: [N, 3] unit directions (x, y, z).
        degree: 0..3.
        convention: one of SH_BASES (the sign convention).

    Returns:
        basis: [N, (degree+1)²] float64.
    """
    x, y, z = np.asarray(dirs, dtype=np.float64).T
    xx, yy, zz = x * x, y * y, z * z
    basis = [np.full_like(x, C0)]
    if degree >= 1:
        basis += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        basis += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy),
                  C2[3] * x * z, C2[4] * (xx - yy)]
    if degree >= 3:
        basis += [C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
                  C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy),
                  C3[5] * z * (xx - yy), C3[6] * x * (xx - 3 * yy)]
    values = np.stack(basis, axis=1)
    if convention == "no_condon_shortley":  # every graphdeco term with a negative constant flips sign
        signs = np.sign([C0, -C1, C1, -C1, *C2, *C3])[:values.shape[1]]
        values = values * np.where(signs < 0, -1.0, 1.0)[None]
    elif convention != "graphdeco":
        raise ValueError(f"sh_basis: expected one of {list(SH_BASES)}, got {convention!r}")
    return values


def eval_sh(sh, dirs, degree, *, basis="graphdeco", colour_clamp="min0"):
    """Colour from SH coefficients (mirrors ``splatbench.raster.eval_sh``).

    Args:
        sh: [N, K, 3] coefficients, DC first then band by band; K >= (degree+1)².
            Bands above ``degree`` are ignored.
        dirs: [N, 3] unit view directions, normalize(mean - camera_centre), world space.
        degree: 0..3.
        basis: one of SH_BASES; colour_clamp: one of COLOUR_CLAMPS.

    Returns:
        colors: [N, 3] float64, ``max(Σ_k sh[:, k] * basis_k(dirs) + 0.5, 0)`` (graphdeco's clamp).
    """
    sizes = {}
    sh = _as_array("sh", sh, ("N", None, 3), sizes)
    dirs = _as_array("dirs", dirs, ("N", 3), sizes)
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or not 0 <= degree <= MAX_DEGREE:
        raise ValueError(f"degree: expected an int in 0..{MAX_DEGREE}, got {degree!r}")
    bases = (degree + 1) ** 2
    if sh.shape[1] < bases:
        raise ValueError(f"degree={degree} needs K={bases} SH coefficients, sh has K={sh.shape[1]}")
    if colour_clamp not in COLOUR_CLAMPS:
        raise ValueError(f"colour_clamp: expected one of {list(COLOUR_CLAMPS)}, got {colour_clamp!r}")
    rgb = np.einsum("nk,nkc->nc", sh_basis(dirs, degree, basis), sh[:, :bases, :]) + 0.5
    if colour_clamp == "none":
        return rgb
    return np.clip(rgb, 0.0, 1.0 if colour_clamp == "0_1" else None)
