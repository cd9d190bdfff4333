"""splatbench's densification strategies against gsplat 1.5.3's, driven from the same state.

Both implementations get the same parameters, Adam moments, screen-space gradients and
steps; after every step the test compares what they decided -- which Gaussians were
cloned, split, pruned, relocated, added, reset -- and the resulting parameters and
moments, row by row, to float32 tolerance. gsplat's strategies are PyTorch code; the
two calls of theirs that go to CUDA kernels are replaced here, in the harness only:

- ``gsplat.strategy.ops.quat_scale_to_covar_preci`` (the MCMC noise) by gsplat's own
  PyTorch version, ``gsplat.cuda._torch_impl._quat_scale_to_covar_preci``;
- ``gsplat.strategy.ops.compute_relocation`` (MCMC's Eq. 9) by `_relocation_kernel`, a
  line-by-line transcription of its CUDA kernel (``RelocationCUDA.cu``, float32 as there).

Random parts share one generator: before each step gsplat's global torch generator is
set to the state of splatbench's seeded generator, and both draw the same numbers in
the same order (split children, MCMC noise). MCMC's sampler differs on purpose (below),
so gsplat's ``_multinomial_sample`` is replaced by splatbench's sampler for the
step-by-step comparison, and the two samplers are compared in distribution separately.

Deliberate deviations of splatbench (each checked where it shows):

1. Step numbering: gsplat's hooks take the 0-based loop index and run after the
   optimizer step, so gsplat refines one iteration later than graphdeco (its step 100
   is the 101st iteration). splatbench counts completed iterations (``ctx.step + 1``)
   as graphdeco does; the harness passes gsplat ``ctx.step + 1`` so that both refine
   at the same iterations.
2. Gradient threshold: ``>=`` as graphdeco (gsplat: ``>``); only a gradient exactly at
   the threshold differs (`test_threshold_tie_is_graphdecos`).
3. Opacity reset: gsplat 1.5.3 never resets (``step % reset_every == 0 & step > 0``
   parses as ``(step % reset_every == 0) and (0 > 0)``; gsplat issue #797, fixed by PR
   #776); splatbench resets as graphdeco does. The harness applies gsplat's own
   ``reset_opa`` where gsplat's intended condition holds, and
   `test_gsplat_1_5_3_never_resets_opacity` pins the installed behaviour.
4. MCMC sampling: splatbench draws by inverse CDF in float64 with a seeded generator
   (no 2^24 limit, deterministic); gsplat calls ``torch.multinomial``. Same
   distribution (`test_mcmc_sampler_has_gsplats_distribution`).
5. MCMC moments: splatbench zeroes the Adam moments of relocated rows (they belonged
   to the dead Gaussian; gsplat keeps them) and of the sources of added copies (as
   3dgs-mcmc's ``replace_tensors_to_optimizer(inds=add_idx)``; gsplat keeps them).
   Compared everywhere else; the rows splatbench zeroes are checked to be exactly those.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math

import pytest
import torch

from splatbench.strategies import DefaultStrategy, MCMCStrategy, ops
from tests.test_strategies import adam_step, ctx, fake_info, make_params

pytestmark = pytest.mark.skipif(importlib.util.find_spec("gsplat") is None,
                                reason="gsplat is not installed (pip install -e '.[gsplat]'): "
                                       "the strategies cannot be compared with gsplat's")

# splatbench group -> gsplat group
NAMES = {"means": "means", "log_scales": "scales", "quats": "quats", "opacity_logits": "opacities",
         "sh_dc": "sh0", "sh_rest": "shN"}
# float32 parameters edited by the same formulas in both; the only rounding differences are
# the opacity-reset clamp (math.log in float64 here, torch.logit in float32 there: 1 ulp of
# the logit) and the relocation (float64 here, the kernel's float32 sums there: for the
# ratios below, <= r(r+1)/2 = 15 terms, each rounded at 6e-8 relative)
RTOL, ATOL = 2e-6, 1e-6


# ---------------------------------------------------------------------------
# Harness

def _relocation_kernel(opacities, scales, ratios, binoms):
    """gsplat's ``relocation_kernel`` (RelocationCUDA.cu), per Gaussian, in float32."""
    n_max = binoms.shape[0]
    ratios = ratios.clamp(1, n_max).int()
    new_o = torch.empty_like(opacities)
    new_s = torch.empty_like(scales)
    for idx in range(opacities.shape[0]):
        n_idx = int(ratios[idx])
        o = opacities[idx].float()
        no = 1.0 - torch.pow(1.0 - o, torch.tensor(1.0 / n_idx, dtype=torch.float32))
        denom = torch.tensor(0.0, dtype=torch.float32)
        for i in range(1, n_idx + 1):
            for k in range(i):
                term = (torch.tensor((-1.0) ** k / math.sqrt(k + 1), dtype=torch.float32)
                        * torch.pow(no, torch.tensor(float(k + 1), dtype=torch.float32)))
                denom = denom + binoms[i - 1, k].float() * term
        new_o[idx] = no
        new_s[idx] = (o / denom) * scales[idx]
    return new_o, new_s


