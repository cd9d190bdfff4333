"""SIGTERM and SIGINT stop `splatbench train` cleanly (issue #15), and Ctrl-C (SIGINT
to the process group) stops a Dask `splatbench run` with one line, tested on real
processes. `train`: one line naming the checkpoint kept, exit status 128 + signal, no native
stack from pycolmap's glog handler, within seconds. A COLMAP-layout dataset is used
on purpose: loading it imports pycolmap, whose import installed the handler that
dumped a stack (and sometimes hung) on SIGTERM.
"""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from splatbench import Gaussians
from splatbench.interrupt import TRACKER_WARNINGS

REPO = Path(__file__).resolve().parents[1]
SPLATBENCH = [sys.executable, "-c", "from splatbench.cli import main; main(prog_name='splatbench')"]
KEPT = re.compile(r"^splatbench: interrupted by (SIGTERM|SIGINT); kept the last checkpoint (\S+) "
                  r"\(the model after (\d+) of 5000 steps; resume with --resume (\S+)\)$")
#: Seconds from the signal to the exit: the step in progress finishes (well under a
#: second at 32 px), the checkpoint is written; the CLI then skips interpreter teardown.
EXIT_WITHIN = 10.0


@pytest.fixture(scope="module")
def colmap_dataset(tmp_path_factory) -> Path:
    """The `diffuse` scene rendered as a COLMAP-layout dataset (sparse/0), 32 px, 8 views."""
    from splatbench.scenes.render import render_dataset

    out = tmp_path_factory.mktemp("signals") / "diffuse-32"
    render_dataset("diffuse", out, resolution=32, views=8, spp=4, progress=False)
    assert (out / "sparse" / "0" / "cameras.bin").is_file()
    return out


def _train(dataset: Path, out: Path) -> subprocess.Popen:
    cmd = [*SPLATBENCH, "train", str(dataset), "--set", "iterations=5000", "--out", str(out), "--quiet"]
    return subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _check_stopped(proc: subprocess.Popen, signum: int, sent: float) -> Path:
    """The process exits in time with one line naming a whole checkpoint; returns it."""
    out, err = proc.communicate(timeout=60)
    waited = time.monotonic() - sent
    lines = [line for line in err.decode().splitlines() if line.strip()]
    assert waited < EXIT_WITHIN, f"exit took {waited:.1f} s: {lines}"
    assert proc.returncode == 128 + signum, (proc.returncode, lines)
    assert len(lines) == 1, lines  # no native stack ("@ 0x..."), no traceback
    match = KEPT.match(lines[0])
    assert match and match.group(1) == signal.Signals(signum).name, lines[0]
    ply = Path(match.group(2))
    assert ply.is_file() and ply.name == f"iteration_{match.group(3)}.ply"
    assert Path(match.group(4)) == ply.with_suffix(".pt") and ply.with_suffix(".pt").is_file()  # resumable
    assert len(Gaussians.from_ply(ply)) > 0  # a whole, readable model
    return ply


@pytest.mark.parametrize("signum, trial", [(signal.SIGTERM, 0), (signal.SIGTERM, 1), (signal.SIGINT, 0)])
def test_a_stop_signal_keeps_a_checkpoint_and_prints_one_line(tmp_path, colmap_dataset, signum, trial):
    out = tmp_path / "run"
    proc = _train(colmap_dataset, out)
    deadline = time.monotonic() + 120
    while not (out / "config.toml").is_file() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # config.toml: the dataset (and pycolmap) is loaded
    assert proc.poll() is None, proc.communicate()[1].decode()[-2000:]
    time.sleep(random.Random(trial).uniform(0.0, 3.0))  # in the warm-up, or between or inside steps
    sent = time.monotonic()
    proc.send_signal(signum)
    _check_stopped(proc, signum, sent)
    assert not (out / "point_cloud.ply").exists()


