"""A train run whose worker was killed continues from its latest checkpoint when the grid runs
again (splatbench.experiments.train_resume), to the same numbers bit for bit; a checkpoint the
trainer refuses is removed and the run starts over, saying why in one line.

Runs go through `execute_run`, the function each runner worker runs, in this process, so that
the thresholds (`CHECKPOINT_FROM`, `CHECKPOINT_EVERY`) can be lowered for a 10-step run and a
kill can be simulated: an exception no `except Exception` catches, raised before a step, leaves
what SIGKILL leaves (the checkpoints written so far, no record, no checkpoint of its own).
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import pytest
import torch

from splatbench.experiments import parse_experiment
from splatbench.experiments import train_resume
from splatbench.experiments.grid import expand
from splatbench.experiments.one_run import RunContext, execute_run
from splatbench.experiments.store import WORK_DIR, read_record, result_path
from splatbench.experiments.train_kind import Prepared
from splatbench.train.loop import Trainer
from tests.test_dry_run_inputs import llff_capture

ITERATIONS, EVERY, KILLED_AT = 10, 3, 8  # checkpoints at 3 and 6; killed before step 8 (its 9th)
#: What a resumed run may record differently from a straight one: times, load and memory, which
#: depend on when it ran, and what says it was resumed.
UNTIMED = {"train_seconds", "cpu_seconds", "render_ms_per_view", "peak_rss_mb", "run_peak_rss_mb", "load_before",
           "load_after", "load_other", "time_loaded", "resumed_step"}


class Killed(BaseException):
    """The simulated SIGKILL (a BaseException, as `Interrupted` is, but not one the trainer handles)."""


@pytest.fixture
def grid(tmp_path):
    llff_capture(tmp_path / "cap")

    def runs(seed: int = 0):
        text = f"""