@pytest.fixture
def gsplat_cpu(monkeypatch):
    """gsplat's strategy modules with their two CUDA calls replaced (module docstring)."""
    import gsplat.strategy.ops as gops
    from gsplat.cuda._torch_impl import _quat_scale_to_covar_preci

    monkeypatch.setattr(gops, "compute_relocation", _relocation_kernel)
    monkeypatch.setattr(gops, "quat_scale_to_covar_preci", _quat_scale_to_covar_preci)
    # deviation 4: the same sampler on both sides (global generator there, see module docstring)
    monkeypatch.setattr(gops, "_multinomial_sample",
                        lambda weights, n, replacement=True: ops.sample_categorical(weights, n, None))
    return gops


def to_gsplat(params, optimizers):
    """A deep copy of splatbench's parameters and Adam states under gsplat's names."""
    gp, go = {}, {}
    for name, p in params.items():
        q = torch.nn.Parameter(p.detach().clone(), requires_grad=p.requires_grad)
        opt = torch.optim.Adam([q], lr=1e-3, eps=1e-15)
        opt.state[q] = {k: v.clone() for k, v in optimizers[name].state[p].items()}
        gp[NAMES[name]], go[NAMES[name]] = q, opt
    return gp, go


def gsplat_info(info, grad, absgrad):
    """gsplat's ``info`` dict for one camera, from splatbench's `RasterInfo` of the same view."""
    n = grad.shape[0]
    means2d = torch.zeros(1, n, 2, requires_grad=True)
    means2d.grad = grad[None].clone()
    if absgrad is not None:
        means2d.absgrad = absgrad[None].clone()
    radii = info.radii.float()[None, :, None].expand(1, n, 2).clone()
    return {"width": info.width, "height": info.height, "n_cameras": 1, "radii": radii, "gaussian_ids": None,
            "means2d": means2d}


class Recorder:
    """Records the masks / counts each side's edit functions were called with."""

    def __init__(self):
        self.calls: list[tuple[str, torch.Tensor | int]] = []

    def wrap(self, monkeypatch, module, fname, kind, arg):
        """Record ``module.fname``'s argument ``arg`` (keyword, else the third positional;
        None: record 0) under ``kind`` at every call."""
        original = getattr(module, fname)

        def recorded(*args, **kwargs):
            value = 0 if arg is None else kwargs[arg] if arg in kwargs else args[2]
            self.calls.append((kind, value.clone() if isinstance(value, torch.Tensor) else value))
            return original(*args, **kwargs)

        monkeypatch.setattr(module, fname, recorded)


def record_both(monkeypatch, gops):
    """Recorders on splatbench's ops and gsplat's (the names each strategy module calls)."""
    import gsplat.strategy.default as gdefault
    import gsplat.strategy.mcmc as gmcmc

    ours, theirs = Recorder(), Recorder()
    for fname, kind, arg in (("duplicate", "clone", "mask"), ("split", "split", "mask"), ("remove", "prune", "mask"),
                             ("reset_opacity", "reset", None), ("relocate", "relocate", "dead_mask"),
                             ("sample_add", "add", "n")):
        ours.wrap(monkeypatch, ops, fname, kind, arg)
    for module in (gdefault, gmcmc):
        for fname, kind, arg in (("duplicate", "clone", "mask"), ("split", "split", "mask"),
                                 ("remove", "prune", "mask"), ("relocate", "relocate", "mask"),
                                 ("sample_add", "add", "n")):
            if hasattr(module, fname):
                theirs.wrap(monkeypatch, module, fname, kind, arg)
    return ours, theirs


