"""Densification strategies: bookkeeping of parameters and Adam moments, the counts the
thresholds select, the split's children, MCMC relocation, noise, determinism, registry."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest
import torch

from splatbench.errors import InputError
from splatbench.raster.torch_bridge import RasterInfo
from splatbench.strategies import (PARAM_GROUPS, DefaultStrategy, MCMCStrategy, StepContext, make_strategy,
                                   ops, refines_at, strategy_fields)

K = 4  # SH bases (degree 1)


# ---------------------------------------------------------------------------
# Fixtures and helpers

def make_params(n: int, seed: int = 0, *, log_scale: float = -3.0, opacity: float = 0.5):
    """Random Gaussians as leaf parameters, one Adam each, after one optimizer step
    (so every group has exp_avg / exp_avg_sq / step)."""
    g = torch.Generator().manual_seed(seed)
    logit = math.log(opacity / (1 - opacity))
    raw = {
        "means": torch.randn(n, 3, generator=g),
        "log_scales": log_scale + 0.1 * torch.randn(n, 3, generator=g),
        "quats": torch.randn(n, 4, generator=g),
        "opacity_logits": logit + 0.1 * torch.randn(n, generator=g),
        "sh_dc": torch.randn(n, 1, 3, generator=g),
        "sh_rest": torch.randn(n, K - 1, 3, generator=g),
    }
    params = {k: torch.nn.Parameter(v) for k, v in raw.items()}
    optimizers = {k: torch.optim.Adam([p], lr=1e-3, eps=1e-15) for k, p in params.items()}
    adam_step(params, optimizers, seed)
    return params, optimizers


def adam_step(params, optimizers, seed: int = 0):
    g = torch.Generator().manual_seed(seed + 1000)
    loss = sum((p * torch.randn(p.shape, generator=g)).sum() for p in params.values())
    loss.backward()
    for opt in optimizers.values():
        opt.step()
        opt.zero_grad(set_to_none=True)


def assert_consistent(params, optimizers, n: int | None = None):
    """Every group: a leaf with N rows; its optimizer holds exactly this tensor, with
    moments of the parameter's shape."""
    n = params["means"].shape[0] if n is None else n
    assert set(params) == set(PARAM_GROUPS)
    for name, p in params.items():
        assert p.is_leaf and p.requires_grad and p.shape[0] == n, (name, p.shape)
        opt = optimizers[name]
        assert len(opt.param_groups) == 1 and len(opt.param_groups[0]["params"]) == 1
        assert opt.param_groups[0]["params"][0] is p, name
        assert list(opt.state.keys()) == [p], name
        st = opt.state[p]
        assert st["exp_avg"].shape == p.shape and st["exp_avg_sq"].shape == p.shape, name
        assert st["step"].numel() == 1


def moments(optimizers, name):
    st = next(iter(optimizers[name].state.values()))
    return st["exp_avg"], st["exp_avg_sq"]


def snapshot(params):
    return {k: v.detach().clone() for k, v in params.items()}


@dataclass
class FakeInfo(RasterInfo):
    """A `RasterInfo` with the screen-space gradients given directly (pixels)."""

    grad: torch.Tensor | None = None
    absgrad: torch.Tensor | None = None

    @property
    def means2d_grad(self):
        return self.grad

    @property
    def means2d_absgrad(self):
        return self.absgrad


def fake_info(grad_px, *, absgrad_px=None, visible=None, radii=None, width=64, height=32, n=None):
    n = grad_px.shape[0] if n is None else n
    visible = torch.ones(n, dtype=torch.bool) if visible is None else visible
    radii = torch.where(visible, 3, 0).int() if radii is None else radii
    return FakeInfo(radii=radii, visible=visible, width=width, height=height, num_pairs=0, sh_degree=1,
                    grad=grad_px, absgrad=absgrad_px)


def ctx(step, info=None, *, extent=1.0, means_lr=1.6e-4, loss=0.1):
    return StepContext(step=step, info=info, scene_extent=extent, means_lr=means_lr, loss=loss)


# ---------------------------------------------------------------------------
# ops

def test_duplicate_appends_copies_with_zero_moments():
    params, opts = make_params(10)
    before = snapshot(params)
    m_before = {k: moments(opts, k)[0].clone() for k in params}
    mask = torch.zeros(10, dtype=torch.bool)
    mask[[1, 4, 7]] = True
    buf = {"acc": torch.arange(10.0)}
    assert ops.duplicate(params, opts, mask, buffers=buf) == 3
    assert_consistent(params, opts, 13)
    for k in params:
        torch.testing.assert_close(params[k].detach()[:10], before[k])
        torch.testing.assert_close(params[k].detach()[10:], before[k][[1, 4, 7]])
        m, v = moments(opts, k)
        torch.testing.assert_close(m[:10], m_before[k])
        assert (m[10:] == 0).all() and (v[10:] == 0).all()
    torch.testing.assert_close(buf["acc"], torch.tensor([*range(10), 1, 4, 7], dtype=torch.float32))
    adam_step(params, opts)  # the optimizer still works on the new tensors
    assert_consistent(params, opts, 13)


def test_remove_drops_rows_and_moments():
    params, opts = make_params(10)
    before = snapshot(params)
    m_before = {k: moments(opts, k)[1].clone() for k in params}
    mask = torch.zeros(10, dtype=torch.bool)
    mask[[0, 5, 9]] = True
    keep = [i for i in range(10) if not mask[i]]
    assert ops.remove(params, opts, mask) == 3
    assert_consistent(params, opts, 7)
    for k in params:
        torch.testing.assert_close(params[k].detach(), before[k][keep])
        torch.testing.assert_close(moments(opts, k)[1], m_before[k][keep])
    adam_step(params, opts)
    assert_consistent(params, opts, 7)


def test_split_children_scale_and_placement():
    params, opts = make_params(8)
    before = snapshot(params)
    mask = torch.zeros(8, dtype=torch.bool)
    mask[[2, 3, 6]] = True
    rest = [i for i in range(8) if not mask[i]]
    gen = torch.Generator().manual_seed(0)
    assert ops.split(params, opts, mask, n=2, generator=gen) == 3
    assert_consistent(params, opts, 5 + 6)
    # the others keep their order, the children ([2, M] child-major) follow
    for k in params:
        torch.testing.assert_close(params[k].detach()[:5], before[k][rest])
    parents = torch.tensor([2, 3, 6, 2, 3, 6])
    torch.testing.assert_close(params["log_scales"].detach()[5:], before["log_scales"][parents] - math.log(1.6))
    for k in ("quats", "opacity_logits", "sh_dc", "sh_rest"):
        torch.testing.assert_close(params[k].detach()[5:], before[k][parents])
    for k in params:
        m, v = moments(opts, k)
        assert (m[5:] == 0).all() and (v[5:] == 0).all()
    # each child lies within a few parent standard deviations of its parent
    offsets = params["means"].detach()[5:] - before["means"][parents]
    rot = ops.quat_to_rotmat(before["quats"][parents])
    local = torch.einsum("mji,mj->mi", rot, offsets) / torch.exp(before["log_scales"][parents])
    assert (local.abs() < 6).all() and (offsets.abs() > 0).all()


