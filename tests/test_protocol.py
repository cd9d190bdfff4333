"""Protocols (issue 29 item 2): graphdeco's 30,000-step schedule unscaled, evaluated in full
at 7,000 and 30,000 steps of one run; its 7K check (the same schedule stopped at 7,000);
the quick protocol (the schedule laid over the run) unchanged.

The runs here are a few steps on the 32² `diffuse` dataset of tests/test_train.py: what
is tested is where the schedule is laid and where the evaluations fall, not quality.
"""

from __future__ import annotations


import math
from pathlib import Path

import pytest
import torch

from splatbench.errors import InputError
from splatbench.train import TrainConfig, TrainResult, apply_overrides, train
from splatbench.train.config import EvalConfig, SHConfig, StrategyConfig
from splatbench.train.loop import Trainer
from splatbench.train.protocol import PROTOCOLS, evaluation_steps
from tests.test_train import config, tiny_diffuse, tiny_diffuse_dir  # noqa: F401 - fixtures


def test_graphdeco_protocols_run_the_30k_schedule_unscaled_and_quick_scales_it():
    quick = apply_overrides(TrainConfig(), ["iterations=2000"])
    s = quick.make_strategy()
    # 2000 / 30000 of graphdeco's steps (round half up): 500 -> 33, 15000 -> 1000, 3000 -> 200, 1000 -> 67
    assert (s.refine_start, s.refine_stop, s.reset_every, quick.sh_steps, quick.schedule_length) == \
        (33, 1000, 200, 67, 2000)
    assert quick.protocol == "quick" and quick.evaluation_steps == []
    for name, iterations, steps in (("graphdeco-30k", 30_000, [7000, 30000]), ("graphdeco-7k", 7000, [7000])):
        cfg = apply_overrides(TrainConfig(), [f"protocol={name}"])  # the protocol brings its iterations
        s = cfg.make_strategy()
        assert (cfg.iterations, cfg.schedule_length, cfg.evaluation_steps) == (iterations, 30_000, steps)
        assert (s.refine_start, s.refine_stop, s.refine_every, s.reset_every, cfg.sh_steps) == \
            (500, 15_000, 100, 3000, 1000)
        assert TrainConfig.from_dict({"protocol": name}).iterations == iterations
    # given iterations win (a smoke test stops the schedule early); more than the protocol's is refused
    assert apply_overrides(TrainConfig(), ["protocol=graphdeco-30k", "iterations=300"]).iterations == 300
    with pytest.raises(InputError, match="iterations: protocol 'graphdeco-7k' runs 7000 steps"):
        apply_overrides(TrainConfig(), ["protocol=graphdeco-7k", "iterations=7001"])
    with pytest.raises(InputError, match="protocol: expected one of 'quick', 'graphdeco-30k', 'graphdeco-7k'"):
        apply_overrides(TrainConfig(), ["protocol=graphdeco"])
    with pytest.raises(InputError, match=r"eval.steps: expected steps in 1\.\.300"):
        apply_overrides(TrainConfig(), ["iterations=300", "eval.steps=[301]"])
    # the quick protocol keeps its final-10 % check; graphdeco's 7K model is taken mid-refinement as the paper's is
    with pytest.raises(InputError, match="final 10 %"):
        TrainConfig(iterations=7000, schedule="absolute")
    assert PROTOCOLS["quick"].final_window_check and not PROTOCOLS["graphdeco-7k"].final_window_check


def test_the_position_lr_decays_over_30k_steps_under_graphdecos_protocols(tmp_path, tiny_diffuse):
    """The 7K check's learning rate at every step is the 30K run's (log-linear over 30,000
    steps: at 7,000 it is 1.6e-4^(23/30) 1.6e-6^(7/30) x extent), not a decay over 7,000."""
    lr = {}
    for name in ("graphdeco-30k", "graphdeco-7k", "quick"):
        cfg = TrainConfig(protocol=name, iterations=7000, out=str(tmp_path / name), strategy=StrategyConfig(name="none"))
        lr[name] = Trainer(cfg, dataset=tiny_diffuse).means_lr
    extent = lr["quick"].scale
    for step in (0, 3500, 6999):
        assert lr["graphdeco-7k"](step) == lr["graphdeco-30k"](step)
    expected = extent * math.exp((23 / 30) * math.log(1.6e-4) + (7 / 30) * math.log(1.6e-6))
    assert lr["graphdeco-7k"](7000) == pytest.approx(expected, rel=1e-12)
    assert lr["quick"](7000) == pytest.approx(extent * 1.6e-6, rel=1e-12)  # the quick run decays over its own length