def nonempty(calls):
    """The edits that change something (gsplat skips the call for an empty mask or a count
    of 0, splatbench calls and returns 0): every reset, masks with a row, counts > 0."""
    return [(k, v) for k, v in calls
            if k == "reset" or (bool(v.any()) if isinstance(v, torch.Tensor) else v != 0)]


def assert_same_calls(ours: Recorder, theirs: Recorder, step: int):
    """The same edits in the same order with the same masks / counts."""
    a, b = nonempty(ours.calls), nonempty(theirs.calls)
    assert [k for k, _ in a] == [k for k, _ in b], f"step {step}: edits {[k for k, _ in a]} vs gsplat {[k for k, _ in b]}"
    for (kind, va), (_, vb) in zip(a, b):
        if isinstance(va, torch.Tensor):
            assert va.shape == vb.shape and bool((va == vb).all()), \
                f"step {step}: {kind} selects {torch.where(va)[0].tolist()[:20]} vs gsplat {torch.where(vb)[0].tolist()[:20]}"
        else:
            assert va == vb, f"step {step}: {kind} {va} vs gsplat {vb}"
    ours.calls.clear()
    theirs.calls.clear()


def assert_same_state(params, optimizers, gp, go, step, *, skip_moment_rows=None):
    for name, p in params.items():
        q = gp[NAMES[name]]
        assert p.shape == q.shape, f"step {step}: {name} {list(p.shape)} vs gsplat {list(q.shape)}"
        torch.testing.assert_close(p.detach(), q.detach(), rtol=RTOL, atol=ATOL, msg=lambda m: f"step {step} {name}: {m}")
        sa, sb = optimizers[name].state[p], go[NAMES[name]].state[q]
        for key in ("exp_avg", "exp_avg_sq"):
            va, vb = sa[key].clone(), sb[key].clone()
            if skip_moment_rows is not None:
                va[skip_moment_rows], vb[skip_moment_rows] = 0, 0
            torch.testing.assert_close(va, vb, rtol=RTOL, atol=ATOL, msg=lambda m: f"step {step} {name} {key}: {m}")


def default_setup(n=240, seed=0):
    """Gaussians of mixed sizes around the clone / split boundary (extent 1, percent_dense
    0.01), some transparent, some too large in the world."""
    params, opts = make_params(n, seed=seed, log_scale=math.log(0.01))
    g = torch.Generator().manual_seed(seed + 7)
    with torch.no_grad():
        params["log_scales"].add_(0.6 * torch.randn(n, 3, generator=g))
        params["opacity_logits"].copy_(3.0 * torch.randn(n, generator=g))   # some below 0.005
        params["log_scales"][:6] = math.log(0.3)                           # > 0.1 x extent
    return params, opts


def random_grads(n, g, *, absgrad=False):
    # pixel gradients whose NDC norm (x W/2 = 32, H/2 = 16) straddles 2e-4 and 8e-4
    grad = torch.randn(n, 2, generator=g) * 1.5e-5
    return grad, (grad.abs() * (1 + 3 * torch.rand(n, 2, generator=g)) if absgrad else None)


def drive_default(strategy: DefaultStrategy, gsplat_kwargs: dict, monkeypatch, gops, *, steps=14, n=240, seed=0):
    """Run ``strategy`` and gsplat's DefaultStrategy side by side over ``steps`` steps;
    assert the same decisions and the same parameters after each. Returns the edits made."""
    from gsplat.strategy import DefaultStrategy as GDefault

    params, opts = default_setup(n, seed)
    gp, go = to_gsplat(params, opts)
    gs = GDefault(**gsplat_kwargs)
    gstate = gs.initialize_state(scene_scale=1.0)
    state = strategy.initialize_state(params)
    ours, theirs = record_both(monkeypatch, gops)
    g = torch.Generator().manual_seed(seed + 11)
    kinds = []
    for step in range(steps):
        n_now = params["means"].shape[0]
        grad, absgrad = random_grads(n_now, g, absgrad=strategy.absgrad)
        visible = torch.rand(n_now, generator=g) > 0.2
        info = fake_info(grad, absgrad_px=absgrad, visible=visible)
        torch.set_rng_state(state.generator.get_state())  # one stream for the split children
        strategy.post_backward(params, opts, state, ctx(step, info, extent=1.0))
        it = step + 1  # deviation 1
        gs.step_post_backward(gp, go, gstate, it, gsplat_info(info, grad, absgrad))
        if it < gs.refine_stop_iter and it % gs.reset_every == 0:  # deviation 3: gsplat's intended reset
            gops.reset_opa(gp, go, gstate, value=gs.prune_opa * 2.0)
            theirs.calls.append(("reset", 0))
        kinds += [k for k, _ in nonempty(ours.calls)]
        assert_same_calls(ours, theirs, step)
        assert_same_state(params, opts, gp, go, step)
        # moments for the next step: an Adam step here, copied to gsplat's side
        adam_step(params, opts, 100 + step)
        same_adam_step(params, opts, gp, go)
    return kinds


