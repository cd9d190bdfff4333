"""The training step's fast path against the path it replaced (issue 30, training throughput
and memory): the same maths, so the losses and the model must be bit-identical step for step.

The old path is reproduced here (as `tests/binning_3sigma.py` keeps the old binning): the
rendered image detached into a leaf, the loss backpropagated to it, the regularisation's
backward, then ``rgb.backward(image.grad)`` into the rasterizer, and ``torch.optim.Adam
(fused=True)`` per group. The new path (`Trainer.step`): one backward from the scalar loss
through the rasterizer (the regularisation's first), `splatbench.train.adam.FusedAdam`, and the
background read from host copies instead of the device tensors.
Densification runs in the window (``refine_every=2``), so the strategies' edits of the
parameters and Adam moments are covered too.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from splatbench.bench.train import synthetic_scene
from splatbench.strategies.base import PARAM_GROUPS, StepContext
from splatbench.train.config import LossConfig, SHConfig, StrategyConfig, TrainConfig
from splatbench.train.losses import photometric_loss
from splatbench.train.loop import Trainer
from splatbench.train.params import refreeze, set_lr

ROOT = Path(__file__).resolve().parents[1]
STEPS = 8


def _old_step(tr: Trainer) -> float:
    """The step before this change (loop.py at c53a18f), minus its timers."""
    cfg, step = tr.config, tr.step_index
    degree = tr.sh.update(step, tr.probe_band)
    lr = tr.means_lr(step)
    set_lr(tr.optimizers["means"], lr)
    view = tr._next_view()
    target = tr.target(view)
    if cfg.random_background:
        bg = torch.rand(3, generator=tr.generator).to(tr.device)
    else:
        bg = tr.background
    if tr.dataset.train.alpha_pixels is not None and bool((bg != tr.gt_background).any()):
        alpha = torch.from_numpy(tr.dataset.train.alpha(view)).to(tr.device)
        target = target + (bg - tr.gt_background) * (1 - alpha)[..., None]
    for opt in tr.optimizers.values():
        opt.zero_grad(set_to_none=True)
    rgb, _, _, info = tr._render(tr.dataset.train.cameras[view], degree, bg.tolist())
    image = rgb.detach().requires_grad_(rgb.requires_grad)
    loss = photometric_loss(image, target, cfg.loss.ssim_lambda, cfg.loss.ssim_window)
    reg = tr.strategy.regularization(tr.params, step)
    ctx = StepContext(step=step, info=info, scene_extent=tr.extent, means_lr=lr, loss=float(loss.detach()))
    tr.strategy.pre_backward(tr.params, tr.optimizers, tr.state, ctx)
    loss.backward()
    if isinstance(reg, torch.Tensor) and reg.requires_grad:
        reg.backward()
    rgb.backward(image.grad)
    for opt in tr.optimizers.values():
        opt.step()
    tr.strategy.post_backward(tr.params, tr.optimizers, tr.state, ctx)
    refreeze(tr.params, tr.lrs)
    tr.step_index += 1
    return float(loss.detach()) + float(reg.detach() if isinstance(reg, torch.Tensor) else reg)


def _torch_adams(tr: Trainer) -> None:
    tr.optimizers = {name: torch.optim.Adam([{"params": [tr.params[name]], "lr": tr.lrs[name], "name": name}],
                                            lr=tr.lrs[name], eps=tr.config.optim.adam_eps, fused=True)
                     for name in PARAM_GROUPS}


def _with_alpha(dataset):
    """``dataset`` with 8-bit alphas on its training views (a radial ramp), so a random
    background is composited under the ground truth."""
    v, h, w, _ = dataset.train.pixels.shape
    yy, xx = np.meshgrid(np.linspace(-1, 1, h), np.linspace(-1, 1, w), indexing="ij")
    ramp = np.clip(255 * (1.2 - np.hypot(xx, yy)), 0, 255).astype(np.uint8)
    return dataclasses.replace(dataset, train=dataclasses.replace(dataset.train,
                                                                  alpha_pixels=np.stack([ramp] * v)))


@pytest.mark.parametrize("strategy, extra, random_background",
                         [("default", {"refine_start": 1, "refine_every": 2, "grad_threshold": 1e-7}, False),
                          ("mcmc", {"refine_start": 1, "refine_every": 2, "opacity_reg": 0.01, "scale_reg": 0.01},
                           False),
                          ("default", {"refine_start": 1, "refine_every": 2, "grad_threshold": 1e-7}, True)],
                         ids=["default", "mcmc-reg", "default-random-background"])
def test_fast_step_gives_the_old_steps_losses_and_model_bit_for_bit(strategy, extra, random_background):
    dataset, _ = synthetic_scene(24, 150, 3, 0)
    if random_background:
        dataset = _with_alpha(dataset)
    cfg = TrainConfig(dataset="", out="", iterations=STEPS, seed=0, device="cpu", random_background=random_background, strategy=StrategyConfig(name=strategy, options=extra), sh=SHConfig(degree=3, interval=2))
    old, new = Trainer(cfg, dataset=dataset), Trainer(cfg, dataset=dataset)
    _torch_adams(old)
    old_losses = [_old_step(old) for _ in range(STEPS)]
    new_losses = [new.step().loss for _ in range(STEPS)]
    assert old_losses == new_losses
    assert old.num_gaussians == new.num_gaussians != 150  # densification ran
    for name in PARAM_GROUPS:
        assert torch.equal(old.params[name], new.params[name]), name
        so, sn = old.optimizers[name].state[old.params[name]], new.optimizers[name].state[new.params[name]]
        for key in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(so[key], sn[key]), (name, key)
    t = new.times
    assert t.steps == STEPS and t.loss > 0 and t.raster_backward > 0  # the hook split the backward


def test_a_training_step_imports_neither_torch_dynamo_nor_sympy():
    """torch.optim's wrappers import torch._dynamo (~70 MB resident) on first use, and
    ``Tensor.backward(gradient)`` imports torch.fx's sympy (~33 MB): a training run uses
    neither (docs/benchmarks.md, "Training": peak RSS)."""
    code = (
        "import sys\n"
        "from splatbench.bench.train import synthetic_scene\n"
        "from splatbench.train.config import StrategyConfig, TrainConfig\n"
        "from splatbench.train.loop import Trainer\n"
        "ds, _ = synthetic_scene(24, 60, 2, 0)\n"
        "tr = Trainer(TrainConfig(dataset='', out='', iterations=2, strategy=StrategyConfig(name='default'), seed=0,"
        " device='cpu'),"
        " dataset=ds)\n"
        "tr.step(); tr.step()\n"
        "print(sorted(m for m in ('torch._dynamo', 'sympy') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout



def test_warm_up_compiles_the_loss_kernels():
    """`Trainer.warm_up` compiles (or loads) the loss's Dr.Jit D-SSIM kernels at the
    training image size, so the first timed step does not pay for them: after it, the
    loss and its gradient run only kernels Dr.Jit holds in memory."""
    import drjit as dr

    dataset, _ = synthetic_scene(24, 60, 2, 0)
    trainer = Trainer(TrainConfig(dataset="", out="", iterations=3, seed=0, device="cpu", strategy=StrategyConfig(name="none"), loss=LossConfig(ssim_window=7)), dataset=dataset)  # a window no other test compiles first
    trainer.warm_up()
    image = torch.rand(24, 24, 3, requires_grad=True)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # clears it
        photometric_loss(image, trainer.target(1), 0.2, 7).backward()
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    jit = [k for k in history if k["type"] == dr.KernelType.JIT]
    assert len(jit) >= 6 and all(k.get("cache_hit") and not k.get("cache_disk") for k in jit), \
        [(k.get("cache_hit"), k.get("cache_disk"), k.get("size")) for k in jit]


def test_dr_jits_allocation_cache_is_flushed_when_the_model_changes_size(monkeypatch):
    """After a step that changed N (densification), the buffers Dr.Jit cached for the old
    sizes are handed back (`dr.flush_malloc_cache`), and only then."""
    import splatbench.train.loop as loop

    calls = []
    monkeypatch.setattr(loop.dr, "flush_malloc_cache", lambda: calls.append(1))
    dataset, _ = synthetic_scene(24, 150, 3, 0)
    cfg = TrainConfig(dataset="", out="", iterations=6, seed=0, device="cpu", strategy=StrategyConfig(name="default", options={"refine_start": 1, "refine_every": 2, "grad_threshold": 1e-7}))
    trainer = Trainer(cfg, dataset=dataset)
    changed = 0
    for _ in range(6):
        n = trainer.num_gaussians
        trainer.step()
        changed += trainer.num_gaussians != n
    assert changed >= 1 and len(calls) == changed
