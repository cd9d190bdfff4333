"""`splatbench bench ab`: the alternating old/new harness. Timings are never checked;
only the protocol (alternation, medians, the quiet-machine rule, clean-up)."""

from __future__ import annotations

import math
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from click.testing import CliRunner

from splatbench.bench import ab
from splatbench.metrics import load as load_rule
from splatbench.metrics.load import LOAD_TAU_S, Load
from splatbench.cli import main

REPO = Path(__file__).resolve().parents[1]


def _load(samples, own_cpu):
    return Load(cpu0=0.0, wall0=0.0, samples=tuple(samples), own_cpu=own_cpu)


def test_ratio_withheld_only_for_the_load_of_others():
    # The 1M run of the last session: the load average climbed from 0.81 to 1.15 over ~40 s while the two
    # workers kept 2 cores busy. Their own share after t s is 2 * (1 - exp(-t / 60)) (0.97 at 40 s), so the
    # others' load is 0.81 (the start), not 1.15: the ratio counts. The old rule (raw load <= 1) withheld it.
    own = _load([(0.0, 0.81), (20.0, 1.0), (40.0, 1.15)], own_cpu=2.0)
    assert math.isclose(own.other, 0.81)
    quiet = ab.summarize("10 8x8", "c11f838", [3.0, 1.0, 2.0, 9.0, 2.0], [1.0, 1.5, 0.5, 1.0, 4.0], own, cores=2)
    assert (quiet.old_median, quiet.new_median, quiet.ratio, quiet.note) == (2.0, 1.0, 2.0, "")
    assert quiet.loads == [0.81, 1.0, 1.15] and quiet.load_other == 0.81 and quiet.own_cpu == 2.0
    # The same samples with no own CPU use: all of it is others' load, 1.15 > 0.5 x 2 cores.
    busy = ab.summarize("10 8x8", "c11f838", [2.0] * 5, [1.0] * 5, _load(own.samples, 0.0), cores=2)
    assert busy.ratio is None and busy.note.startswith("ratio withheld: load of other processes reached 1.15 > 0.5")
    # A neighbour that starts during the runs: 2.9 at 40 s is 1.93 above the workers' own share.
    neighbour = _load([(0.0, 0.3), (40.0, 2.9)], own_cpu=2.0)
    assert math.isclose(neighbour.other, 2.9 - 2.0 * (1 - math.exp(-40.0 / LOAD_TAU_S)))
    assert ab.summarize("10 8x8", "c", [2.0] * 5, [1.0] * 5, neighbour, cores=2).ratio is None
    # A busy machine at the start counts whatever the benchmark did afterwards.
    assert _load([(0.0, 1.2), (1.0, 1.2)], own_cpu=2.0).loaded(cores=2)


def test_load_measures_own_cpu():
    load = Load.start()
    end = time.perf_counter() + 0.3
    while time.perf_counter() < end:  # one busy core for 0.3 s
        pass
    load = load.stop()
    # Single-threaded busy loop: own CPU use is at most 1 core (plus clock granularity), and at least a
    # tenth of one even on a machine shared with several busy neighbours.
    assert 0.1 < load.own_cpu < 1.1 and len(load.samples) == 2
    assert set(load.metrics()) == {"load_before", "load_after", "own_cpu", "own_before", "load_other", "cores",
                                   "loaded"}