def test_split_children_follow_the_parent_gaussian():
    """Many children of one anisotropic, rotated parent: their mean is the parent's mean
    and their covariance the parent's covariance R diag(s^2) R^T."""
    params, opts = make_params(1)
    with torch.no_grad():
        params["log_scales"].copy_(torch.log(torch.tensor([[0.5, 0.2, 0.05]])))
        params["quats"].copy_(torch.tensor([[0.9, 0.3, -0.2, 0.4]]))
    before = snapshot(params)
    n = 20_000
    ops.split(params, opts, torch.ones(1, dtype=torch.bool), n=n, generator=torch.Generator().manual_seed(1))
    assert_consistent(params, opts, n)
    x = params["means"].detach().double()
    torch.testing.assert_close(x.mean(0), before["means"][0].double(), atol=0.02, rtol=0)
    cov = torch.cov(x.T)
    want = ops.covariances(before["log_scales"], before["quats"])[0].double()
    torch.testing.assert_close(cov, want, atol=0.01, rtol=0.05)
    torch.testing.assert_close(params["log_scales"].detach()[0], before["log_scales"][0] - math.log(0.8 * n))


def test_reset_opacity_clamps_and_zeroes_moments():
    params, opts = make_params(50, opacity=0.3)
    with torch.no_grad():
        params["opacity_logits"][:5] = -8.0  # already below 0.01: unchanged
    before = snapshot(params)
    step_before = next(iter(opts["opacity_logits"].state.values()))["step"].clone()
    means_m = moments(opts, "means")[0].clone()
    ops.reset_opacity(params, opts, 0.01)
    assert_consistent(params, opts, 50)
    o = torch.sigmoid(params["opacity_logits"].detach())
    assert (o <= 0.01 + 1e-6).all()
    torch.testing.assert_close(params["opacity_logits"].detach()[:5], before["opacity_logits"][:5])
    m, v = moments(opts, "opacity_logits")
    assert (m == 0).all() and (v == 0).all()
    assert next(iter(opts["opacity_logits"].state.values()))["step"] == step_before
    torch.testing.assert_close(moments(opts, "means")[0], means_m)  # other groups untouched
    for k in PARAM_GROUPS[:3]:
        torch.testing.assert_close(params[k].detach(), before[k])


def test_ops_on_groups_without_state_or_optimizer():
    """A frozen group (no optimizer) and an optimizer that has not stepped yet."""
    params, opts = make_params(6)
    params["sh_rest"] = torch.nn.Parameter(torch.zeros(6, 0, 3), requires_grad=False)  # degree 0, frozen
    del opts["sh_rest"]
    opts["sh_dc"] = torch.optim.Adam([params["sh_dc"]], lr=1e-3)  # no state yet
    ops.duplicate(params, opts, torch.tensor([1, 0, 0, 0, 0, 1], dtype=torch.bool))
    assert params["sh_rest"].shape == (8, 0, 3) and not params["sh_rest"].requires_grad
    assert opts["sh_dc"].param_groups[0]["params"][0] is params["sh_dc"] and not opts["sh_dc"].state
    ops.remove(params, opts, torch.tensor([1] + [0] * 7, dtype=torch.bool))
    assert all(p.shape[0] == 7 for p in params.values())


def test_ops_reject_bad_masks_and_foreign_optimizers():
    params, opts = make_params(5)
    with pytest.raises(InputError, match=r"bool mask of shape \[5\]"):
        ops.remove(params, opts, torch.zeros(4, dtype=torch.bool))
    opts["means"] = torch.optim.Adam([torch.nn.Parameter(torch.zeros(5, 3))])
    with pytest.raises(InputError, match="does not hold"):
        ops.remove(params, opts, torch.ones(5, dtype=torch.bool))


# ---------------------------------------------------------------------------
# default / absgrad

def grow_setup(n=20, extent=2.0):
    """Gaussians 0..9 small (max scale 0.005 x extent), 10..19 large (0.05 x extent);
    high gradient for {0, 1, 2} (small) and {10, 11, 12, 13} (large)."""
    params, opts = make_params(n, opacity=0.5)
    with torch.no_grad():
        params["log_scales"][:10] = math.log(0.005 * extent)
        params["log_scales"][10:] = math.log(0.05 * extent)
        params["log_scales"][:, 1:] -= 1.0  # anisotropic; the max is component 0
    strat = DefaultStrategy(grad_threshold=2e-4, max_screen_size=20.0)  # graphdeco's 20 px, switched on
    state = strat.initialize_state(params)
    high = [0, 1, 2, 10, 11, 12, 13]
    state.count[:] = 4
    state.grad_accum[:] = 4 * 1e-4
    state.grad_accum[high] = 4 * 2e-4  # exactly at the threshold (>=)
    return params, opts, strat, state, extent


def test_default_refine_clone_and_split_counts():
    params, opts, strat, state, extent = grow_setup()
    before = snapshot(params)
    stats = strat.refine(params, opts, state, step=599, scene_extent=extent)
    assert (stats.cloned, stats.split, stats.pruned) == (3, 4, 0)
    assert params["means"].shape[0] == 20 + 3 + 4 == stats.num_gaussians
    assert_consistent(params, opts)
    # survivors: 0..9, 14..19 in order, then the 3 clones, then the 8 children
    rest = [i for i in range(20) if i not in (10, 11, 12, 13)]
    torch.testing.assert_close(params["means"].detach()[:16], before["means"][rest])
    torch.testing.assert_close(params["means"].detach()[16:19], before["means"][[0, 1, 2]])
    torch.testing.assert_close(params["log_scales"].detach()[19:],
                               before["log_scales"][[10, 11, 12, 13] * 2] - math.log(1.6))
    assert state.count.shape == (27,) and (state.count == 0).all() and (state.grad_accum == 0).all()