def test_the_7k_check_is_the_30k_run_stopped_there(tmp_path, tiny_diffuse):
    """A graphdeco-7k run and a graphdeco-30k run of the same seed are the same run up to
    the 7K run's end (here scaled down: stopped after 10 and 20 steps, the longer one
    checkpointed at 10): the same PLY bytes; under the quick protocol they are not (its
    learning rate decays over each run's own length), so the comparison can fail."""
    def run(name, protocol, iterations, **kw):
        return train(config(tmp_path, out=str(tmp_path / name), protocol=protocol, iterations=iterations,
                            schedule="scaled", **kw, strategy=StrategyConfig(name="default")), dataset=tiny_diffuse)

    short = run("7k", "graphdeco-7k", 10)
    long = run("30k", "graphdeco-30k", 20, checkpoint_every=10)
    at_10 = tmp_path / "30k" / "checkpoints" / "iteration_10.ply"
    assert Path(short.ply_path).read_bytes() == at_10.read_bytes()
    quick_short = train(config(tmp_path, out=str(tmp_path / "q10"), iterations=10), dataset=tiny_diffuse)
    train(config(tmp_path, out=str(tmp_path / "q20"), iterations=20, checkpoint_every=10), dataset=tiny_diffuse)
    quick_at_10 = tmp_path / "q20" / "checkpoints" / "iteration_10.ply"
    assert Path(quick_short.ply_path).read_bytes() != quick_at_10.read_bytes()


def test_step_evaluations_record_every_column_and_survive_a_resume(tmp_path, tiny_diffuse):
    """graphdeco-30k stopped at 12 with eval_steps [6]: full evaluations after 6 and 12
    steps (PSNR, SSIM, LPIPS in both input conventions, Gaussians, loop time), the last one
    the final model's; the curve holds the step-6 point too; a resumed run ends with the
    same list; the JSON round trip keeps it."""
    base = dict(protocol="graphdeco-30k", iterations=12, eval=EvalConfig(steps=[6]), strategy=StrategyConfig(name="default"), sh=SHConfig(degree=0))
    straight = train(config(tmp_path, out=str(tmp_path / "a"), checkpoint_every=8, **base), dataset=tiny_diffuse)
    assert straight.protocol == "graphdeco-30k"
    assert [e.step for e in straight.step_evaluations] == [6, 12]
    first, last = straight.step_evaluations
    assert (last.psnr, last.ssim, last.num_gaussians, last.views) == \
        (straight.test_psnr, straight.test_ssim, straight.num_gaussians, straight.test_views)
    assert first.psnr < last.psnr  # 6 more steps of a model far from converged
    assert 0 < first.train_seconds < last.train_seconds == straight.train_seconds
    assert [p.step for p in straight.evaluations] == [6, 12]
    if last.lpips_net:  # the LPIPS weights are installed (`make setup`); otherwise notes say why
        assert last.lpips_net == "alex" and last.lpips_scaled == straight.test_lpips  # config: alex, scaled
        assert last.lpips_unscaled is not None and last.lpips_unscaled != last.lpips_scaled
    assert straight.at_step(6) == first and straight.at_step(7) is None
    assert TrainResult.from_dict(straight.to_dict()).step_evaluations == straight.step_evaluations
    # resumed after step 8 (past the step-6 evaluation, which the checkpoint carries)
    ckpt = tmp_path / "a" / "checkpoints" / "iteration_8.pt"
    resumed = train(config(tmp_path, out=str(tmp_path / "b"), **base), dataset=tiny_diffuse, resume=ckpt)
    assert [e.step for e in resumed.step_evaluations] == [6, 12]
    assert resumed.step_evaluations[0] == first and resumed.step_evaluations[1].psnr == last.psnr
    # a quick run without eval_steps records none (its result is as before)
    quick = train(config(tmp_path, out=str(tmp_path / "q"), iterations=4), dataset=tiny_diffuse)
    assert quick.step_evaluations == [] and quick.protocol == "quick"


