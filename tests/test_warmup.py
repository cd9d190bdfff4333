"""Kernel compilation stays out of the timed training loop (issue #15, item 8):
after `Trainer.warm_up`, no step at any SH degree, and no evaluation, compiles or
loads a kernel -- every Dr.Jit launch hits the in-memory cache.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
import torch

from splatbench.train.config import SHConfig, StrategyConfig, TrainConfig
from splatbench.train.loop import Trainer


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory):
    from splatbench.scenes.render import render_dataset

    out = tmp_path_factory.mktemp("warmup") / "diffuse-16"
    render_dataset("diffuse", out, resolution=16, views=4, spp=1, progress=False)
    return out


def test_after_warm_up_no_step_or_evaluation_compiles_a_kernel(tmp_path, dataset_dir):
    # the schedule raises the degree every 2 steps: 0, 1, 2, 3 within the 8 steps
    config = TrainConfig(dataset=str(dataset_dir), out=str(tmp_path), iterations=8, sh=SHConfig(degree=3, interval=2), strategy=StrategyConfig(name="none")).validate()
    trainer = Trainer(config)
    before = {k: v.detach().clone() for k, v in trainer.params.items()}
    rng_state = trainer.generator.get_state()
    trainer.warm_up()
    # the warm-up changes no parameter and no random stream
    assert all(torch.equal(before[k], v.detach()) for k, v in trainer.params.items())
    assert torch.equal(rng_state, trainer.generator.get_state())
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        dr.kernel_history_clear()
        degrees = {trainer.step().sh_degree for _ in range(config.iterations)}
        trainer.evaluate()
        history = dr.kernel_history([dr.KernelType.JIT])
    assert degrees == {0, 1, 2, 3}
    assert history, "no kernel launches were recorded"
    compiled = [h for h in history if not h.get("cache_hit", True)]
    assert not compiled, f"{len(compiled)} of {len(history)} launches compiled or loaded a kernel " \
                         f"({sum(h.get('backend_time', 0.0) for h in compiled):.0f} ms)"
    assert np.isfinite(trainer.params["means"].detach().numpy()).all()