def test_default_prune_counts():
    params, opts, strat, state, extent = grow_setup()
    with torch.no_grad():
        params["opacity_logits"][[5, 6]] = -6.0      # transparent (< 0.005)
        params["log_scales"][17] = math.log(0.2 * extent)  # too large in the world (> 0.1 x extent)
    state.max_radii[:] = 5
    state.max_radii[[8, 12]] = 25  # too large on screen; 12 is split instead, its children kept
    # before the first opacity reset only opacity prunes (on a copy)
    p2 = {k: torch.nn.Parameter(v.detach().clone()) for k, v in params.items()}
    o2 = {k: torch.optim.Adam([p], lr=1e-3) for k, p in p2.items()}
    s2 = strat.initialize_state(p2)
    s2.count[:], s2.grad_accum[:], s2.max_radii[:] = state.count, state.grad_accum, state.max_radii
    early = strat.refine(p2, o2, s2, step=1000, scene_extent=extent)
    assert (early.cloned, early.split, early.pruned) == (3, 4, 2)
    # after it: also screen size (8) and world size (17)
    late = strat.refine(params, opts, state, step=3100, scene_extent=extent)
    assert (late.cloned, late.split, late.pruned) == (3, 4, 4)
    assert params["means"].shape[0] == 20 + 3 + 4 - 4
    assert_consistent(params, opts)
    # screen-size pruning can be switched off
    p3 = {k: torch.nn.Parameter(v.detach().clone()) for k, v in grow_setup()[0].items()}
    o3 = {k: torch.optim.Adam([p]) for k, p in p3.items()}
    off = DefaultStrategy(max_screen_size=0, max_world_size=0)
    s3 = off.initialize_state(p3)
    s3.max_radii[:] = 1000
    assert off.refine(p3, o3, s3, step=5000, scene_extent=extent).pruned == 0


def test_a_sparse_start_is_emptied_by_the_world_size_prune_and_the_run_says_why():
    """Issue 29: why the default strategy empties a sparse model. On `far` (a forward-facing rig,
    scene extent 1.38 from the camera spread, backdrop 150 units away), SfM's 27 points have 3-NN
    scales of about 0.5 (median 0.595 at step 100, 0.501 at step 200 after two splits), all above
    0.1 x 1.38: the first refinement after the first opacity reset (graphdeco's and gsplat's rule;
    step 200 of a scaled 2000-step run) removes every one. The same set-up here: 30 Gaussians of
    scale 0.5, extent 1.38, opaque (0.5 >> the 0.005 opacity threshold), no gradient (nothing grows)."""
    extent = 1.38
    params, opts = make_params(30, opacity=0.5, log_scale=math.log(0.5))
    strat = DefaultStrategy(reset_every=200, refine_start=33, refine_stop=1000)  # graphdeco's, scaled to 2000
    state = strat.initialize_state(params)
    before_reset = strat.refine(params, opts, state, step=99, scene_extent=extent)
    assert before_reset.pruned == 0 and strat.outcome_note(state) is None  # no size prune before the reset
    after = strat.refine(params, opts, state, step=299, scene_extent=extent)
    assert (after.pruned, after.pruned_size, after.num_gaussians) == (30, 30, 0)
    note = strat.outcome_note(state)
    assert note.startswith("warning: strategy 'default': the size prune removed 30 of 30 Gaussians at step 300")
    assert "scene extent 1.38" in note and "max_world_size=0" in note
    # the rule is the cause: without it the same Gaussians stay
    keep = DefaultStrategy(reset_every=200, refine_start=33, refine_stop=1000, max_world_size=0)
    p2, o2 = make_params(30, opacity=0.5, log_scale=math.log(0.5))
    s2 = keep.initialize_state(p2)
    assert keep.refine(p2, o2, s2, step=299, scene_extent=extent).pruned == 0 and keep.outcome_note(s2) is None


def test_default_strategy_has_screen_size_pruning_off_as_graphdeco_and_gsplat_do():
    """graphdeco clears max_radii2D while densifying, before its 20-px test reads it, and
    gsplat's default refine_scale2d_stop is 0: neither prunes by screen size. The same
    set-up as above with the default strategy prunes only by opacity (5, 6) and world
    size (17), not the Gaussian 25 px wide on screen (8)."""
    assert DefaultStrategy().max_screen_size == 0
    params, opts, _, state, extent = grow_setup()
    with torch.no_grad():
        params["opacity_logits"][[5, 6]] = -6.0
        params["log_scales"][17] = math.log(0.2 * extent)
    default = DefaultStrategy(grad_threshold=2e-4)
    s = default.initialize_state(params)
    s.count[:], s.grad_accum[:], s.max_radii[:] = state.count, state.grad_accum, 5
    s.max_radii[[8, 12]] = 25
    kept = params["means"].detach()[8].clone()
    stats = default.refine(params, opts, s, step=3100, scene_extent=extent)
    assert (stats.cloned, stats.split, stats.pruned) == (3, 4, 3)
    assert (params["means"].detach() == kept).all(dim=1).any()  # Gaussian 8 survived


def test_default_accumulates_ndc_gradient_of_visible_views():
    params, opts = make_params(4)
    strat = DefaultStrategy(refine_start=0, refine_every=1000)
    state = strat.initialize_state(params)
    W, H = 64, 32
    grad = torch.tensor([[1e-5, 0.0], [0.0, 1e-5], [3e-6, 4e-6], [1.0, 1.0]])
    visible = torch.tensor([True, True, True, False])
    strat.post_backward(params, opts, state, ctx(10, fake_info(grad, visible=visible, width=W, height=H)))
    strat.post_backward(params, opts, state, ctx(11, fake_info(2 * grad, visible=visible, width=W, height=H)))
    want = torch.tensor([1e-5 * W / 2, 1e-5 * H / 2, math.hypot(3e-6 * W / 2, 4e-6 * H / 2), 0.0]) * 3
    torch.testing.assert_close(state.grad_accum, want)
    torch.testing.assert_close(state.count, torch.tensor([2.0, 2.0, 2.0, 0.0]))
    torch.testing.assert_close(state.max_radii, torch.tensor([3.0, 3.0, 3.0, 0.0]))


def test_absgrad_uses_the_absolute_gradient_and_its_threshold():
    strat = make_strategy("absgrad")
    assert strat.name == "absgrad" and strat.absgrad and strat.grad_threshold == 8e-4
    assert make_strategy("default").absgrad is False and make_strategy("mcmc").absgrad is False
    params, opts = make_params(3)
    state = strat.initialize_state(params)
    grad, absgrad = torch.zeros(3, 2), torch.tensor([[1e-4, 0.0], [0.0, 0.0], [0.0, 2e-4]])
    strat.post_backward(params, opts, state, ctx(0, fake_info(grad, absgrad_px=absgrad, width=100, height=50)))
    torch.testing.assert_close(state.grad_accum, torch.tensor([5e-3, 0.0, 5e-3]))
    with pytest.raises(InputError, match="absgrad=True"):
        strat.post_backward(params, opts, state, ctx(1, fake_info(grad)))
    with pytest.raises(InputError, match="means2d_grad is None"):
        make_strategy("default").post_backward(params, opts, state, ctx(1, fake_info(None, n=3)))