def test_a_checkpoint_written_before_protocols_existed_resumes(tmp_path, tiny_diffuse):
    """A checkpoint whose config has no ``protocol`` / ``eval.steps`` (a field added after it was
    written) resumes a run at their defaults."""
    base = dict(iterations=8, checkpoint_every=4)
    train(config(tmp_path, out=str(tmp_path / "a"), **base), dataset=tiny_diffuse)
    ckpt = tmp_path / "a" / "checkpoints" / "iteration_4.pt"
    state = torch.load(ckpt, map_location="cpu", weights_only=True)
    del state["config"]["protocol"], state["config"]["eval"]["steps"]
    torch.save(state, ckpt)
    assert train(config(tmp_path, out=str(tmp_path / "b"), **base), dataset=tiny_diffuse, resume=ckpt).iterations == 8


def test_protocol_and_eval_steps_change_run_ids():
    """Grid run ids hash the resolved config (splatbench.experiments.train_kind): the protocol and
    the evaluation steps are in it, at their defaults too, so another protocol or other eval steps
    make new runs, and the default written out is the same run."""
    from splatbench.experiments.grid import make_run_id
    from splatbench.experiments.train_kind import TRAIN

    def run_id(**kw):
        return make_run_id("train", TRAIN.resolve({"scene": "diffuse", "seed": 0, "iterations": 7000, **kw}))

    resolved = TRAIN.resolve({"scene": "diffuse", "seed": 0, "iterations": 2000})
    assert resolved["protocol"] == "quick" and resolved["eval"]["steps"] == []
    assert run_id() == run_id(protocol="quick") == run_id(eval={"steps": []})
    ids = {run_id(protocol="graphdeco-7k"), run_id(protocol="graphdeco-30k"), run_id(eval={"steps": [100]})}
    assert len(ids) == 3 and run_id() not in ids
    # a protocol given without iterations brings its own
    assert TRAIN.resolve({"scene": "diffuse", "seed": 0, "protocol": "graphdeco-7k"})["iterations"] == 7000


def test_evaluation_steps_are_those_reached_and_the_end():
    assert evaluation_steps("graphdeco-30k", [], 30_000) == [7000, 30000]
    assert evaluation_steps("graphdeco-30k", [], 300) == [300]              # stopped early: the end only
    assert evaluation_steps("graphdeco-30k", [100], 300) == [100, 300]
    assert evaluation_steps("quick", [], 2000) == [] and evaluation_steps("quick", [500], 2000) == [500, 2000]


def test_a_short_graphdeco_run_is_advised_to_run_full_length_and_told_its_columns_are_not_the_papers():
    """Under a named protocol the schedule is graphdeco's as written: a run too short to refine
    is advised to run the protocol's length (not to change refine_every, which would leave
    the protocol); a run stopped early is told its last evaluation is no published column,
    while a column it did reach (the 30K run's 7,000 steps) still is."""
    from splatbench.train.loop import _schedule_note

    short = apply_overrides(TrainConfig(), ["protocol=graphdeco-7k", "iterations=50"])
    note = _schedule_note(short.make_strategy(), short)
    assert note.startswith("warning: strategy 'default' never refines in this run")
    assert "run the protocol's full length (iterations=7000" in note and "smaller value" not in note
    quick = apply_overrides(TrainConfig(), ["iterations=200"])
    assert "give strategy.refine_every a smaller value" in _schedule_note(quick.make_strategy(), quick)

    assert PROTOCOLS["graphdeco-7k"].early_stop_note(50) == (
        "protocol 'graphdeco-7k' stopped early, after 50 of its 7000 steps: its step evaluation at 50 is not the "
        "3DGS paper's 7K column (run all 7000 steps for that)")
    assert PROTOCOLS["graphdeco-30k"].early_stop_note(10_000) == (
        "protocol 'graphdeco-30k' stopped early, after 10000 of its 30000 steps: its step evaluation at 10000 is "
        "not the 3DGS paper's 30K column (run all 30000 steps for that); its step-7000 evaluation is the 7K column's")
    assert "7K and 30K columns" in PROTOCOLS["graphdeco-30k"].early_stop_note(300)
    assert PROTOCOLS["graphdeco-7k"].early_stop_note(7000) is None and PROTOCOLS["quick"].early_stop_note(5) is None


def test_a_graphdeco_run_stopped_early_says_so_among_its_notes_and_warnings(tmp_path, tiny_diffuse):
    res = train(TrainConfig(protocol="graphdeco-7k", iterations=3, out=str(tmp_path / "r"), strategy=StrategyConfig(name="default"), sh=SHConfig(degree=0)), dataset=tiny_diffuse)
    assert any(n.startswith("protocol 'graphdeco-7k' stopped early, after 3 of its 7000 steps") for n in res.notes)
    assert any("never refines" in w and "run the protocol's full length" in w for w in res.warnings)
