"""Schedules that scale with the run (issue 11 §1): graphdeco's 30,000-step numbers
scaled to the run's length, and the rule that no topology change falls in the final
10 % of a run, checked before any data is read."""

from __future__ import annotations

import pytest

from splatbench.errors import InputError
from splatbench.strategies import STRATEGIES, DefaultStrategy, MCMCStrategy
from splatbench.train.config import StrategyConfig, TrainConfig
from splatbench.train.schedule import final_window_start, scale_step


def test_scale_step_keeps_graphdecos_proportions():
    # 600 / 30,000 = 1/50: refine from 500/50 = 10 to 15,000/50 = 300, reset every 3,000/50 = 60
    assert scale_step(500, 600, "scaled") == 10
    assert scale_step(15_000, 600, "scaled") == 300
    assert scale_step(3000, 600, "scaled", interval=True) == 60
    assert scale_step(1000, 2000, "scaled", interval=True) == 67   # 66.67 rounds half up
    assert scale_step(500, 30_000, "scaled") == 500                 # graphdeco's own length: unchanged
    assert scale_step(100, 100, "scaled", interval=True) == 1       # 0.33: a period is never 0
    assert scale_step(100, 100, "scaled") == 0
    assert scale_step(500, 600, "absolute") == 500
    with pytest.raises(InputError, match="schedule"):
        scale_step(500, 600, "relative")


def test_final_window():
    assert final_window_start(600) == 540     # steps 540..599 are the final 10 %
    assert final_window_start(25) == 22       # ceil(2.5) = 3 steps
    assert final_window_start(3) == 2         # at least the last step


def test_config_scales_strategy_and_sh_steps():
    cfg = TrainConfig(iterations=600).validate()
    s = cfg.make_strategy()
    assert (s.refine_start, s.refine_stop, s.refine_every, s.reset_every) == (10, 300, 100, 60)
    assert cfg.sh_steps == 20
    written = cfg.make_strategy(scaled=False)
    assert (written.refine_start, written.refine_stop, written.reset_every) == (500, 15_000, 3000)
    absolute = TrainConfig(iterations=600, schedule="absolute", strategy=StrategyConfig(options={"refine_stop": 450}))
    assert absolute.validate().make_strategy().refine_start == 500 and absolute.sh_steps == 1000


def test_absolute_graphdeco_schedule_on_a_short_run_is_rejected_with_one_line():
    with pytest.raises(InputError) as err:
        TrainConfig(iterations=600, schedule="absolute").validate()
    msg = str(err.value)
    assert "\n" not in msg
    # graphdeco's refinement at it = 600 is the run's last step (599)
    assert "refine window 500..15000" in msg and "step 599" in msg and "final 10 % of 600" in msg
    assert "schedule='scaled'" in msg
    with pytest.raises(InputError, match="relocation .*step 599"):
        TrainConfig(iterations=600, schedule="absolute", strategy=StrategyConfig(name="mcmc")).validate()
    with pytest.raises(InputError, match="schedule: expected"):
        TrainConfig(iterations=600, schedule="fractions").validate()


@pytest.mark.parametrize("iterations", [1, 2, 7, 60, 600, 2000, 30_000])
@pytest.mark.parametrize("name", sorted(STRATEGIES))
def test_scaled_defaults_are_valid_at_any_length(name, iterations):
    cfg = TrainConfig(iterations=iterations, strategy=StrategyConfig(name=name)).validate()
    change = cfg.make_strategy().last_topology_change(iterations)
    assert change is None or change.step < final_window_start(iterations)


def test_graphdecos_own_run_is_valid_in_absolute_steps():
    cfg = TrainConfig(iterations=30_000, schedule="absolute").validate()
    assert cfg.make_strategy().last_topology_change(30_000).step == 14_899   # refinement at it = 14,900


def test_last_topology_change_names_the_latest_event():
    # reset (every 30, last at it = 90) after the last refinement (it = 50)
    s = DefaultStrategy(refine_start=0, refine_stop=100, refine_every=50, reset_every=30)
    assert s.last_topology_change(100) == (89, "an opacity reset (every 30; refine window 0..100, every 50)")
    assert s.last_topology_change(29) is None                 # neither a reset nor a refinement yet
    assert DefaultStrategy(refine_start=500).last_topology_change(500) is None   # refine only after 500
    assert MCMCStrategy(refine_start=2, refine_stop=10, refine_every=3).last_topology_change(100).step == 8


def test_step_fields_as_fractions_of_the_run():
    """"25%" / "1/4" of the run, whatever `schedule` says; not scaled again; periods >= 1."""
    cfg = TrainConfig(iterations=2000, strategy=StrategyConfig(options={"refine_stop": "75%", "refine_every": "1/40",
                                                         "reset_every": "1/5", "refine_start": 50}))
    s = cfg.make_strategy()
    # refine_start is steps of graphdeco's 30,000 (scaled: 50 x 2000 / 30000 = 3.33 -> 3)
    assert (s.refine_start, s.refine_stop, s.refine_every, s.reset_every) == (3, 1500, 50, 400)
    assert cfg.make_strategy(scaled=False).refine_stop == 1500
    absolute = TrainConfig(iterations=2000, schedule="absolute", strategy=StrategyConfig(options={"refine_start": "1%", "refine_stop": "50%", "reset_every": "10%"}))
    a = absolute.make_strategy()
    assert (a.refine_start, a.refine_stop, a.reset_every) == (20, 1000, 200)
    tiny = TrainConfig(iterations=20, strategy=StrategyConfig(name="mcmc", options={"refine_every": "1%"})).make_strategy()
    assert tiny.refine_every == 1                     # 0.2 steps: a period is never 0
    # the same fraction is the same proportion at any length
    for n in (600, 6000):
        assert TrainConfig(iterations=n, strategy=StrategyConfig(options={"refine_stop": "1/4"})).make_strategy().refine_stop == n // 4


@pytest.mark.parametrize("options, match", [
    ({"refine_stop": "3/4 of it"}, "strategy.refine_stop: expected steps .* fraction"),
    ({"refine_stop": "120%"}, "between 0 and 1"),
    ({"reset_every": "1/0"}, "strategy.reset_every"),
    ({"grad_threshold": "10%"}, "grad_threshold"),
])
def test_bad_fractions_are_one_line(options, match):
    with pytest.raises(InputError, match=match) as err:
        TrainConfig(iterations=2000, strategy=StrategyConfig(options=options))
    assert "\n" not in str(err.value)


def test_fraction_schedule_still_keeps_the_final_window():
    with pytest.raises(InputError, match="final 10 %"):
        TrainConfig(iterations=2000, strategy=StrategyConfig(options={"refine_stop": "100%", "reset_every": 0}))


def test_reset_every_zero_stays_zero_when_scaled():
    s = TrainConfig(iterations=600, strategy=StrategyConfig(options={"reset_every": 0})).make_strategy()
    assert s.reset_every == 0 and s.last_topology_change(600).what.startswith("a refinement")