def test_default_schedule():
    """Refine at it = step + 1 in (refine_start, refine_stop) with it % refine_every == 0,
    opacity reset at it % reset_every == 0, nothing from refine_stop on."""
    params, opts = make_params(30, opacity=0.5)
    strat = DefaultStrategy(refine_start=4, refine_stop=20, refine_every=4, reset_every=12, grad_threshold=1e9)
    state = strat.initialize_state(params)
    resets = []
    for step in range(30):
        o_before = torch.sigmoid(params["opacity_logits"].detach()).max().item()
        n = params["means"].shape[0]
        strat.post_backward(params, opts, state, ctx(step, fake_info(torch.zeros(n, 2))))
        if torch.sigmoid(params["opacity_logits"].detach()).max().item() < o_before - 1e-3:
            resets.append(step)
            with torch.no_grad():
                params["opacity_logits"].add_(5.0)
    assert [s.step for s in state.history] == [7, 11, 15]
    assert resets == [11]
    # what the config's final-10 % check reads: the last event of the run, and of a shorter one
    assert strat.last_topology_change(30).step == max(resets + [s.step for s in state.history]) == 15
    assert strat.last_topology_change(12).step == 11 and strat.last_topology_change(7) is None


def test_refines_at_is_the_schedule_the_strategy_runs_and_plans():
    """`refines_at` (shared by post_backward and the reports' count of runs that refined at their last
    step) marks exactly the steps the strategy refined at, and as many as `planned_counts` counts."""
    strat = DefaultStrategy(refine_start=4, refine_stop=20, refine_every=4, reset_every=0, grad_threshold=1e9)
    params, opts = make_params(30, opacity=0.5)
    state = strat.initialize_state(params)
    for step in range(30):
        strat.post_backward(params, opts, state, ctx(step, fake_info(torch.zeros(params["means"].shape[0], 2))))
    marked = [it for it in range(1, 31) if refines_at(it, 4, 20, 4)]
    assert marked == [s.step + 1 for s in state.history] == [8, 12, 16]  # not 4 (= start) nor 20 (= stop)
    assert len(marked) == strat.planned_counts(30).refinements
    assert not refines_at(8, 4, 20, 0)  # no period: never (a record with refine_every = 0)


def test_default_early_stop_on_loss_plateau():
    params, opts = make_params(10)
    strat = make_strategy("default", refine_start=0, refine_every=5, early_stop=True, early_stop_rel_tol=0.01,
                          early_stop_patience=2, grad_threshold=1e9)
    state = strat.initialize_state(params)
    for step in range(100):
        loss = 1.0 / (1 + step) if step < 30 else 1.0 / 31  # falls, then flat
        strat.post_backward(params, opts, state, ctx(step, fake_info(torch.zeros(10, 2)), loss=loss))
    assert state.stopped and state.plateau.stopped_at == 44
    # intervals ending at 34 (first flat one, still 9 % lower) and 39 (1st miss) refine; 44 (2nd miss) stops
    assert [s.step for s in state.history] == [4, 9, 14, 19, 24, 29, 34, 39]
    # off by default: it never stops
    plain = make_strategy("default", refine_start=0, refine_every=5, grad_threshold=1e9)
    s2 = plain.initialize_state(params)
    for step in range(100):
        plain.post_backward(params, opts, s2, ctx(step, fake_info(torch.zeros(10, 2)), loss=0.5))
    assert not s2.stopped and len(s2.history) == 20  # it = 5, 10, ..., 100


# ---------------------------------------------------------------------------
# MCMC

def naive_relocation(o: float, s: float, n: int) -> tuple[float, float]:
    """The paper's formula, summed literally (float64)."""
    new_o = 1 - (1 - o) ** (1 / n)
    denom = sum(math.comb(i - 1, k) * (-1) ** k / math.sqrt(k + 1) * new_o ** (k + 1)
                for i in range(1, n + 1) for k in range(i))
    return new_o, o / denom * s


def test_compute_relocation_matches_the_formula():
    g = torch.Generator().manual_seed(0)
    o = torch.rand(40, generator=g, dtype=torch.float64) * 0.98 + 0.01
    s = torch.rand(40, 3, generator=g, dtype=torch.float64) + 0.1
    r = torch.randint(1, 30, (40,), generator=g)
    new_o, new_s = ops.compute_relocation(o, s, r)
    for i in range(40):
        want_o, want_s = naive_relocation(o[i].item(), s[i, 0].item(), int(r[i]))
        assert new_o[i].item() == pytest.approx(want_o, rel=1e-9)
        assert new_s[i, 0].item() == pytest.approx(want_s, rel=1e-6)
    # r copies of opacity new_o composite to the original opacity; r = 1 is the identity
    torch.testing.assert_close(1 - (1 - new_o) ** r, o)
    one_o, one_s = ops.compute_relocation(o, s, torch.ones(40, dtype=torch.long))
    torch.testing.assert_close(one_o, o)
    torch.testing.assert_close(one_s, s)


def test_relocate_keeps_count_and_revives_the_dead():
    params, opts = make_params(40, opacity=0.5)
    dead = torch.zeros(40, dtype=torch.bool)
    dead[[3, 7, 8, 20, 33]] = True
    with torch.no_grad():
        params["opacity_logits"][dead] = -10.0
    before = snapshot(params)
    gen = torch.Generator().manual_seed(0)
    assert ops.relocate(params, opts, dead, min_opacity=0.005, generator=gen) == 5
    assert_consistent(params, opts, 40)
    after = snapshot(params)
    assert (torch.sigmoid(after["opacity_logits"]) > 0.005).all()
    # each relocated row is a copy of a live row (the source, with its corrected opacity and scale)
    for d in torch.where(dead)[0]:
        src = [i for i in torch.where(~dead)[0] if torch.equal(after["means"][i], after["means"][d])]
        assert src, f"row {int(d)} is no copy of a live Gaussian"
        for k in PARAM_GROUPS:
            torch.testing.assert_close(after[k][d], after[k][src[0]])
        for k in PARAM_GROUPS:
            m, v = moments(opts, k)
            assert (m[d] == 0).all() and (m[src[0]] == 0).all()
    # untouched rows are unchanged, sources lost opacity (shared with their copies)
    changed = (after["opacity_logits"] != before["opacity_logits"]) & ~dead
    assert changed.any() and (after["opacity_logits"][changed] < before["opacity_logits"][changed]).all()
    untouched = ~changed & ~dead
    torch.testing.assert_close(after["means"][untouched], before["means"][untouched])


