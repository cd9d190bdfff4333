"""Edits of the Gaussian set that keep parameters and Adam moments together
(after gsplat's ``strategy/ops.py``).

Every function here works in place on ``params`` (group name -> leaf
`torch.nn.Parameter`, N rows) and ``optimizers`` (group name -> its own Adam
holding that one parameter: `splatbench.strategies.base.AdamLike`). A group's parameter is replaced
by a new leaf tensor, both in ``params`` and in the optimizer's ``param_groups``,
and its optimizer state moves to the new tensor with the same row edit applied to
every per-row entry (``exp_avg``, ``exp_avg_sq``, ``max_exp_avg_sq``): rows of
removed Gaussians are dropped, rows of new or re-initialised Gaussians get zero
moments (as gsplat does), and the scalar ``step`` is kept. A group without an
optimizer (frozen) or whose optimizer has not stepped yet (no state) only has its
parameter replaced.

``buffers`` (optional, per-Gaussian tensors of the caller such as gradient
accumulators) receive the same row edit: copied from the parent for `duplicate`
and `split`, dropped for `remove`, zeroed for `relocate` / `sample_add`.

Random draws use the ``generator`` passed in (a seeded `torch.Generator` kept in
the strategy's state), so a seed fixes every result.

Letters: N Gaussians; M selected Gaussians; S children per split Gaussian.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache

import torch
import torch.nn.functional as F

from splatbench.errors import InputError
from splatbench.strategies.base import Optimizers, Params

Buffers = dict[str, torch.Tensor]

# gsplat's `compute_relocation` clamps the number of copies of one Gaussian to this.
RELOCATION_N_MAX = 51


# ---------------------------------------------------------------------------
# The one place that replaces parameters and moves optimizer state.

@torch.no_grad()
def _edit(params: Params, optimizers: Optimizers,
          param_fn: Callable[[str, torch.Tensor], torch.Tensor],
          moment_fn: Callable[[torch.Tensor], torch.Tensor],
          names: tuple[str, ...] | None = None) -> None:
    """Replace ``params[name]`` by ``param_fn(name, old)`` and every per-row optimizer
    state tensor ``v`` by ``moment_fn(v)``, for each group in ``names`` (default all)."""
    for name in (tuple(params) if names is None else names):
        old = params[name]
        new = torch.nn.Parameter(param_fn(name, old.detach()).contiguous(), requires_grad=old.requires_grad)
        params[name] = new
        opt = optimizers.get(name)
        if opt is None:
            continue
        found = False
        for group in opt.param_groups:
            for i, p in enumerate(group["params"]):
                if p is old:
                    group["params"][i] = new
                    found = True
        if not found:
            raise InputError(f"optimizers[{name!r}]: does not hold params[{name!r}] "
                             f"(shape {list(old.shape)}); edit parameters only through splatbench.strategies.ops")
        state = opt.state.pop(old, None)
        if state:
            opt.state[new] = {k: (moment_fn(v) if _is_row_state(v, old) else v) for k, v in state.items()}


def _is_row_state(v: object, param: torch.Tensor) -> bool:
    return isinstance(v, torch.Tensor) and v.dim() > 0 and v.shape == param.shape


def _zeros_rows(v: torch.Tensor, n: int) -> torch.Tensor:
    return torch.zeros((n, *v.shape[1:]), dtype=v.dtype, device=v.device)


def _num(params: Params) -> int:
    return int(params["means"].shape[0])


def _check_mask(params: Params, mask: torch.Tensor, what: str) -> torch.Tensor:
    n = _num(params)
    if mask.dtype != torch.bool or tuple(mask.shape) != (n,):
        raise InputError(f"{what}: expected a bool mask of shape [{n}], got {mask.dtype} {list(mask.shape)}")
    return mask.to(params["means"].device)


# ---------------------------------------------------------------------------
# Geometry helpers.

def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """Rotation matrices [M, 3, 3] from quaternions [M, 4] (w, x, y, z; normalised here)."""
    w, x, y, z = F.normalize(quats, dim=-1).unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(*quats.shape[:-1], 3, 3)


def covariances(log_scales: torch.Tensor, quats: torch.Tensor) -> torch.Tensor:
    """World covariances [M, 3, 3] = R diag(s^2) R^T."""
    rs = quat_to_rotmat(quats) * torch.exp(log_scales)[..., None, :]
    return rs @ rs.transpose(-1, -2)


def sample_categorical(weights: torch.Tensor, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """``n`` indices drawn with replacement with probability proportional to ``weights`` [N]
    (inverse CDF in float64: no 2^24 category limit, zero weights never drawn)."""
    cdf = torch.cumsum(weights.detach().double().clamp_min(0), dim=0)
    total = cdf[-1]
    if not bool(total > 0):
        raise InputError("sample_categorical: weights sum to zero")
    u = torch.rand(n, generator=generator, dtype=torch.float64, device=weights.device) * total
    return torch.searchsorted(cdf, u, right=True).clamp_max(weights.shape[0] - 1)


@lru_cache(maxsize=4)
def _relocation_coefficients(n_max: int) -> torch.Tensor:
    """[n_max + 1, n_max] float64: row r, column k holds (-1)^k C(r, k+1) / sqrt(k+1).

    This is the paper's double sum sum_{i=1..r} sum_{k=0..i-1} C(i-1, k) (-1)^k / sqrt(k+1)
    collapsed over i with sum_{i=1..r} C(i-1, k) = C(r, k+1) (hockey-stick identity)."""
    coef = torch.zeros(n_max + 1, n_max, dtype=torch.float64)
    for r in range(1, n_max + 1):
        for k in range(r):
            coef[r, k] = (-1) ** k * math.comb(r, k + 1) / math.sqrt(k + 1)
    return coef


def compute_relocation(opacities: torch.Tensor, scales: torch.Tensor, ratios: torch.Tensor,
                       n_max: int = RELOCATION_N_MAX) -> tuple[torch.Tensor, torch.Tensor]:
    """3DGS-MCMC's moment-preserving split of one Gaussian into ``ratio`` copies
    (Kheradmand et al. 2024, Eq. 9; mirrors gsplat's CUDA ``compute_relocation``).

    Args:
        opacities: [M] opacities in (0, 1). scales: [M, 3] (not log). ratios: [M] number
            of copies, the original included (clamped to [1, n_max]).

    Returns:
        new_opacities [M] = 1 - (1 - o)^(1/r) and new_scales [M, 3] = o / D * s with
        D = sum_{i=1..r} sum_{k=0..i-1} C(i-1, k) (-1)^k new_o^(k+1) / sqrt(k+1),
        evaluated in float64 (the alternating binomial sum cancels heavily).
    """
    r = ratios.long().clamp(1, n_max)
    o = opacities.double()
    new_o = 1.0 - torch.pow(1.0 - o, 1.0 / r.double())
    coef = _relocation_coefficients(n_max).to(o.device)[r]                      # [M, n_max]
    powers = new_o[:, None] ** torch.arange(1, n_max + 1, device=o.device, dtype=torch.float64)
    denom = (coef * powers).sum(-1)
    new_s = (o / denom)[:, None] * scales.double()
    return new_o.to(opacities.dtype), new_s.to(scales.dtype)


# ---------------------------------------------------------------------------
# Adaptive density control (3DGS).

@torch.no_grad()
def duplicate(params: Params, optimizers: Optimizers, mask: torch.Tensor, *,
              buffers: Buffers | None = None) -> int:
    """Clone the Gaussians in ``mask`` [N] (appended at the end, identical parameters,
    zero moments). Returns the number cloned."""
    sel = torch.where(_check_mask(params, mask, "duplicate"))[0]
    m = len(sel)
    if m == 0:
        return 0
    _edit(params, optimizers, lambda _, p: torch.cat([p, p[sel]]), lambda v: torch.cat([v, _zeros_rows(v, m)]))
    for k, v in (buffers or {}).items():
        buffers[k] = torch.cat([v, v[sel]])
    return m


@torch.no_grad()
def split(params: Params, optimizers: Optimizers, mask: torch.Tensor, n: int = 2, *,
          generator: torch.Generator | None = None, buffers: Buffers | None = None,
          revised_opacity: bool = False) -> int:
    """Replace each Gaussian in ``mask`` [N] by ``n`` children sampled from it (3DGS):
    means = parent + R (s * randn), scales = s / (0.8 n) (s / 1.6 for n = 2), the
    parent's rotation, opacity and colour. Parents are removed; the others keep their
    order and the children ([n, M] child-major) are appended with zero moments.
    ``revised_opacity``: each child gets opacity 1 - (1 - o)^(1/n) instead of o, so
    that n overlapping children let as much light through as their parent did
    ("Revising Densification in Gaussian Splatting", Rota Bulo et al. 2024; gsplat's
    ``split(revised_opacity=True)``: 1 - sqrt(1 - o) for its n = 2).
    Returns the number of parents split."""
    if n < 1:
        raise InputError(f"split: n must be >= 1, got {n}")
    mask = _check_mask(params, mask, "split")
    sel, rest = torch.where(mask)[0], torch.where(~mask)[0]
    m = len(sel)
    if m == 0:
        return 0
    means, log_scales = params["means"].detach(), params["log_scales"].detach()
    scales = torch.exp(log_scales[sel])                                           # [M, 3]
    rot = quat_to_rotmat(params["quats"].detach()[sel])                         # [M, 3, 3]
    noise = torch.randn((n, m, 3), generator=generator, dtype=means.dtype, device=means.device)
    offsets = torch.einsum("mij,mj,smj->smi", rot, scales, noise)              # [n, M, 3]

    def children(name: str, p: torch.Tensor) -> torch.Tensor:
        if name == "means":
            c = (p[sel][None] + offsets).reshape(n * m, 3)
        elif name == "log_scales":
            c = torch.log(scales / (0.8 * n)).repeat(n, 1)
        elif name == "opacity_logits" and revised_opacity:
            c = torch.logit(1.0 - torch.pow(1.0 - torch.sigmoid(p[sel]), 1.0 / n)).repeat(n)
        else:
            c = p[sel].repeat(n, *([1] * (p.dim() - 1)))
        return torch.cat([p[rest], c])

    _edit(params, optimizers, children, lambda v: torch.cat([v[rest], _zeros_rows(v, n * m)]))
    for k, v in (buffers or {}).items():
        buffers[k] = torch.cat([v[rest], v[sel].repeat(n, *([1] * (v.dim() - 1)))])
    return m


@torch.no_grad()
def remove(params: Params, optimizers: Optimizers, mask: torch.Tensor, *,
           buffers: Buffers | None = None) -> int:
    """Remove the Gaussians in ``mask`` [N] (rows and moments). Returns the number removed."""
    keep = torch.where(~_check_mask(params, mask, "remove"))[0]
    m = _num(params) - len(keep)
    if m == 0:
        return 0
    _edit(params, optimizers, lambda _, p: p[keep], lambda v: v[keep])
    for k, v in (buffers or {}).items():
        buffers[k] = v[keep]
    return m


@torch.no_grad()
def reset_opacity(params: Params, optimizers: Optimizers, value: float) -> None:
    """Clamp every opacity to at most ``value`` (post-sigmoid) and zero all opacity
    moments (3DGS's periodic opacity reset)."""
    if not 0.0 < value < 1.0:
        raise InputError(f"reset_opacity: value must be in (0, 1), got {value}")
    limit = math.log(value / (1.0 - value))
    _edit(params, optimizers, lambda _, p: p.clamp(max=limit), torch.zeros_like, names=("opacity_logits",))


# ---------------------------------------------------------------------------
# 3DGS-MCMC.

@torch.no_grad()
def _copy_corrected(params: Params, sources: torch.Tensor, min_opacity: float
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """The corrected opacity logits [M] and log scales [M, 3] shared by each sampled
    source Gaussian and its new copies (ratio = copies of that source + 1)."""
    opac = torch.sigmoid(params["opacity_logits"].detach())
    ratios = torch.bincount(sources, minlength=_num(params))[sources] + 1
    new_o, new_s = compute_relocation(opac[sources], torch.exp(params["log_scales"].detach()[sources]), ratios)
    eps = torch.finfo(torch.float32).eps
    new_o = new_o.clamp(min=min_opacity, max=1.0 - eps)
    return torch.logit(new_o), torch.log(new_s)


def _with_corrected_sources(name: str, p: torch.Tensor, sources: torch.Tensor, logits: torch.Tensor,
                            log_scales: torch.Tensor) -> torch.Tensor:
    """A copy of parameter group ``name`` whose ``sources`` rows hold the corrected opacity logits
    or log scales of `_copy_corrected` (the other groups' rows unchanged)."""
    p = p.clone()
    if name == "opacity_logits":
        p[sources] = logits
    elif name == "log_scales":
        p[sources] = log_scales
    return p


@torch.no_grad()
def relocate(params: Params, optimizers: Optimizers, dead_mask: torch.Tensor, *, min_opacity: float = 0.005,
             generator: torch.Generator | None = None, buffers: Buffers | None = None) -> int:
    """Move the dead Gaussians (``dead_mask`` [N]) onto live ones sampled proportionally
    to opacity (3DGS-MCMC). Each sampled source and its copies share the corrected
    opacity and scale of `compute_relocation`; the sources' and the relocated rows'
    moments are zeroed. N is unchanged. Returns the number relocated (0 when nothing
    is alive)."""
    dead_mask = _check_mask(params, dead_mask, "relocate")
    dead, alive = torch.where(dead_mask)[0], torch.where(~dead_mask)[0]
    if len(dead) == 0 or len(alive) == 0:
        return 0
    opac = torch.sigmoid(params["opacity_logits"].detach())
    sources = alive[sample_categorical(opac[alive], len(dead), generator)]
    logits, log_scales = _copy_corrected(params, sources, min_opacity)
    touched = torch.cat([sources, dead])

    def move(name: str, p: torch.Tensor) -> torch.Tensor:
        p = _with_corrected_sources(name, p, sources, logits, log_scales)
        p[dead] = p[sources]
        return p

    def zero_touched(v: torch.Tensor) -> torch.Tensor:
        v = v.clone()
        v[touched] = 0
        return v

    _edit(params, optimizers, move, zero_touched)
    for k, v in (buffers or {}).items():
        buffers[k] = zero_touched(v)
    return len(dead)


@torch.no_grad()
def sample_add(params: Params, optimizers: Optimizers, n: int, *, min_opacity: float = 0.005,
               generator: torch.Generator | None = None, buffers: Buffers | None = None) -> int:
    """Append ``n`` copies of Gaussians sampled proportionally to opacity (3DGS-MCMC),
    with the opacity and scale correction of `compute_relocation` applied to each
    source and its copies; the sources' moments are zeroed, the copies get zero
    moments. Returns ``n``."""
    if n <= 0:
        return 0
    sources = sample_categorical(torch.sigmoid(params["opacity_logits"].detach()), n, generator)
    logits, log_scales = _copy_corrected(params, sources, min_opacity)

    def grow(name: str, p: torch.Tensor) -> torch.Tensor:
        p = _with_corrected_sources(name, p, sources, logits, log_scales)
        return torch.cat([p, p[sources]])

    def grow_moment(v: torch.Tensor) -> torch.Tensor:
        v = v.clone()
        v[sources] = 0
        return torch.cat([v, _zeros_rows(v, n)])

    _edit(params, optimizers, grow, grow_moment)
    for k, v in (buffers or {}).items():
        buffers[k] = torch.cat([v, _zeros_rows(v, n)])
    return n


def noise_gate(opacities: torch.Tensor, k: float = 100.0, x0: float = 0.995) -> torch.Tensor:
    """3DGS-MCMC's ``op_sigmoid(1 - opacity)`` = 1 / (1 + exp(-k (1 - o - x0))):
    ~1 for transparent Gaussians (o < 0.005), ~0 (e^-99) for opaque ones."""
    return torch.sigmoid(k * ((1.0 - opacities) - x0))


@torch.no_grad()
def inject_noise(params: Params, scale: float, *, generator: torch.Generator | None = None) -> torch.Tensor:
    """Perturb ``params["means"]`` in place by Sigma (eps * gate(opacity) * scale),
    eps ~ N(0, I), Sigma = R diag(s^2) R^T (3DGS-MCMC's SGLD noise; ``scale`` is
    means_lr x noise_lr). Moments are untouched. Returns the noise added [N, 3]."""
    means = params["means"]
    eps = torch.randn(means.shape, generator=generator, dtype=means.dtype, device=means.device)
    gate = noise_gate(torch.sigmoid(params["opacity_logits"].detach()))
    cov = covariances(params["log_scales"].detach(), params["quats"].detach())
    noise = torch.einsum("nij,nj->ni", cov, eps * gate[:, None] * scale)
    means.add_(noise)
    return noise
