"""Real spherical harmonics, degrees 0-3, with graphdeco-inria 3DGS's constants and signs.

Mirrors `reference.eval_sh`. Only the bands up to the requested degree are read,
so unused bands cost neither time nor gradient work.
"""

from __future__ import annotations

from splatbench.conventions import SH_C0, SH_C1, SH_C2, SH_C3
from splatbench.raster.device import dr
from splatbench.raster.projection import array_namespace

C0, C1, C2, C3 = SH_C0, SH_C1, SH_C2, SH_C3


def sh_basis(x, y, z, degree: int) -> list:
    """The (degree+1)^2 basis values for unit directions (x, y, z), DC first."""
    basis = [C0]
    if degree >= 1:
        basis += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        basis += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2.0 * zz - xx - yy),
                  C2[3] * x * z, C2[4] * (xx - yy)]
    if degree >= 3:
        basis += [C3[0] * y * (3.0 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4.0 * zz - xx - yy),
                  C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy), C3[4] * x * (4.0 * zz - xx - yy),
                  C3[5] * z * (xx - yy), C3[6] * x * (xx - 3.0 * yy)]
    return basis


def eval_sh(sh, dirs, degree: int):
    """Colour of each Gaussian seen along ``dirs``: max(SH . basis + 0.5, 0).

    Args:
        sh: [N, K, 3] Dr.Jit tensor, K = (d+1)^2 >= (degree+1)^2.
        dirs: [N, 3] as a Dr.Jit Array3f of unit vectors (world space).
        degree: bands 0..degree are used; higher bands are never read.

    Returns:
        [N, 3] colours as an Array3f.
    """
    m = array_namespace(sh.array)
    n, k_total = sh.shape[0], sh.shape[1]
    basis = sh_basis(dirs.x, dirs.y, dirs.z, degree)
    row = dr.arange(m.UInt32, n) * (3 * k_total)
    rgb = []
    for c in range(3):
        acc = 0.5
        for k, b in enumerate(basis):
            coeff = dr.gather(m.Float, sh.array, row + (3 * k + c), mode=dr.ReduceMode.Permute)
            acc = acc + b * coeff
        rgb.append(dr.maximum(acc, 0.0))
    return m.Array3f(*rgb)