def test_mcmc_refine_adds_five_percent_up_to_the_cap():
    params, opts = make_params(100)
    strat = MCMCStrategy(cap_max=1000)
    state = strat.initialize_state(params)
    assert strat.refine(params, opts, state, 600).added == 5
    assert params["means"].shape[0] == 105
    assert_consistent(params, opts, 105)
    capped = MCMCStrategy(cap_max=107)
    assert capped.refine(params, opts, state, 700).added == 2
    assert capped.refine(params, opts, state, 800).added == 0
    assert params["means"].shape[0] == 107
    m, v = moments(opts, "sh_dc")
    assert (m[100:] == 0).all() and (v[100:] == 0).all()
    adam_step(params, opts)
    assert_consistent(params, opts, 107)


def test_mcmc_relocates_then_adds_on_schedule():
    params, opts = make_params(60)
    with torch.no_grad():
        params["opacity_logits"][:6] = -9.0
    strat = make_strategy("mcmc", refine_start=2, refine_every=3, refine_stop=10, cap_max=64)
    state = strat.initialize_state(params)
    for step in range(12):
        strat.post_backward(params, opts, state, ctx(step))
    assert [(s.step, s.relocated, s.added) for s in state.history] == [(2, 6, 3), (5, 0, 1), (8, 0, 0)]
    assert strat.last_topology_change(12).step == state.history[-1].step
    assert params["means"].shape[0] == 64
    assert_consistent(params, opts, 64)


def test_mcmc_early_stop_keeps_the_noise():
    params, opts = make_params(50)
    strat = make_strategy("mcmc", refine_start=0, refine_every=5, early_stop=True, early_stop_patience=1,
                          cap_max=10_000)
    state = strat.initialize_state(params)
    for step in range(30):
        strat.post_backward(params, opts, state, ctx(step, loss=1.0 if step < 5 else 0.5))
    # intervals ending at 4 (the first), 9 (50 % lower) refine; 14 (flat) stops
    assert [s.step for s in state.history] == [4, 9] and state.stopped and state.plateau.stopped_at == 14
    assert (state.last_noise != 0).any()


def test_mcmc_noise_is_zero_for_opaque_gaussians():
    params, opts = make_params(20, opacity=0.5)
    with torch.no_grad():
        params["opacity_logits"][:10] = 10.0   # opaque
        params["opacity_logits"][10:] = -7.0   # nearly transparent (0.0009)
        params["log_scales"][:] = math.log(0.1)
    before = params["means"].detach().clone()
    strat = MCMCStrategy(refine_start=10**9)
    state = strat.initialize_state(params)
    strat.post_backward(params, opts, state, ctx(0, means_lr=1e-3))
    delta = params["means"].detach() - before
    torch.testing.assert_close(delta, state.last_noise)
    assert delta[:10].abs().max() < 1e-30
    # transparent: ~ 0.01 (= s^2) x means_lr x noise_lr x N(0, 1) = 5 x N(0, 1)
    assert 0.5 < delta[10:].std() < 20
    # the noise scales with the means' learning rate
    strat.post_backward(params, opts, state, ctx(1, means_lr=0.0))
    assert (state.last_noise == 0).all()


def test_mcmc_regularization():
    params, _ = make_params(30)
    reg = MCMCStrategy(opacity_reg=0.01, scale_reg=0.02).regularization(params, 0)
    want = 0.01 * torch.sigmoid(params["opacity_logits"]).mean() + 0.02 * torch.exp(params["log_scales"]).mean()
    torch.testing.assert_close(reg, want)
    reg.backward()
    assert params["opacity_logits"].grad is not None and params["log_scales"].grad is not None
    assert make_strategy("default").regularization(params, 0) == 0.0
    assert make_strategy("none").regularization(params, 0) == 0.0


# ---------------------------------------------------------------------------
# Determinism, none, registry

def run_strategy(name: str, seed: int, **fields):
    params, opts = make_params(40, seed=5)
    strat = make_strategy(name, seed=seed, refine_start=0, refine_every=3, **fields)
    state = strat.initialize_state(params)
    g = torch.Generator().manual_seed(9)
    for step in range(10):
        n = params["means"].shape[0]
        info = fake_info(torch.randn(n, 2, generator=g) * 1e-5, absgrad_px=torch.rand(n, 2, generator=g) * 4e-5)
        strat.post_backward(params, opts, state, ctx(step, info, extent=5.0))
        adam_step(params, opts, step)
    return snapshot(params)


@pytest.mark.parametrize("name", ["default", "absgrad", "mcmc", "budget"])
def test_same_seed_same_tensors(name):
    # budget: a refine window of 3 refinements, so that each has a share of the budget to grow by
    extra = {"refine_stop": 10} if name == "budget" else {}
    a, b, c = run_strategy(name, 1, **extra), run_strategy(name, 1, **extra), run_strategy(name, 2, **extra)
    assert a["means"].shape[0] > 40  # something was added
    for k in PARAM_GROUPS:
        assert torch.equal(a[k], b[k]), k
    assert a["means"].shape != c["means"].shape or not torch.equal(a["means"], c["means"])


def test_none_is_a_no_op():
    params, opts = make_params(10)
    before = snapshot(params)
    strat = make_strategy("none")
    state = strat.initialize_state(params)
    for step in range(5):
        strat.pre_backward(params, opts, state, ctx(step))
        strat.post_backward(params, opts, state, ctx(step))
    for k in PARAM_GROUPS:
        assert torch.equal(params[k].detach(), before[k])
    assert strat.name == "none" and strategy_fields("none") == ()


@pytest.mark.parametrize("name, overrides, match", [
    ("nope", {}, "unknown name 'nope'"),
    ("default", {"grad_thresh": 1e-4}, r"strategy\.grad_thresh: unknown key \(did you mean 'grad_threshold'"),
    ("mcmc", {"absgrad": True}, r"strategy\.absgrad: unknown key \(known: "),
    ("none", {"seed": 1}, r"strategy\.seed: unknown key \(known: none\)"),
    ("default", {"refine_every": 0}, "refine_every"),
    ("mcmc", {"cap_max": "many"}, "cap_max"),
    ("default", {"grad_threshold": -1.0}, "grad_threshold"),
    ("absgrad", {"reset_value": 1.5}, "reset_value"),
])
def test_registry_errors_are_one_line(name, overrides, match):
    with pytest.raises(InputError, match=match) as exc:
        make_strategy(name, **overrides)
    assert "\n" not in str(exc.value)