def same_adam_step(params, opts, gp, go):
    """gsplat's side gets the Adam step splatbench's side just took: copy the parameters and
    moments over (the optimizer is not under test, the strategies are)."""
    for name, p in params.items():
        q = gp[NAMES[name]]
        with torch.no_grad():
            q.copy_(p.detach())
        go[NAMES[name]].state[q] = {k: v.clone() for k, v in opts[name].state[p].items()}
        q.grad = None


# ---------------------------------------------------------------------------
# DefaultStrategy

SCHEDULE = dict(refine_start=2, refine_stop=13, refine_every=3, reset_every=7)
GSPLAT_SCHEDULE = dict(refine_start_iter=2, refine_stop_iter=13, refine_every=3, reset_every=7)


@pytest.mark.parametrize("options, gsplat_options", [
    ({}, {}),
    ({"absgrad": True, "grad_threshold": 8e-4}, {"absgrad": True, "grow_grad2d": 8e-4}),
    ({"revised_opacity": True}, {"revised_opacity": True}),
], ids=["default", "absgrad", "revised_opacity"])
def test_default_strategy_decides_as_gsplat(options, gsplat_options, monkeypatch, gsplat_cpu):
    strategy = DefaultStrategy(**SCHEDULE, **options)
    kinds = drive_default(strategy, {**GSPLAT_SCHEDULE, **gsplat_options}, monkeypatch, gsplat_cpu)
    # the comparison covered every kind of decision: growth before and after the first
    # reset (size pruning from it = 9 on), opacity pruning and the reset itself
    assert {"clone", "split", "prune", "reset"} <= set(kinds), kinds


def test_revised_opacity_changes_only_split_children():
    """Against the plain rule from the same state: the same rows, children opacity
    1 - sqrt(1 - o) instead of o, nothing else changed (so the gsplat check above would
    see a strategy that ignored the option)."""
    results = []
    for revised in (False, True):
        params, opts = default_setup(60, seed=3)
        with torch.no_grad():  # opacities well above prune_opacity for parents and children alike
            params["opacity_logits"].copy_(0.5 * torch.randn(60, generator=torch.Generator().manual_seed(4)))
        strat = DefaultStrategy(revised_opacity=revised)
        state = strat.initialize_state(params)
        state.grad_accum[:], state.count[:] = 1.0, 1.0  # every Gaussian grows
        strat.refine(params, opts, state, step=0, scene_extent=1.0)
        results.append((params, state.last))
    (plain, s0), (revised, s1) = results
    assert s0 == s1 and s0.split > 0
    first_child = plain["means"].shape[0] - 2 * s0.split
    for name in plain:
        if name != "opacity_logits":
            torch.testing.assert_close(plain[name], revised[name])
    torch.testing.assert_close(plain["opacity_logits"][:first_child], revised["opacity_logits"][:first_child])
    o = torch.sigmoid(plain["opacity_logits"][first_child:].detach())
    torch.testing.assert_close(torch.sigmoid(revised["opacity_logits"][first_child:].detach()), 1 - torch.sqrt(1 - o),
                               rtol=1e-5, atol=1e-6)


@dataclasses.dataclass(frozen=True)
class SwappedCloneSplit(DefaultStrategy):
    """Deliberately wrong: clones the large Gaussians and splits the small ones."""

    def select(self, params, state, scene_extent):
        clone, grow = super().select(params, state, scene_extent)
        return grow, clone