def test_bad_commit_is_one_line(tmp_path):
    result = CliRunner().invoke(main, ["bench", "ab", "--against", "no-such-commit", "--synthetic", "10", "8x8",
                                       "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert "--against: 'no-such-commit' is not a commit of" in result.output and "Traceback" not in result.output


def test_alternating_runs_against_head_and_clean_up(monkeypatch):
    monkeypatch.setattr(load_rule, "QUIET_SHARE", -1.0)  # this machine is never quiet enough: the ratio is withheld

    made = []  # this run's temporary tree (others may run `bench ab` on this repository meanwhile)
    real_old_tree = ab.old_tree

    @contextmanager
    def recording_old_tree(repo, commit):
        with real_old_tree(repo, commit) as tree:
            made.append(str(tree))
            yield tree

    monkeypatch.setattr(ab, "old_tree", recording_old_tree)
    (r,) = ab.run_ab(REPO, "HEAD", [(50, 16, 16)], repeats=5, warmup=1)
    assert len(r.old_seconds) == len(r.new_seconds) == 5 and min(r.old_seconds + r.new_seconds) > 0
    # before the workers, before each of the 5 pairs, after the last; the workers reported their CPU time
    assert len(r.loads) == 7 and r.own_cpu > 0 and r.ratio is None and "withheld" in r.note
    # the same rasterizer on both sides, from the same workload file: the same bits
    assert r.identical is True and set(r.max_abs_diff) == {"rgb", "means", "log_scales", "quats", "opacity_logits",
                                                             "sh"} and max(r.max_abs_diff.values()) == 0.0
    trees = subprocess.run(["git", "-C", str(REPO), "worktree", "list"], capture_output=True, text=True).stdout
    assert len(made) == 1 and "splatbench-ab-" in made[0] and made[0] not in trees  # it is gone


def test_own_share_follows_the_kernel_average_of_own_cpu_use():
    # The load average is an exponential moving average (tau 60 s) of runnable threads: a
    # process busy on 2 cores for 120 s from a standstill lifts it by 2·(1 - e^-2) = 1.729;
    # 60 s idle after that leaves 1.729·e^-1 = 0.636. Piecewise-constant use between calls,
    # so the tracker reproduces these closed forms to float64 round-off.

    from splatbench.metrics.load import OwnShare

    t, c = [0.0], [0.0]
    share = OwnShare(clock=lambda: t[0], cpu=lambda: c[0], age_s=None)
    assert share() == 0.0
    t[0], c[0] = 120.0, 240.0
    assert share() == pytest.approx(2 * (1 - math.exp(-2)), rel=1e-12)
    t[0] = 180.0
    assert share() == pytest.approx(2 * (1 - math.exp(-2)) * math.exp(-1), rel=1e-12)


def test_own_load_before_the_section_is_not_counted_as_others():
    # A raster run's warm-up lifts the load average before its timed pairs: with own_before
    # = 0.9 at the start and a load of 1.2 there, others account for 0.3 (quiet), whereas the
    # raw start sample (1.2 > 1.0 on 2 cores) would have marked the run loaded.
    lo = Load(cpu0=0.0, wall0=0.0, samples=((0.0, 1.2), (30.0, 1.5)), own_cpu=1.0, own_before=0.9)
    own_30 = 0.9 * math.exp(-0.5) + 1.0 * (1 - math.exp(-0.5))
    assert lo.other == pytest.approx(max(1.2 - 0.9, 1.5 - own_30), rel=1e-12)
    assert not lo.loaded(2)
    assert Load(cpu0=0.0, wall0=0.0, samples=((0.0, 1.2),), own_cpu=0.0).loaded(2)


def test_outputs_that_differ_are_named(tmp_path):
    """`compare_outputs` says which output moved and by how much; a missing or reshaped one is NaN."""
    rgb = np.zeros((4, 4, 3), np.float32)
    np.savez(tmp_path / "a.npz", rgb=rgb, means=np.ones((3, 3), np.float32))
    np.savez(tmp_path / "b.npz", rgb=rgb + np.float32(2.0 ** -20), means=np.ones((3, 3), np.float32))
    same, diffs = ab.compare_outputs(tmp_path / "a.npz", tmp_path / "b.npz")
    assert not same and diffs == {"rgb": 2.0 ** -20, "means": 0.0}
    np.savez(tmp_path / "c.npz", rgb=rgb[:2])
    same, diffs = ab.compare_outputs(tmp_path / "a.npz", tmp_path / "c.npz")
    assert not same and np.isnan(diffs["rgb"]) and np.isnan(diffs["means"])
    line = ab.format_result(ab.AbResult("w", "HEAD", [0.1] * 5, [0.1] * 5, 0.1, 0.1, identical=False,
                                        max_abs_diff={"rgb": 1e-6, "sh": 3e-5}))
    assert line.endswith("outputs differ: largest |old - new| 3e-05 (sh; rgb 1e-06)")


def test_a_model_workload_is_timed_on_both_sides(monkeypatch):
    """A view of a real trained model (the bundled guitar, small) goes through the same file to both sides."""
    from splatbench.workloads import parse_model

    monkeypatch.setattr(load_rule, "QUIET_SHARE", -1.0)
    spec = parse_model("guitar", views=3, size="48x32")[0]
    (r,) = ab.run_ab(REPO, "HEAD", [spec], repeats=5, warmup=1)
    assert r.workload.startswith("guitar") or "guitar" in r.workload, r.workload
    assert r.identical is True and len(r.new_seconds) == 5