def test_registry_presets_and_overrides():
    assert make_strategy("default") == DefaultStrategy()
    assert make_strategy("absgrad", grad_threshold=1e-3) == DefaultStrategy(absgrad=True, grad_threshold=1e-3)
    assert make_strategy("mcmc", cap_max=5000).cap_max == 5000
    assert "cap_max" in strategy_fields("mcmc") and "absgrad" in strategy_fields("default")


# ---------------------------------------------------------------------------
# With the rasterizer

@pytest.mark.parametrize("name", ["default", "absgrad", "mcmc", "budget"])
def test_training_steps_through_the_rasterizer(name):
    """A few real optimisation steps: rasterize, backward, Adam, post_backward, with
    densification every other step; shapes stay consistent and Adam keeps working."""
    import splatbench
    from splatbench.workloads import synthetic

    scene = synthetic(200, 32, 24, seed=2)
    g = scene.gaussians
    params = {
        "means": torch.tensor(g.means), "log_scales": torch.tensor(g.log_scales), "quats": torch.tensor(g.quats),
        "opacity_logits": torch.tensor(g.opacity_logits), "sh_dc": torch.tensor(g.sh[:, :1]),
        "sh_rest": torch.tensor(g.sh[:, 1:]),
    }
    params = {k: torch.nn.Parameter(v.float().contiguous()) for k, v in params.items()}
    # the trainer's optimizers (fused Adam): densification must carry their state as well
    from splatbench.train.params import make_optimizers

    opts = make_optimizers(params, {k: 1e-3 for k in params}, 1e-15)
    strat = make_strategy(name, refine_start=0, refine_every=2, **({"grad_threshold": 1e-6} if name != "mcmc"
                                                                     else {"cap_max": 260}))
    state = strat.initialize_state(params)
    target = torch.full((24, 32, 3), 0.5)
    counts = []
    for step in range(6):
        sh = torch.cat([params["sh_dc"], params["sh_rest"]], dim=1)
        rgb, _, _, info = splatbench.rasterize(params["means"], params["log_scales"], params["quats"],
                                               params["opacity_logits"], sh, scene.camera, absgrad=strat.absgrad)
        strat.pre_backward(params, opts, state, ctx(step, info))
        loss = (rgb - target).abs().mean() + strat.regularization(params, step)
        loss.backward()
        for opt in opts.values():
            opt.step()
            opt.zero_grad(set_to_none=True)
        strat.post_backward(params, opts, state, ctx(step, info, extent=2.0, means_lr=1e-3, loss=loss.item()))
        assert_consistent(params, opts)
        counts.append(params["means"].shape[0])
    assert counts[-1] > 200, counts


@pytest.mark.parametrize("name", ["none", "default", "absgrad", "mcmc", "budget"])
def test_every_strategy_states_the_whole_protocol(name):
    """The trainer reads ``absgrad``, ``schedule_fields`` and ``initial_opacity`` directly
    (no getattr probing), the config ``reads_mean_gradients``: each registered strategy must
    declare them with the right types."""
    from splatbench.strategies import STRATEGIES

    strategy = make_strategy(name)
    assert type(strategy) is STRATEGIES[name][0]
    assert isinstance(strategy.absgrad, bool) and strategy.absgrad == (name == "absgrad")
    assert "reads_mean_gradients" in vars(type(strategy)) and isinstance(strategy.reads_mean_gradients, bool)
    assert isinstance(strategy.schedule_fields, dict) and isinstance(strategy.initial_opacity, float)
    assert all(hasattr(strategy, field) for field in strategy.schedule_fields)
    assert "run_fraction_fields" in vars(type(strategy)) or "run_fraction_fields" in vars(DefaultStrategy)
    assert isinstance(strategy.run_fraction_fields, dict)
    assert all(hasattr(strategy, field) for field in strategy.run_fraction_fields)
    assert set(strategy.schedule_fields) <= set(strategy.run_fraction_fields)

def _written_forms(value) -> set[str]:
    """How a default may be written in a docstring: ``2e-4``, ``0.0002``, ``15,000``, ``0``, ``"multiplier"``."""
    if isinstance(value, str):
        return {f'"{value}"'}
    if isinstance(value, bool):
        return {str(value)}
    forms = {repr(value), f"{value:g}", f"{value:,}"}
    if isinstance(value, float):
        forms.add(f"{value:.0e}".replace("e-0", "e-").replace("e+0", "e").replace("e+", "e"))
    return forms


@pytest.mark.parametrize("name", ["none", "default", "mcmc", "budget"])
def test_every_strategy_cites_its_defaults(name):
    """Issue 23: each strategy's docstring (its class's, or the class it extends, or their
    modules') names every field with its default value (``field`` VALUE), beside its source.
    A field added, or a default changed, without its docstring line fails here."""
    import dataclasses
    import re
    import sys

    from splatbench.strategies import STRATEGIES

    cls = STRATEGIES[name][0]
    docs = "\n".join((k.__doc__ or "") + (sys.modules[k.__module__].__doc__ or "")
                     for k in cls.__mro__ if k.__module__.startswith("splatbench."))
    docs = re.sub(r"\s+", " ", docs)
    uncited = []
    for f in dataclasses.fields(cls):
        forms = _written_forms(f.default)
        if not any(re.search(rf"``{f.name}`` (= )?{re.escape(v)}(?!\d|\.\d)", docs) for v in forms):
            uncited.append(f"{f.name} = {f.default!r}")
    assert not uncited, f"{cls.__name__}: defaults not cited in the docstring: {uncited}"



@dataclass
class CountingInfo(FakeInfo):
    """A `FakeInfo` that counts reads of the screen-space mean gradients."""

    reads: list = None

    @property
    def means2d_grad(self):
        self.reads.append("means2d_grad")
        return self.grad

    @property
    def means2d_absgrad(self):
        self.reads.append("means2d_absgrad")
        return self.absgrad