@dataclasses.dataclass(frozen=True)
class StrictSizeBoundary(DefaultStrategy):
    """Deliberately wrong: the size boundary at 2 x percent_dense (graphdeco: percent_dense)."""

    def select(self, params, state, scene_extent):
        avg, _, _ = self.candidates(params, state, scene_extent)
        high = avg >= self.grad_threshold
        small = torch.exp(params["log_scales"].detach()).amax(dim=-1) <= 2 * self.percent_dense * scene_extent
        return high & small, high & ~small


@pytest.mark.parametrize("wrong", [SwappedCloneSplit, StrictSizeBoundary])
def test_a_wrong_clone_split_rule_fails_the_gsplat_check(wrong, monkeypatch, gsplat_cpu):
    with pytest.raises(AssertionError, match="selects|shape|edits"):
        drive_default(wrong(**SCHEDULE), dict(GSPLAT_SCHEDULE), monkeypatch, gsplat_cpu)


def test_threshold_tie_is_graphdecos(gsplat_cpu):
    """Deviation 2: a gradient exactly at the threshold grows here (graphdeco's >=), not in
    gsplat (>). The threshold is set to the NDC norm both compute for the gradient."""
    from gsplat.strategy import DefaultStrategy as GDefault

    params, opts = make_params(4, seed=1, log_scale=math.log(0.005), opacity=0.5)  # small, opaque: clones
    gp, go = to_gsplat(params, opts)
    grad = torch.tensor([[7e-6, 3e-6]] * 4)
    tie = float((grad * torch.tensor([32.0, 16.0])).norm(dim=-1)[0])  # W/2, H/2 of fake_info
    strat = DefaultStrategy(refine_start=0, refine_every=1, grad_threshold=tie)
    strat.post_backward(params, opts, state := strat.initialize_state(params), ctx(0, fake_info(grad)))
    gs = GDefault(refine_start_iter=0, refine_every=1, grow_grad2d=tie)
    gs.step_post_backward(gp, go, gs.initialize_state(1.0), 1, gsplat_info(fake_info(grad), grad, None))
    assert (state.last.cloned, params["means"].shape[0]) == (4, 8)
    assert gp["means"].shape[0] == 4


def test_gsplat_1_5_3_never_resets_opacity(gsplat_cpu):
    """Deviation 3 pinned: gsplat 1.5.3's DefaultStrategy leaves opacities alone at its reset
    steps (issue #797). If a newer gsplat resets, this fails: drop the harness's reset."""
    from gsplat.strategy import DefaultStrategy as GDefault

    params, opts = default_setup(8, seed=2)
    gp, go = to_gsplat(params, opts)
    gs = GDefault(refine_start_iter=100, reset_every=5)
    before = gp["opacities"].detach().clone()
    assert float(torch.sigmoid(before).max()) > 0.5
    grad = torch.zeros(8, 2)
    gs.step_post_backward(gp, go, gs.initialize_state(1.0), 5, gsplat_info(fake_info(grad), grad, None))
    torch.testing.assert_close(gp["opacities"].detach(), before)
    # splatbench resets at the same iteration (ctx.step 4 = the 5th iteration)
    strat = DefaultStrategy(refine_start=100, reset_every=5)
    strat.post_backward(params, opts, strat.initialize_state(params), ctx(4, fake_info(grad)))
    assert float(torch.sigmoid(params["opacity_logits"].detach()).max()) <= 0.01 + 1e-6


# ---------------------------------------------------------------------------
# MCMCStrategy