@pytest.mark.slow
def test_timeout_sigterm_20_of_20(tmp_path, colmap_dataset):
    """The issue's must-show, as written (progress bar on): ``timeout -s TERM 8
    splatbench train DATA --set iterations=5000`` exits within 10 s with one line naming
    the checkpoint and no native stack, 20 times out of 20."""
    ok = 0
    for trial in range(20):
        out = tmp_path / f"run{trial}"
        cmd = ["timeout", "-s", "TERM", "8", *SPLATBENCH, "train", str(colmap_dataset), "--set",
               "iterations=5000", "--out", str(out)]
        t0 = time.monotonic()
        proc = subprocess.run(cmd, cwd=REPO, capture_output=True, timeout=60)
        elapsed = time.monotonic() - t0
        lines = [ln for ln in re.split(r"[\r\n]", proc.stderr.decode()) if ln.strip()]
        assert elapsed < 10.0, (trial, elapsed, lines[-3:])
        assert proc.returncode == 124, (trial, proc.returncode, lines[-3:])  # timeout's status once it signalled
        assert lines and KEPT.match(lines[-1]), (trial, lines[-3:])
        # tqdm's progress bar, and the init note said before it (which start the run took)
        others = [ln for ln in lines[:-1] if not ln.startswith(("train: ", "init auto: "))]
        assert not others, (trial, others[:12])  # no native stack ("@ 0x..."), no traceback
        assert Path(KEPT.match(lines[-1]).group(2)).is_file()
        ok += 1
    print(f"timeout -s TERM 8 splatbench train: {ok} of 20 stopped cleanly")
    assert ok == 20


def test_sigterm_stops_bench_and_its_workload_process(tmp_path):
    """`bench raster` times each workload in a child process: SIGTERM ends both."""
    import psutil

    cmd = [*SPLATBENCH, "bench", "raster", "--synthetic", "20000", "256x256", "--repeats", "50",
           "--out", str(tmp_path / "b")]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline, children = time.monotonic() + 120, []
    while not children and proc.poll() is None and time.monotonic() < deadline:
        children = psutil.Process(proc.pid).children()
        time.sleep(0.05)
    assert children, proc.communicate()[1].decode()[-2000:]
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert time.monotonic() - sent < EXIT_WITHIN
    assert proc.returncode == 128 + signal.SIGTERM
    assert err.decode().strip().splitlines()[-1] == "splatbench: interrupted by SIGTERM; nothing kept"
    assert "Traceback" not in err.decode()
    time.sleep(0.5)
    assert not [c for c in children if c.is_running() and c.status() != psutil.STATUS_ZOMBIE]


# --------------------------------------------------------------------------- pycolmap
_KILL_SELF = "import os, signal; {imp}; os.kill(os.getpid(), signal.SIGTERM); import time; time.sleep(30)"


def test_import_pycolmap_leaves_sigterm_to_python():
    """Through `import_pycolmap`, SIGTERM ends the process as the default action does:
    status -SIGTERM and nothing on stderr (glog's handler printed a native stack)."""
    imp = "from splatbench.interrupt import import_pycolmap; import_pycolmap()"
    proc = subprocess.run([sys.executable, "-c", _KILL_SELF.format(imp=imp)], capture_output=True, timeout=60)
    assert proc.returncode == -signal.SIGTERM, proc.stderr.decode()[-2000:]
    assert proc.stderr.decode().strip() == ""


def test_plain_pycolmap_import_is_what_needed_fixing():
    """The control: a bare ``import pycolmap`` replaces Python's SIGTERM handling (if
    this starts passing with a clean exit, pycolmap stopped installing glog's handler
    and `import_pycolmap` could go)."""
    proc = subprocess.run([sys.executable, "-c", _KILL_SELF.format(imp="import pycolmap")], capture_output=True,
                          timeout=60, env={**os.environ, "GLOG_logtostderr": "1"})
    assert proc.returncode != -signal.SIGTERM or proc.stderr.strip(), "glog's handler no longer installed"