@pytest.mark.parametrize("name", ["none", "default", "absgrad", "mcmc", "budget"])
def test_reads_mean_gradients_is_what_the_hooks_read(name):
    """The declaration `TrainConfig`'s frozen-means check trusts: over a run with refinements
    (so every code path of the hooks runs), a strategy reads the screen-space mean gradients
    exactly when it declares ``reads_mean_gradients``."""
    params, opts = make_params(40, seed=3)
    schedule = {"refine_start": 0, "refine_every": 3, "refine_stop": 10}
    strat = make_strategy(name, **{k: v for k, v in schedule.items() if k in strategy_fields(name)})
    state = strat.initialize_state(params)
    g = torch.Generator().manual_seed(4)
    reads: list[str] = []
    for step in range(12):
        n = params["means"].shape[0]
        info = fake_info(torch.randn(n, 2, generator=g) * 1e-3, absgrad_px=torch.rand(n, 2, generator=g) * 4e-3)
        info = CountingInfo(**{**vars(info), "reads": reads})
        strat.pre_backward(params, opts, state, ctx(step, info))
        strat.post_backward(params, opts, state, ctx(step, info))
        adam_step(params, opts, step)
    assert bool(reads) == strat.reads_mean_gradients, reads


# ---------------------------------------------------------------------------
# Budget (Taming 3DGS)

def test_count_schedule_is_tamings_eq_2():
    """f(k) = a k^2 + b k + N0, b = 2 (B - N0) / S, a = -(B - N0) / S^2: twice the linear
    slope at the start, B at the last refinement, never above B, never decreasing."""
    from splatbench.strategies.budget import count_schedule, refinement_count

    assert count_schedule(100, 500, 4) == [275, 400, 475, 500]
    counts = count_schedule(20_000, 35_000, 29)
    assert counts[-1] == 35_000 and counts == sorted(counts) and max(counts) <= 35_000
    assert counts[0] - 20_000 == 1016  # 2 x 15,000 / 29 - 15,000 / 29^2 = 1016.6
    assert count_schedule(10, 20, 0) == []
    # 3DGS's windows: it in (start, stop), multiples of every
    assert refinement_count(500, 15_000, 100) == 144   # it = 600 .. 14,900
    assert refinement_count(33, 1000, 100) == 9        # it = 100 .. 900
    assert refinement_count(0, 10, 3) == 3 and refinement_count(10, 10, 3) == 0


