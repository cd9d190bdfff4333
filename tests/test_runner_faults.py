"""The runner under faults (issue #15): per-run claims, two runners on one
experiment, a runner killed (its workers die with it), SIGTERM to the runner, and
a sweep whose workers and runner are killed at random points.

Everything runs the dummy kind of `tests.kinds_for_tests`, so no rendering is involved.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from splatbench.experiments import expand, load_experiment
from splatbench.experiments.claims import (HEARTBEAT_TIMEOUT, Owner, claim_path, process_start, try_claim)
from splatbench.experiments.store import read_records, read_table

REPO = Path(__file__).resolve().parents[1]
LINE = re.compile(r"^done (\d+), skipped (\d+) \(finished\), (\d+) claimed by another runner, failed (\d+) of (\d+)$")

SWEEP = """
name = "sweep"
kind = "tests.kinds_for_tests:DUMMY"
scenes = ["alpha", "beta"]
seeds = [0, 1, 2, 3]
[base]
sleep = {sleep}
gate = "{gate}"
[axes]
x = [0.0, 1.5]
"""


def experiment(tmp_path: Path, sleep: float, gate: Path | str = "") -> Path:
    path = tmp_path / "sweep.toml"
    path.write_text(SWEEP.format(sleep=sleep, gate=gate))
    return path


def start(path: Path, results: Path, log: Path, workers: int = 2) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "splatbench.experiments.cli", str(path), "--workers", str(workers),
           "--results", str(results), "--no-progress"]
    return subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=open(log, "ab"), start_new_session=True)


def result_files(folder: Path) -> list[Path]:
    return [p for p in folder.glob("*.json") if re.fullmatch(r"[0-9a-f]{16}\.json", p.name)] if folder.is_dir() else []


def workers_of(pid: int, timeout: float = 60.0) -> list[psutil.Process]:
    """The runner's pool workers (spawned processes running ``spawn_main``), once there are any."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            kids = [p for p in psutil.Process(pid).children(recursive=True) if _is_worker(p)]
        except psutil.NoSuchProcess:
            return []
        if kids:
            return kids
        time.sleep(0.05)
    return []


def _is_worker(proc: psutil.Process) -> bool:
    """A live pool worker; a killed one not yet reaped (a zombie: no command line) or one
    gone meanwhile is not."""
    try:
        return "spawn_main" in " ".join(proc.cmdline())
    except psutil.Error:
        return False


def alive(procs: list[psutil.Process]) -> list[int]:
    return [p.pid for p in procs if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]


def assert_complete(folder: Path, ids: set[str]) -> None:
    """Every run done, one file and one table row each, no claims or temporaries left."""
    records = read_records(folder)
    assert set(records) == ids and all(r.status == "done" for r in records.values())
    table = read_table(folder)
    assert sorted(table["run_id"]) == sorted(ids)  # one row per run
    for row in table.to_dict("records"):  # the row is the file's, not another attempt's
        rec = records[row["run_id"]]
        assert (row["worker"], row["started"], row["finished"]) == (rec.worker, rec.started, rec.finished)
    assert not list((folder / "claims").iterdir()), list((folder / "claims").iterdir())
    assert not [p for p in folder.iterdir() if p.name.endswith(".tmp")]


# --------------------------------------------------------------------------- claims
def test_a_claim_is_exclusive_until_released(tmp_path):
    first = try_claim(tmp_path, "r1")
    assert first is not None and first.owner.pid == os.getpid()
    assert try_claim(tmp_path, "r1") is None  # held by a live owner (this process)
    assert json.loads(claim_path(tmp_path, "r1").read_text())["pid"] == os.getpid()
    first.release()
    assert not claim_path(tmp_path, "r1").exists()
    assert try_claim(tmp_path, "r1") is not None