def test_mcmc_strategy_decides_as_gsplat(monkeypatch, gsplat_cpu):
    from gsplat.strategy import MCMCStrategy as GMCMC

    n = 150
    params, opts = make_params(n, seed=5, log_scale=math.log(0.05))
    g = torch.Generator().manual_seed(9)
    with torch.no_grad():
        params["opacity_logits"].copy_(2.5 * torch.randn(n, generator=g) - 2.0)  # many dead (<= 0.005)
    gp, go = to_gsplat(params, opts)
    strat = MCMCStrategy(refine_start=1, refine_stop=9, refine_every=2, cap_max=170, min_opacity=0.005, noise_lr=5e5)
    gs = GMCMC(cap_max=170, noise_lr=5e5, refine_start_iter=1, refine_stop_iter=9, refine_every=2, min_opacity=0.005)
    state, gstate = strat.initialize_state(params), gs.initialize_state()
    ours, theirs = record_both(monkeypatch, gsplat_cpu)
    kinds, lr, zeroed_rows = [], 1.6e-4, 0
    for step in range(10):
        dead = torch.sigmoid(params["opacity_logits"].detach()) <= 0.005
        torch.set_rng_state(state.generator.get_state())  # one stream: sampling, then the noise
        strat.post_backward(params, opts, state, ctx(step, None, means_lr=lr))
        gs.step_post_backward(gp, go, gstate, step + 1, {}, lr=lr)  # deviation 1
        refined = state.last is not None and state.last.step == step
        # deviation 5: where the moments differ, splatbench's are zero on purpose (the
        # relocated rows, the sampled sources), and only at a refinement
        zeroed = torch.zeros(params["means"].shape[0], dtype=torch.bool)
        for name, p in params.items():
            q = gp[NAMES[name]]
            if p.shape != q.shape:
                break  # reported by assert_same_state below
            for key in ("exp_avg", "exp_avg_sq"):
                m, mg = opts[name].state[p][key], go[NAMES[name]].state[q][key]
                differs = ~(m == mg).reshape(m.shape[0], -1).all(dim=-1)
                assert bool((m[differs] == 0).all()), f"step {step}: {name} {key} differs where splatbench's is not 0"
                zeroed |= differs
        assert refined or not bool(zeroed.any()), f"step {step}: moments differ without a refinement"
        if refined and state.last.relocated:
            assert bool(zeroed[: dead.shape[0]][dead].all()), f"step {step}: a relocated row kept its moments"
        zeroed_rows += int(zeroed.sum())
        kinds += [k for k, _ in nonempty(ours.calls)]
        assert_same_calls(ours, theirs, step)
        assert_same_state(params, opts, gp, go, step, skip_moment_rows=zeroed)
        assert state.last_noise is not None and float(state.last_noise.abs().max()) > 0
        adam_step(params, opts, 200 + step)
        same_adam_step(params, opts, gp, go)
    assert {"relocate", "add"} <= set(kinds), kinds
    assert zeroed_rows > 0
    assert params["means"].shape[0] == 170  # the cap reached, as in gsplat


def test_relocation_formula_is_the_kernels():
    """ops.compute_relocation (float64) against the CUDA kernel's transcription (float32)."""
    g = torch.Generator().manual_seed(0)
    o = torch.rand(200, generator=g) * 0.98 + 0.01
    s = torch.rand(200, 3, generator=g) + 0.1
    r = torch.randint(1, 8, (200,), generator=g)
    binoms = torch.tensor([[math.comb(n, k) if k <= n else 0 for k in range(51)] for n in range(51)],
                          dtype=torch.float32)
    no, ns = ops.compute_relocation(o, s, r)
    ko, ks = _relocation_kernel(o, s, r, binoms)
    # up to r(r+1)/2 = 28 float32 terms of alternating sign in the kernel's sum
    torch.testing.assert_close(no, ko, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(ns, ks, rtol=1e-4, atol=1e-6)


def test_mcmc_sampler_has_gsplats_distribution():
    """Deviation 4: splatbench's inverse-CDF sampler and torch.multinomial (gsplat's) draw
    from the same distribution: a chi-square test of each against the opacities, and of
    the two against each other, at 99.9 % (so a correct sampler fails once in 1000 seeds;
    the seeds are fixed)."""
    from scipy.stats import chi2_contingency, chisquare

    w = torch.tensor([0.9, 0.5, 0.05, 0.3, 0.0, 0.7, 0.2, 0.01])
    n = 40_000
    torch.manual_seed(1)
    ours = torch.bincount(ops.sample_categorical(w, n, torch.Generator().manual_seed(2)), minlength=8)
    theirs = torch.bincount(torch.multinomial(w, n, replacement=True), minlength=8)
    assert int(ours[4]) == 0 and int(theirs[4]) == 0  # zero weight never drawn
    keep = w > 0
    expected = (w[keep].double() / w[keep].double().sum() * n).numpy()
    assert chisquare(ours[keep].numpy(), expected).pvalue > 1e-3
    assert chisquare(theirs[keep].numpy(), expected).pvalue > 1e-3
    assert chi2_contingency([ours[keep].numpy(), theirs[keep].numpy()]).pvalue > 1e-3