# --------------------------------------------------------------------------- Dask runner
#: The runner's note of what it will run (`splatbench.experiments.runner`: printed as it starts, with or without
#: a progress bar).
RUNNER_NOTE = re.compile(r"^\w+: \d+ runs.*, \d+ already done.*, \d+ to run \(")
RUN_STOPPED = re.compile(r"^splatbench: interrupted by SIGINT; kept (\d+) runs finished now in (\S+); (\d+) in flight "
                         r"stopped \(they run again next time\)$")


def _descendants(pid: int) -> list:
    import psutil

    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


@pytest.mark.parametrize("executor, moment, after", [("dask", "workers starting", 0.0), ("dask", "workers starting", 0.5),
                                                     ("dask", "runs in flight", 0.0), ("local", "runs in flight", 0.0),
                                                     ("local", "workers starting", 0.0)])
def test_ctrl_c_stops_a_run_with_one_line(tmp_path, executor, moment, after):
    """Ctrl-C in a terminal sends SIGINT to the whole process group: the runner, its
    worker processes (Dask's or the local pool's) and any still importing. The runner prints one line and exits 130;
    no worker prints a KeyboardInterrupt or CancelledError traceback, none outlives it.
    The moments are found, not timed: the first worker process has appeared (it is still
    importing; ``after`` s later, most likely still importing); every worker holds a run,
    waiting at a gate this test never opens. The local pool's semaphores are unlinked before
    the runner's fast exit (`splatbench.cli._release_semaphores`): without that, about 1 run in
    6 under load printed the resource tracker's "leaked semaphore objects" warning after the line."""
    import psutil

    gate = tmp_path / "gate"
    gate.mkdir()
    grid = tmp_path / "grid.toml"
    grid.write_text(f'name = "ctrlc"\nkind = "tests.kinds_for_tests:DUMMY"\nscenes = ["alpha"]\nseeds = [0, 1, 2, 3]\n'
                    f'[base]\ngate = "{gate}"\n')
    cmd = [*SPLATBENCH, "run", str(grid), "--executor", executor, "--workers", "2", "--results",
           str(tmp_path / "results"), "--no-progress"]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.monotonic() + 180
    while proc.poll() is None and time.monotonic() < deadline:
        if moment == "workers starting":
            if any("spawn_main" in " ".join(p.cmdline()) for p in _descendants(proc.pid) if p.is_running()):
                break
        elif len(list(gate.glob("waiting-*"))) == 2:
            break
        time.sleep(0.01)
    time.sleep(after)
    assert proc.poll() is None, proc.communicate()[1].decode()[-2000:]
    family = _descendants(proc.pid)
    # the resource tracker runs with its warnings ignored (`start_quiet_resource_tracker`):
    # one in about 100 interrupted runs under load otherwise printed its "leaked semaphore" and
    # "No such file or directory" warnings for a semaphore a stopped worker had half released
    trackers = [p.cmdline() for p in family if p.is_running() and "resource_tracker" in " ".join(p.cmdline())]
    assert trackers and all(f"-W{TRACKER_WARNINGS}" in args for args in trackers), trackers
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    # the runner's own first note ("NAME: N runs, ... to run") comes before any signal; then one line
    lines = [line for line in err.decode().splitlines() if line.strip() and not RUNNER_NOTE.match(line)]
    assert proc.returncode == 128 + signal.SIGINT, (proc.returncode, lines[-12:])
    assert len(lines) == 1, lines[:40]  # no traceback from a worker, the scheduler or the runner
    match = RUN_STOPPED.match(lines[0])
    assert match, lines[0]
    assert match.group(1) == "0"  # no run got through the gate
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and [p for p in family if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]:
        time.sleep(0.1)
    assert not [p for p in family if p.is_running() and p.status() != psutil.STATUS_ZOMBIE], family