def _plant(folder: Path, run_id: str, owner: Owner, age: float = 0.0) -> None:
    path = claim_path(folder, run_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(owner.text())
    if age:
        os.utime(path, (time.time() - age, time.time() - age))


def test_stale_claims_are_taken_over_and_live_ones_kept(tmp_path):
    host, me = socket.gethostname(), Owner.me()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    cases = {
        "dead_pid": (Owner(host, int(dead), None, "t1", ""), 0.0, True),
        "reused_pid": (Owner(host, os.getpid(), "1", "t2", ""), 0.0, True),  # this pid, another start time
        "live_here": (Owner(host, os.getpid(), process_start(os.getpid()), "t3", ""), 0.0, False),
        "other_host_quiet": (Owner("elsewhere", 1, None, "t4", ""), HEARTBEAT_TIMEOUT + 60, True),
        "other_host_recent": (Owner("elsewhere", 1, None, "t5", ""), 1.0, False),
    }
    for run_id, (owner, age, stale) in cases.items():
        _plant(tmp_path, run_id, owner, age)
        claim = try_claim(tmp_path, run_id)
        assert (claim is not None) == stale, run_id
        now = Owner.parse(claim_path(tmp_path, run_id).read_text())
        assert now == (claim.owner if stale else owner), run_id
        assert now.token != me.token


# --------------------------------------------------------------------------- two runners
def test_two_runners_share_the_grid_and_their_summaries_add_up(tmp_path):
    path = experiment(tmp_path, sleep=0.3)
    results = tmp_path / "results"
    procs = [start(path, results, tmp_path / f"runner{i}.log") for i in range(2)]
    lines = []
    for proc in procs:
        out, _ = proc.communicate(timeout=180)
        assert proc.returncode == 0, (tmp_path / "runner0.log").read_text()[-2000:]
        lines.append(out.decode().strip().splitlines()[-1])
    counts = [tuple(int(g) for g in LINE.match(line).groups()) for line in lines]
    ids = {r.run_id for r in expand(load_experiment(path))}
    for done, skipped, claimed, failed, total in counts:
        assert total == len(ids) and done + skipped + claimed + failed == total and failed == 0, lines
    assert sum(c[0] for c in counts) == len(ids), lines  # every run done once, by one of them
    assert all(c[0] > 0 for c in counts), lines  # both did work (runs take 0.3 s; both start together)
    assert_complete(results / "sweep", ids)


# --------------------------------------------------------------------------- a killed runner
def test_sigkill_of_the_runner_leaves_no_worker_alive(tmp_path):
    path = experiment(tmp_path, sleep=5.0)
    proc = start(path, tmp_path / "results", tmp_path / "runner.log")
    workers = workers_of(proc.pid)
    assert workers, (tmp_path / "runner.log").read_text()[-2000:]
    time.sleep(1.0)  # the workers are inside their runs
    proc.kill()  # the runner only, not its process group
    proc.wait(timeout=10)
    deadline = time.monotonic() + 10.0
    while alive(workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not alive(workers), alive(workers)


def test_sigterm_to_the_runner_stops_its_workers_and_releases_its_claims(tmp_path):
    path = experiment(tmp_path, sleep=5.0)
    results = tmp_path / "results"
    proc = start(path, results, tmp_path / "runner.log")
    workers = workers_of(proc.pid)
    assert workers
    time.sleep(1.0)
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)  # the runner only
    proc.wait(timeout=30)
    assert time.monotonic() - sent < 10.0
    assert proc.returncode == 128 + signal.SIGTERM
    lines = [ln for ln in (tmp_path / "runner.log").read_text().splitlines() if ln.startswith("splatbench:")]
    assert len(lines) == 1 and re.match(r"splatbench: interrupted by SIGTERM; kept 0 runs finished now in \S+; "
                                        r"\d in flight stopped \(they run again next time\)$", lines[0]), lines
    assert "Traceback" not in (tmp_path / "runner.log").read_text()
    assert not alive(workers)
    assert not list((results / "sweep" / "claims").iterdir())


# --------------------------------------------------------------------------- fault injection
def _tree(pid: int) -> str:
    """The runner's process tree, for a failure message."""
    try:
        kids = psutil.Process(pid).children(recursive=True)
        return "; ".join(f"{p.pid} {'worker' if _is_worker(p) else 'other'}" for p in kids)
    except psutil.NoSuchProcess:
        return "(the runner is gone)"


def _wait_for(what: str, condition, proc: subprocess.Popen, log: Path, timeout: float = 300.0):
    """Poll ``condition`` until it returns something true; fail naming ``what`` after
    ``timeout`` s or when the runner exits first. Generous: no verdict rests on speed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        assert proc.poll() is None, (f"the runner exited ({proc.returncode}) before {what}", log.read_text()[-2000:])
        time.sleep(0.05)
    gate = sorted(p.name for p in (log.parent / "gate").iterdir())
    raise AssertionError(f"timed out waiting for {what}: processes {_tree(proc.pid)}; gate {gate}; "
                         f"log {log.read_text()[-2000:]}")


def _fault_injection(tmp_path: Path, rounds: int, seed: int) -> None:
    """Kill workers (SIGKILL) mid-run and stop the runner (SIGTERM) mid-sweep, round after
    round, then finish: every run is done exactly once -- a result, once written, is never
    replaced (no run is redone) -- and nothing is corrupt.

    The faults land mid-sweep by construction, not by timing: every run waits at a gate
    (the dummy kind's ``gate``) for a token this test hands out, one per round, so a round
    ends with at most one more run done, a worker is killed only while it is inside a run,
    and the runner is stopped while runs are still blocked. Only the final, undisturbed
    runner finds the gate open."""
    gate = tmp_path / "gate"
    gate.mkdir()
    path = experiment(tmp_path, sleep=0.0, gate=gate)
    results, log = tmp_path / "results", tmp_path / "runner.log"
    folder = results / "sweep"
    ids = {r.run_id for r in expand(load_experiment(path))}
    assert rounds < len(ids)  # one token a round: the grid cannot finish before the last runner
    rng = random.Random(seed)
    first_seen: dict[str, str] = {}
    kills = 0

    def snapshot() -> int:
        for p in result_files(folder):
            text = p.read_text()
            record = json.loads(text)  # always whole
            if record["status"] == "done":
                first_seen.setdefault(p.stem, text)
        return len(first_seen)

    def waiting(proc: subprocess.Popen) -> list[psutil.Process]:
        """The runner's workers that are inside a run, blocked at the gate."""
        marked = {int(p.name.split("-")[1]) for p in gate.glob("waiting-*")}
        return [w for w in workers_of(proc.pid, timeout=0.1) if w.pid in marked]

    procs: list[subprocess.Popen] = []
    try:
        for round_ in range(rounds):
            proc = start(path, results, log)
            procs.append(proc)
            broken: set[int] = set()  # the workers of a pool broken by the kill (it terminates them all)
            if round_ == 0 or rng.random() < 0.5:  # a worker dies mid-run (at least once)
                victim = rng.choice(_wait_for("a run in flight", lambda: waiting(proc), proc, log))
                broken = {w.pid for w in workers_of(proc.pid, timeout=0.1)}
                victim.kill()
                kills += 1
            done = snapshot()
            # the token goes to a run of a live pool: one of a broken pool could take it and die
            _wait_for("a run in flight", lambda: [w for w in waiting(proc) if w.pid not in broken], proc, log)
            (gate / f"token-{round_:03d}").touch()  # one run may finish
            _wait_for("the released run's result", lambda: snapshot() > done, proc, log)
            _wait_for("a run in flight again", lambda: waiting(proc), proc, log)
            workers = workers_of(proc.pid, timeout=0.1)
            assert proc.poll() is None, "the runner finished while its runs were held at the gate"
            proc.send_signal(signal.SIGTERM)  # mid-sweep: every other run is held at the gate
            proc.wait(timeout=60)
            assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, log.read_text()[-2000:])
            deadline = time.monotonic() + 10.0
            while alive(workers) and time.monotonic() < deadline:
                time.sleep(0.1)
            assert not alive(workers), "a worker outlived its runner"
            snapshot()
    finally:  # a failed check leaves no runner (its session: its workers too) blocked at the gate
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
    assert kills >= 1
    assert len(first_seen) <= rounds < len(ids)  # by construction: one token a round
    (gate / "open").touch()
    proc = start(path, results, log)  # undisturbed: finishes the grid (failed runs are retried)
    out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 0, log.read_text()[-3000:]
    snapshot()
    assert set(first_seen) == ids
    for run_id, text in first_seen.items():
        assert (folder / f"{run_id}.json").read_text() == text, f"run {run_id} was done twice"
    assert_complete(folder, ids)
    assert "Traceback" not in log.read_text(), log.read_text()[log.read_text().index("Traceback") - 200:][:3000]


def test_random_worker_kills_and_runner_sigterms_end_with_every_run_done_once(tmp_path):
    _fault_injection(tmp_path, rounds=3, seed=15)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
def test_fault_injection_many_rounds(tmp_path, seed):
    _fault_injection(tmp_path, rounds=8, seed=seed)


def test_a_dead_worker_the_pool_misses_breaks_the_pool_after_the_grace(monkeypatch):
    """CPython's process pool can miss a worker SIGKILLed while it held a queue lock and then wait
    forever; `LocalExecutor.wait` breaks the pool itself once a worker has lain dead for the grace."""
    import concurrent.futures as cf
    import time
    from types import SimpleNamespace

    from splatbench.experiments import executors

    monkeypatch.setattr(executors, "DEAD_WORKER_POLL", 0.05)
    monkeypatch.setattr(executors, "DEAD_WORKER_GRACE", 0.3)
    ex = executors.LocalExecutor.__new__(executors.LocalExecutor)
    ex._dead_since, ex.stalled = None, False
    alive = SimpleNamespace(exitcode=None)
    ex.pool = SimpleNamespace(_processes={1: alive})
    fut = cf.Future()
    fut.set_running_or_notify_cancel()
    assert ex.wait([fut], timeout=0.5) == set() and not ex.stalled  # all alive: nothing done, nothing broken
    ex.pool._processes[2] = SimpleNamespace(exitcode=-9)  # killed, unnoticed
    t0 = time.monotonic()
    assert ex.wait([fut], timeout=30) == set() and ex.stalled
    assert 0.3 <= time.monotonic() - t0 < 5  # after the grace, long before the timeout
    assert not fut.done()  # the pool's own futures are left to the pool (setting them races with it)