def budget_setup(n=60, seed=0, **fields):
    params, opts = make_params(n, seed=seed, opacity=0.5)
    with torch.no_grad():
        params["log_scales"][: n // 2] = math.log(0.005)   # small: clone candidates at extent 1
        params["log_scales"][n // 2:] = math.log(0.05)     # large: split candidates
    strat = make_strategy("budget", refine_start=0, refine_every=1, refine_stop=5, reset_every=1000,
                          max_world_size=0.0, **fields)
    return params, opts, strat, strat.initialize_state(params)


def test_budget_grows_to_its_targets_among_the_candidates_only():
    params, opts, strat, state = budget_setup(budget=2.0)   # 60 -> 120 over 4 refinements
    assert state.targets == [86, 105, 116, 120]             # 60 + 30 k - 3.75 k^2
    for k, target in enumerate(state.targets):
        n = params["means"].shape[0]
        state.count[:] = 1
        state.grad_accum[:] = 1e-4                       # below the threshold ...
        cand = torch.arange(n) % 3 != 0                  # ... but for two thirds of them
        state.grad_accum[cand] = 3e-4
        stats = strat.refine(params, opts, state, step=k, scene_extent=1.0)
        grown = stats.cloned + stats.split
        # Taming floors each group's share of the headroom: at most 1 short of the target
        assert stats.pruned == 0 and target - 1 <= stats.num_gaussians <= target, (k, stats)
        assert grown == stats.num_gaussians - n <= int(cand.sum())
        assert_consistent(params, opts)
    assert state.short == [] and strat.outcome_note(state) is None  # every target met
    # more Gaussians than the budget: no growth
    n = params["means"].shape[0]
    state.targets = [10]
    state.refinements = 0
    assert strat.refine(params, opts, state, step=9, scene_extent=1.0).num_gaussians == n


def test_budget_says_when_too_few_candidates_leave_it_below_its_budget():
    """Taming grows candidates only: with 6 of 60 passing the threshold, 60 -> 120 cannot be met.
    Every refinement is recorded short and the run's note names the final count, the budget,
    the threshold and the two ways out; once a later refinement meets its target, no note."""
    params, opts, strat, state = budget_setup(budget=2.0)   # targets 86, 105, 116, 120
    for k in range(4):
        state.count[:] = 1
        state.grad_accum[:] = 1e-4
        state.grad_accum[:6] = 3e-4                      # 6 candidates (clone: the small half)
        stats = strat.refine(params, opts, state, step=k, scene_extent=1.0)
        assert stats.num_gaussians == 60 + 6 * (k + 1)   # all candidates grow, no more
    assert [s[0] for s in state.short] == [1, 2, 3, 4] and state.short[-1] == (4, 120, 84)  # 78 + 6
    note = strat.outcome_note(state)
    assert note.startswith("warning: strategy 'budget' ended at 84 Gaussians, below its budget of 120")
    assert "4 of 4 refinements" in note and "grad_threshold 0.0002" in note and "smaller budget" in note
    # a last refinement whose target was within reach: the model met its budget, no note
    state.targets, state.refinements = [5, 84], 1
    strat.refine(params, opts, state, step=4, scene_extent=1.0)
    assert strat.outcome_note(state) is None


def test_budget_says_why_it_made_fewer_refinements_than_its_schedule():
    """A run that stopped before the count schedule's last refinement (a 3,100-step cut of graphdeco-7k
    whose schedule is laid over 7,000) is no early stop: the note names the cause it had."""
    for early, cause in ((False, "(the run ended before the schedule's last refinement)"),
                         (True, "(early_stop ended densification)")):
        params, opts, strat, state = budget_setup(budget=2.0, early_stop=early)   # 60 -> 120 over 4
        state.count[:] = 1
        state.grad_accum[:] = 3e-4
        strat.refine(params, opts, state, step=0, scene_extent=1.0)    # 1 of the 4 refinements
        note = strat.outcome_note(state)
        assert note.startswith("strategy 'budget' ended at 86 Gaussians, below its budget of 120: it made 1 of the "
                               "4 refinements") and note.endswith(cause), note


def test_budget_and_mcmc_say_when_their_budget_or_cap_is_below_the_initial_count():
    """Neither prunes down to a count: a budget or cap under the initial count is never met and
    the run says so (the multiplier mode's warning names final_count, the usual intent)."""
    params, opts, strat, state = budget_setup(budget=0.5)    # 30 of 60, multiplier
    for k in range(4):
        strat.refine(params, opts, state, step=k, scene_extent=1.0)
    note = strat.outcome_note(state)
    assert note.startswith("warning: strategy 'budget': its budget of 30 is below the initial 60 Gaussians")
    assert "strategy.budget_mode=final_count" in note and "ended at 60" in note
    params, opts = make_params(60, seed=0, opacity=0.5)
    mcmc = make_strategy("mcmc", cap_max=40)
    note = mcmc.outcome_note(mcmc.initialize_state(params))
    assert note.startswith("warning: strategy 'mcmc': cap_max 40 is below the initial 60 Gaussians")
    assert make_strategy("mcmc", cap_max=60).outcome_note(mcmc.initialize_state(params)) is None


def test_budget_notes_a_final_prune_below_its_budget_without_a_warning():
    """The last refinement meets its target, then prunes transparent Gaussians in the same step
    (Taming's order): a plain note with the numbers, not a warning (the rule worked as designed)."""
    params, opts, strat, state = budget_setup(budget=80, budget_mode="final_count")
    state.targets = [80]
    with torch.no_grad():
        params["opacity_logits"][:5] = -10.0               # opacity 4.5e-5 < prune_opacity 0.005
    state.count[:] = 1
    state.grad_accum[:] = 3e-4                            # every Gaussian a candidate
    stats = strat.refine(params, opts, state, step=0, scene_extent=1.0)
    assert stats.pruned >= 5 and stats.num_gaussians == 80 - stats.pruned
    note = strat.outcome_note(state)
    assert note == (f"strategy 'budget' ended at {80 - stats.pruned:,} Gaussians, {stats.pruned} below its budget of "
                    f"80: its last refinement grew to 80 and pruned {stats.pruned} (opacity below prune_opacity, or "
                    f"too large) in the same step, as Taming 3DGS does")


def test_budget_shares_headroom_by_candidates_and_draws_by_score():
    """Headroom split clone : split = 20 : 10 (candidates 2 : 1); within the split group,
    Gaussians with a much larger score (opacity; the volume term, which would favour every
    large Gaussian alike, off) are drawn first."""
    params, opts, strat, state = budget_setup(budget=80, budget_mode="final_count", score_volume=0.0)
    state.targets = [80]
    with torch.no_grad():
        params["opacity_logits"][:] = -4.0                     # opacity 0.018
        params["opacity_logits"][30:40] = 4.0                  # opacity 0.98: high score
    state.count[:] = 1
    state.grad_accum[:] = 3e-4
    state.grad_accum[40:50] = 0.0                              # split candidates: 30..39, 50..59
    clone, split = strat.select(params, state, 1.0)
    assert int(clone.sum()) == 20 * 30 // 50 and int(split.sum()) == 20 * 20 // 50
    assert bool(clone[:30].all() == clone[:30].any()) or int(clone[30:].sum()) == 0
    assert int(split[:30].sum()) == 0 and int(split[40:50].sum()) == 0
    # 8 of 20 split candidates drawn; the 10 opaque ones score 100 x 0.982 / 0.018 + 25 = 5480, the
    # others 125: each draw picks a transparent one with probability < 10 x 125 / (3 x 5480) < 8 %
    assert int(split[30:40].sum()) >= 7


def test_budget_final_count_and_multiplier_and_bad_values():
    assert make_strategy("budget", budget=3.0).final_count(1000) == 3000
    assert make_strategy("budget", budget=35_000, budget_mode="final_count").final_count(20_000) == 35_000
    for fields, match in [({"budget_mode": "twice"}, "budget_mode"), ({"budget": 0.0}, "budget"),
                          ({"budget": 10.5, "budget_mode": "final_count"}, "whole number"),
                          ({"absgrad": True}, "absgrad"), ({"score_opacity": -1.0}, "score_opacity")]:
        with pytest.raises(InputError, match=match):
            make_strategy("budget", **fields)


def test_a_strategys_own_check_names_the_option_as_the_user_wrote_it():
    """__post_init__ says ``BudgetStrategy.budget_mode``; through make_strategy (a config's
    strategy_options) the message names ``strategy.budget_mode``, the same name the type
    checks use, so one option has one name whatever check caught it."""
    with pytest.raises(InputError) as err:
        make_strategy("budget", budget_mode="final")
    assert str(err.value).startswith("strategy 'budget': strategy.budget_mode: expected one of")
    with pytest.raises(InputError) as err:
        make_strategy("budget", reset_value=2.0)   # checked by the base class, DefaultStrategy
    assert str(err.value).startswith("strategy 'budget': strategy.reset_value: expected a number in (0, 1)")


def test_budget_score_is_median_normalised():
    from splatbench.strategies.budget import median_normalized

    v = torch.tensor([0.0, 1.0, 2.0, 4.0, float("nan")])
    # median of the positive values (1, 2, 4) is 2; zero and NaN score 0
    torch.testing.assert_close(median_normalized(10.0, v), torch.tensor([0.0, 5.0, 10.0, 20.0, 0.0]))


def test_reset_every_zero_means_never():
    params, opts, strat, state, extent = grow_setup()
    never = DefaultStrategy(refine_start=10_000, reset_every=0)
    st = never.initialize_state(params)
    before = params["opacity_logits"].detach().clone()
    for step in range(0, 12):
        never.post_backward(params, opts, st, ctx(step, fake_info(torch.zeros(20, 2))))
    torch.testing.assert_close(params["opacity_logits"].detach(), before)
    assert never.last_topology_change(12) is None
    # and no size pruning, which 3DGS ties to the first reset: a Gaussian 10 x too large stays
    with torch.no_grad():
        params["log_scales"][5] = math.log(10.0)
    st.count[:], st.grad_accum[:] = 1, 0
    assert DefaultStrategy(reset_every=0).refine(params, opts, st, step=50_000, scene_extent=1.0).pruned == 0


def test_a_scaled_schedule_that_never_refines_is_named():
    """graphdeco's schedule scaled to 200 steps: refine window 3..100, every 100 (a sample
    size, not scaled), so no refinement step falls in it; the run says so rather than
    reporting 'default' densification that never densified. At 2000 steps it refines."""
    from splatbench.train.config import StrategyConfig, TrainConfig

    for name in ("default", "absgrad", "budget"):
        short = TrainConfig(dataset="x", iterations=200, strategy=StrategyConfig(name=name)).make_strategy()
        assert "never refines in this run" in short.schedule_note(200) and "refine_every" in short.schedule_note(200)
        assert TrainConfig(dataset="x", iterations=2000, strategy=StrategyConfig(name=name)).make_strategy().schedule_note(2000) is None
    fraction = TrainConfig(dataset="x", iterations=200, strategy=StrategyConfig(name="default", options={"refine_every": "5%"})).make_strategy()
    assert fraction.schedule_note(200) is None
