"""The Gaussian scene representation: raw 3DGS parameters and their activations.

Letters: N Gaussians, K spherical-harmonic bases per colour channel (K = (d+1)² for
SH degree d in 0..3). Activations follow ``docs/conventions.md``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields

import numpy as np

from splatbench.guards import SH_BASES_OF_DEGREE, as_float_array, check_sh_degree
from splatbench.conventions import LOG_SCALE_CLIP, QUAT_MIN, SH_C0
from splatbench.errors import InputError
from splatbench.ply import ViewHints, read_ply, write_ply




def normalize_quats(quats: np.ndarray) -> np.ndarray:
    """Unit quaternions [N, 4] by the overflow-safe rule of conventions.md.

    ``q' = q / max|q_i|`` then ``q'/|q'|``, so 1e30 components do not overflow; a
    quaternion with max|q_i| < QUAT_MIN counts as zero, and a zero quaternion gives
    zeros (which `quat_to_rotmat` maps to the identity). The result has the dtype
    of ``quats``.
    """
    q = np.asarray(quats)
    peak = np.max(np.abs(q), axis=-1, keepdims=True)
    keep = peak >= QUAT_MIN
    scaled = np.where(keep, q / np.where(keep, peak, 1), 0)
    norm = np.sqrt(np.sum(scaled * scaled, axis=-1, keepdims=True))
    return np.where(keep, scaled / np.where(norm > 0, norm, 1), 0).astype(q.dtype, copy=False)


def quat_to_rotmat(unit_quats: np.ndarray) -> np.ndarray:
    """Rotation matrices [N, 3, 3] from unit quaternions [N, 4] (w, x, y, z).

    Uses the formula of conventions.md, which maps the zero quaternion to the identity.
    """
    w, x, y, z = np.moveaxis(np.asarray(unit_quats), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


@dataclass(frozen=True, eq=False)
class Gaussians:
    """N anisotropic 3D Gaussians in raw (pre-activation) 3DGS parameters.

    Fields (all converted to C-contiguous float32 and checked for shape and
    finiteness on construction; errors are one-line `InputError` naming the field)::

        means           [N, 3]     world positions
        log_scales      [N, 3]     per-axis log standard deviations
        quats           [N, 4]     rotations (w, x, y, z), any length; 0 means identity
        opacity_logits  [N]        opacity before the sigmoid
        sh              [N, K, 3]  SH coefficients, K = (d+1)² with d in 0..3, DC first
                                   then band by band; last axis is the RGB channel

    The arrays are not copied when they already are contiguous float32, so treat
    them as read-only; use `subset`, `with_sh_degree` or `dataclasses.replace` to
    derive new sets.

    Example::

        g = Gaussians(means=np.zeros((2, 3)), log_scales=np.zeros((2, 3)),
                      quats=[[1, 0, 0, 0]] * 2, opacity_logits=np.zeros(2),
                      sh=np.zeros((2, 16, 3)))
        len(g), g.sh_degree, g.covariances().shape   # 2, 3, (2, 3, 3)
    """

    means: np.ndarray           # [N, 3]
    log_scales: np.ndarray      # [N, 3]
    quats: np.ndarray           # [N, 4] (w, x, y, z)
    opacity_logits: np.ndarray  # [N]
    sh: np.ndarray              # [N, K, 3]

    def __post_init__(self) -> None:
        sizes: dict[str, int] = {}
        set_ = object.__setattr__
        set_(self, "means", as_float_array("means", self.means, ("N", 3), sizes))
        set_(self, "log_scales", as_float_array("log_scales", self.log_scales, ("N", 3), sizes))
        set_(self, "quats", as_float_array("quats", self.quats, ("N", 4), sizes))
        set_(self, "opacity_logits", as_float_array("opacity_logits", self.opacity_logits, ("N",), sizes))
        sh_shape = np.shape(self.sh)
        if len(sh_shape) != 3 or sh_shape[1] not in SH_BASES_OF_DEGREE or sh_shape[2] != 3:
            raise InputError(
                f"sh: expected shape [N, K, 3] with K in {SH_BASES_OF_DEGREE}, got {list(sh_shape)}")
        set_(self, "sh", as_float_array("sh", self.sh, ("N", None, 3), sizes))

    # ------------------------------------------------------------------ basics
    def __len__(self) -> int:
        return int(self.means.shape[0])

    def __repr__(self) -> str:
        return f"Gaussians(N={len(self)}, sh_degree={self.sh_degree})"

    @property
    def sh_degree(self) -> int:
        """SH degree d (0..3), from K = (d+1)²."""
        return SH_BASES_OF_DEGREE.index(self.sh.shape[1])

    # ------------------------------------------------------------- activations
    @property
    def scales(self) -> np.ndarray:
        """[N, 3] float32 standard deviations, ``exp(clip(log_scales, -20, 20))``."""
        return np.exp(np.clip(self.log_scales, -LOG_SCALE_CLIP, LOG_SCALE_CLIP))

    @property
    def rotations(self) -> np.ndarray:
        """[N, 4] float32 unit quaternions (w, x, y, z); zero quaternions stay zero."""
        return normalize_quats(self.quats)

    @property
    def opacities(self) -> np.ndarray:
        """[N] float32 opacities in (0, 1), ``sigmoid(opacity_logits)`` (overflow-free)."""
        x = self.opacity_logits
        e = np.exp(-np.abs(x))  # in (0, 1]: no overflow for any finite logit
        return np.where(x >= 0, 1 / (1 + e), e / (1 + e)).astype(np.float32)

    def covariances(self) -> np.ndarray:
        """[N, 3, 3] float64 world covariances ``Σ = R S Sᵀ Rᵀ`` (conventions.md).

        Computed as ``M Mᵀ`` with ``M = R S`` in float64, so the result is exactly
        symmetric and positive semi-definite up to rounding.
        """
        rot = quat_to_rotmat(normalize_quats(self.quats.astype(np.float64)))
        scales = np.exp(np.clip(self.log_scales.astype(np.float64), -LOG_SCALE_CLIP, LOG_SCALE_CLIP))
        m = rot * scales[:, None, :]
        return m @ np.swapaxes(m, -1, -2)

    # ---------------------------------------------------------------- editing
    def with_sh_degree(self, degree: int) -> Gaussians:
        """A copy with SH truncated to ``degree`` bands or zero-padded up to it."""
        d = check_sh_degree("degree", degree)
        k = SH_BASES_OF_DEGREE[d]
        n, k_now, _ = self.sh.shape
        if k <= k_now:
            sh = self.sh[:, :k].copy()
        else:
            sh = np.concatenate([self.sh, np.zeros((n, k - k_now, 3), np.float32)], axis=1)
        return Gaussians(self.means, self.log_scales, self.quats, self.opacity_logits, sh)

    def subset(self, index) -> Gaussians:
        """The Gaussians selected by a boolean mask [N] or an integer index array."""
        idx = np.asarray(index)
        n = len(self)
        if idx.dtype == np.bool_:
            if idx.shape != (n,):
                raise InputError(f"index: boolean mask must have shape [{n}], got {list(idx.shape)}")
        elif np.issubdtype(idx.dtype, np.integer) or idx.size == 0:
            idx = idx.astype(np.int64).reshape(-1)
            bad = (idx < -n) | (idx >= n)
            if bad.any():
                raise InputError(f"index: value {int(idx[np.argmax(bad)])} out of range for N={n}")
        else:
            raise InputError(f"index: expected a boolean mask or integer indices, got dtype {idx.dtype}")
        return Gaussians(self.means[idx], self.log_scales[idx], self.quats[idx],
                         self.opacity_logits[idx], self.sh[idx])

    # --------------------------------------------------------------------- I/O
    @classmethod
    def from_ply(cls, path: str | os.PathLike) -> Gaussians:
        """Read a graphdeco-inria 3DGS ``.ply`` (see `splatbench.ply.read_ply`); a bad value
        is one `InputError` line naming the file."""
        arrays = read_ply(path)
        try:
            return cls(*arrays)
        except InputError as exc:
            raise InputError(f"{os.fspath(path)}: {exc}") from None

    def to_ply(self, path: str | os.PathLike, hints: ViewHints | None = None) -> None:
        """Write a graphdeco-inria 3DGS ``.ply`` atomically (see `splatbench.ply.write_ply`);
        ``hints`` (`splatbench.ply.ViewHints`: up, background) go into its header comments."""
        write_ply(self, path, hints)


#: The five parameter groups, in `Gaussians`' field order: the order of `rasterize`'s and every
#: backend's arguments.
GROUPS: tuple[str, ...] = tuple(f.name for f in fields(Gaussians))