name = "long"
kind = "train"
scenes = [{{ name = "cap", path = "{tmp_path / 'cap'}", downscale = 16 }}]
seeds = [{seed}]
[base]
iterations = {ITERATIONS}
log_every = 1
init.method = "random"
init.random_points = 200
eval.lpips_net = "none"
"""
        spec = parse_experiment(tomllib.loads(text), source="long.toml", default_name="long")
        (run,) = expand(spec)
        return run
    return runs


def attempt(run, results: Path, *, kill_at: int | None = None, monkeypatch=None) -> dict | None:
    """One attempt of ``run`` as a worker makes it (the record, as a dict); ``kill_at``: killed
    before the step of that 0-based index (then None: no record)."""
    context = RunContext(prepared=Prepared(datasets=results / "datasets"))
    if kill_at is None:
        return execute_run(run, str(results), context)
    step = Trainer.step

    def dies(self, *args, **kwargs):  # Trainer.step's own arguments passed through (its evaluation hook)
        if self.step_index == kill_at:
            raise Killed()
        return step(self, *args, **kwargs)
    with monkeypatch.context() as patch:
        patch.setattr(Trainer, "step", dies)
        with pytest.raises(Killed):
            execute_run(run, str(results), context)
    assert not result_path(results, run.experiment, run.run_id).exists()
    return None


def work(results: Path, run) -> Path:
    return results / run.experiment / WORK_DIR / run.run_id


def test_a_killed_run_resumes_from_its_latest_checkpoint_to_the_same_numbers(grid, tmp_path, monkeypatch, capsys):
    run = grid()
    monkeypatch.setattr(train_resume, "CHECKPOINT_EVERY", EVERY)
    monkeypatch.setattr(train_resume, "CHECKPOINT_FROM", 1)  # every run here is "long"
    straight = attempt(run, tmp_path / "straight")
    assert straight["status"] == "done", straight.get("error")
    assert not (work(tmp_path / "straight", run) / "checkpoints").exists()  # removed once the run is done
    # writing checkpoints changes no number: a run that writes none (under the threshold) is the same
    monkeypatch.setattr(train_resume, "CHECKPOINT_FROM", ITERATIONS + 1)
    plain = attempt(run, tmp_path / "plain")
    assert plain["curves"]["loss"] == straight["curves"]["loss"] and len(plain["curves"]["loss"]) == ITERATIONS
    assert (work(tmp_path / "plain", run) / "point_cloud.ply").read_bytes() == \
        (work(tmp_path / "straight", run) / "point_cloud.ply").read_bytes()
    monkeypatch.setattr(train_resume, "CHECKPOINT_FROM", 1)

    killed = tmp_path / "killed"
    attempt(run, killed, kill_at=KILLED_AT, monkeypatch=monkeypatch)
    # the latest checkpoint alone is kept (step 3's removed once step 6's was written)
    assert sorted(p.name for p in (work(killed, run) / "checkpoints").iterdir()) == ["iteration_6.ply", "iteration_6.pt"]
    before = torch.load(work(killed, run) / "checkpoints" / "iteration_6.pt", weights_only=True)["extra"]["loop_seconds"]
    capsys.readouterr()
    resumed = attempt(run, killed)
    assert resumed["status"] == "done", resumed.get("error")
    lines = capsys.readouterr().err.splitlines()
    assert f"{run.run_id}: resumed from step 6 of {ITERATIONS} ({work(killed, run) / 'checkpoints' / 'iteration_6.pt'})" \
        in lines
    assert resumed["metrics"]["resumed_step"] == 6 and straight["metrics"]["resumed_step"] is None
    assert resumed["notes"][0].startswith("resumed from ") and resumed["notes"][0].endswith(" at step 6 of 10")
    # bit-identical: the final model's bytes, every curve, every metric but the times and load
    assert (work(killed, run) / "point_cloud.ply").read_bytes() == \
        (work(tmp_path / "straight", run) / "point_cloud.ply").read_bytes()
    assert resumed["curves"] == straight["curves"]
    assert {k: v for k, v in resumed["metrics"].items() if k not in UNTIMED} == \
        {k: v for k, v in straight["metrics"].items() if k not in UNTIMED}
    # the run's recorded config (what its id hashes) is the grid's: checkpoint_every stays 0 there
    assert resumed["config"] == straight["config"] and resumed["config"]["checkpoint_every"] == 0
    assert resumed["run_id"] == run.run_id
    assert not (work(killed, run) / "checkpoints").exists()
    # its loop time sums both attempts': the killed one's 6 steps (saved in the checkpoint) and this one's 4
    assert 0 < round(before, 3) < resumed["metrics"]["train_seconds"]
    assert read_record(result_path(killed, run.experiment, run.run_id)).metrics["resumed_step"] == 6


@pytest.mark.parametrize("damage", ["truncated", "another config"])
def test_a_refused_checkpoint_is_removed_and_the_run_starts_over(grid, tmp_path, monkeypatch, capsys, damage):
    run = grid()
    monkeypatch.setattr(train_resume, "CHECKPOINT_EVERY", EVERY)
    monkeypatch.setattr(train_resume, "CHECKPOINT_FROM", 1)
    straight = attempt(run, tmp_path / "straight")
    results = tmp_path / "results"
    if damage == "truncated":
        attempt(run, results, kill_at=KILLED_AT, monkeypatch=monkeypatch)
        pt = work(results, run) / "checkpoints" / "iteration_6.pt"
        pt.write_bytes(pt.read_bytes()[: pt.stat().st_size // 2])
        reason = "is not a readable checkpoint"
    else:  # seed 1's checkpoint in seed 0's folder: the trainer refuses the config, naming the field
        other = grid(seed=1)
        attempt(other, tmp_path / "other", kill_at=KILLED_AT, monkeypatch=monkeypatch)
        shutil.copytree(work(tmp_path / "other", other) / "checkpoints", work(results, run) / "checkpoints")
        reason = "was written with seed=1, strategy.seed=1; this run has seed=0, strategy.seed=0"
    capsys.readouterr()
    again = attempt(run, results)
    assert again["status"] == "done", again.get("error")
    said = [line for line in capsys.readouterr().err.splitlines() if "started over" in line]
    assert len(said) == 1 and said[0].startswith(f"{run.run_id}: started over: the checkpoint left by an earlier "
                                                 f"attempt was refused (resume: ") and reason in said[0], said
    assert again["notes"][0] == said[0].removeprefix(f"{run.run_id}: ")  # the record says why too
    assert again["metrics"]["resumed_step"] is None
    assert (work(results, run) / "point_cloud.ply").read_bytes() == \
        (work(tmp_path / "straight", run) / "point_cloud.ply").read_bytes()
    assert again["curves"] == straight["curves"]
    assert not (work(results, run) / "checkpoints").exists()
