"""Forward+backward of this checkout against an older commit, timed in alternation.

`run_ab` checks the old commit out into a temporary `git worktree`, starts one
worker process per side (the same interpreter; ``PYTHONPATH`` selects the tree),
builds the workload in each, warms both up (kernels compile or load from
``~/.drjit``), then asks them for one timed forward+backward at a time, old and new
in turn, so that both sides see the same machine over the same minutes. Each
worker runs Dr.Jit and torch on ``threads`` threads. The ratio old/new of the
medians is reported only when the load of *other* processes stayed low: the
1-minute load average is sampled before the workers start, between the pairs of
runs and at the end, and the workers' own share of it (from the CPU seconds they
report) is subtracted by `splatbench.metrics.load.Load`, the rule the ``raster`` run
kind uses too. Otherwise the ratio is withheld (`AbResult.ratio` is None) and
`AbResult.note` says why. docs/benchmarks.md shows the command.

The workload (synthetic, an npz such as the bundled garden, or a view of a trained
model) is built once, here, and saved with `splatbench.workloads.save_npz`; both
workers read it with `load_npz` and time `splatbench.rasterize`, which both trees
provide (the worker must not import this module, which the old tree may not have).
Each side also writes its image and gradients of d(sum rgb) once, untimed; the result
says whether they are bit-identical and, if not, the largest difference.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from splatbench.metrics import load as load_rule
from splatbench.metrics.load import Load, usable_cores
from splatbench.errors import InputError, SplatbenchError

WORKER = r"""
import json, sys, time
spec = json.loads(sys.argv[1])
import drjit as dr, numpy as np, torch
import inspect
import splatbench
from splatbench.workloads import load_npz
dr.set_thread_count(spec["threads"]); torch.set_num_threads(spec["threads"])
w = load_npz(spec["npz"])
g = w.gaussians
names = ("means", "log_scales", "quats", "opacity_logits", "sh")
_opt = inspect.signature(splatbench.rasterize).parameters.get("options")
if _opt is not None and _opt.kind is not _opt.VAR_KEYWORD:  # typed options (this side may be older: **options)
    from splatbench.raster.options import RasterOptions
    CPU = {"options": RasterOptions(device="cpu")}
else:
    CPU = {"device": "cpu"}
leaves = [torch.tensor(getattr(g, k)).requires_grad_(True) for k in names]

def run(save=None):
    t0 = time.perf_counter()
    rgb, _, _, _ = splatbench.rasterize(*leaves, w.camera, **CPU)
    rgb.sum().backward()
    seconds = time.perf_counter() - t0
    if save:
        np.savez(save, rgb=rgb.detach().numpy(), **{k: p.grad.numpy() for k, p in zip(names, leaves)})
    for p in leaves:
        p.grad = None
    return seconds

for _ in range(spec["warmup"]):
    run()
run(spec["outputs"])  # the image and gradients of d(sum rgb), untimed, for the comparison of the two sides
def cpu():
    return time.process_time()  # all threads, ns resolution (os.times counts 10 ms ticks)

print(json.dumps({"ready": splatbench.__file__, "cpu": cpu()}), flush=True)
for line in sys.stdin:
    if line.strip() != "run":
        break
    print(json.dumps({"seconds": run(), "cpu": cpu()}), flush=True)
"""


class AbError(SplatbenchError):
    """The old tree could not be checked out, or a worker failed."""


@dataclass(frozen=True)
class AbResult:
    """One workload timed old vs new. Seconds per forward+backward, in run order."""

    workload: str               # "N WxH"
    against: str                # the old commit, as given
    old_seconds: list[float]
    new_seconds: list[float]
    old_median: float
    new_median: float
    loads: list[float] = field(default_factory=list)  # 1-minute load average: before the workers start,
    #                                                   before each pair of runs, after the last
    own_cpu: float = 0.0        # cores the two workers kept busy, from their start to the last run
    load_other: float = 0.0     # estimated load of other processes (`splatbench.metrics.load.Load.other`)
    cores: int = 0              # usable cores
    ratio: float | None = None  # old_median / new_median; None when the machine was not quiet
    note: str = ""              # why the ratio is withheld ("" when it is reported)
    # Median CPU seconds per run (all threads of a worker, from its os.times). Indicative only, but less
    # sensitive to neighbours than wall time with --threads 1 (with more, idle Dr.Jit workers spin and count).
    old_cpu_median: float = 0.0
    new_cpu_median: float = 0.0
    # The two sides' image [H, W, 3] and gradients of d(sum rgb) (all five groups), compared once
    identical: bool | None = None    # every value bit-identical (None: not compared)
    max_abs_diff: dict = field(default_factory=dict)  # output -> largest |old - new| ("rgb", "means", ...)


@contextmanager
def old_tree(repo: Path, commit: str):
    """A detached temporary worktree of ``commit`` (removed afterwards)."""
    probe = subprocess.run(["git", "-C", str(repo), "rev-parse", "--verify", "--quiet", f"{commit}^{{commit}}"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        raise InputError(f"--against: {commit!r} is not a commit of {repo}")
    parent = Path(tempfile.mkdtemp(prefix="splatbench-ab-"))
    tmp = parent / "tree"
    add = subprocess.run(["git", "-C", str(repo), "worktree", "add", "--detach", str(tmp), commit],
                         capture_output=True, text=True)
    if add.returncode != 0:
        raise AbError(f"git worktree add {commit} failed: {add.stderr.strip().splitlines()[-1:]}")
    try:
        yield tmp
    finally:
        subprocess.run(["git", "-C", str(repo), "worktree", "remove", "--force", str(tmp)], capture_output=True)
        shutil.rmtree(parent, ignore_errors=True)


class Worker:
    """One persistent worker process running ``script`` (default `WORKER`) with the
    splatbench of ``tree``. The script prints ``{"ready": splatbench.__file__}``, then
    answers each ``run`` line on stdin with ``{"seconds": ...}``."""

    def __init__(self, tree: Path, spec: dict, script: str = WORKER) -> None:
        env = {**os.environ, "PYTHONPATH": str(tree)}
        self.tree = tree
        self.cpu = 0.0  # the worker's CPU seconds at its last reply
        self.cpu_runs: list[float] = []  # CPU seconds of each timed run (all the worker's threads)
        self.stderr = tempfile.TemporaryFile(mode="w+")  # a file, not a pipe: a full pipe would block the worker
        self.proc = subprocess.Popen([sys.executable, "-c", script, json.dumps(spec)], cwd=str(tree), env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.stderr, text=True)
        ready = self._read()
        if not str(ready.get("ready", "")).startswith(str(tree)):
            self.close()
            raise AbError(f"worker for {tree} imported splatbench from {ready.get('ready')!r}, not from that tree")

    def _read(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            self.stderr.seek(0)
            err = self.stderr.read().strip().splitlines()
            raise AbError(f"worker for {self.tree} exited with {code}: {err[-1] if err else 'no output'}")
        reply = json.loads(line)
        self.cpu = float(reply.get("cpu", self.cpu))
        return reply

    def run(self) -> float:
        self.proc.stdin.write("run\n")
        self.proc.stdin.flush()
        before = self.cpu
        seconds = float(self._read()["seconds"])
        self.cpu_runs.append(self.cpu - before)
        return seconds

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=60)
        self.stderr.close()


def run_ab(repo: Path, against: str, workloads: list, *, repeats: int = 5,
           warmup: int = 2, threads: int = 2, seed: int = 0, progress=None) -> list[AbResult]:
    """Time each workload old vs new, alternating, and compare the two sides' outputs.

    Args:
        repo: a checkout of this repository (the new side is the tree this module
            was imported from). against: the old commit. workloads: `WorkloadSpec`s, or
            ``(n, width, height)`` for a synthetic one of ``seed``. repeats: timed runs per
            side (>= 5 for a reported median). warmup: untimed runs per side first.
    """
    from splatbench.workloads import WorkloadSpec, save_npz

    if repeats < 5:
        raise InputError(f"--repeats: expected >= 5 timed runs per side, got {repeats}")
    new_tree = Path(__file__).resolve().parents[2]
    results = []
    specs = [w if isinstance(w, WorkloadSpec) else WorkloadSpec("synthetic", n=w[0], width=w[1], height=w[2], seed=seed)
             for w in workloads]
    with old_tree(repo, against) as old, tempfile.TemporaryDirectory(prefix="splatbench-ab-io-") as io:
        for k_spec, ws in enumerate(specs):
            workload = ws.build()
            label = ws.label or (f"{ws.n} {ws.width}x{ws.height}" if ws.kind == "synthetic" else workload.name)
            npz = Path(io) / f"workload{k_spec}.npz"
            save_npz(workload, npz)
            del workload
            outputs = [Path(io) / f"outputs{k_spec}-{side}.npz" for side in ("old", "new")]
            spec = {"npz": str(npz), "threads": threads, "warmup": warmup}
            if progress:
                progress(f"{label}: building and warming up both sides ...")
            sides = []
            load = Load.start(cpu=0.0)  # before the workers exist: all their CPU time is the benchmark's own
            try:
                sides.append(Worker(old, {**spec, "outputs": str(outputs[0])}))
                sides.append(Worker(new_tree, {**spec, "outputs": str(outputs[1])}))
                old_s, new_s = [], []
                for k in range(repeats):
                    load = load.sample()
                    order = (0, 1) if k % 2 == 0 else (1, 0)  # neither side always goes first
                    for side in order:
                        (old_s if side == 0 else new_s).append(sides[side].run())
                load = load.stop(cpu=sum(w.cpu for w in sides))
            finally:
                for w in sides:
                    w.close()
            result = summarize(label, against, old_s, new_s, load)
            identical, diffs = compare_outputs(*outputs)
            results.append(dataclasses.replace(result, old_cpu_median=statistics.median(sides[0].cpu_runs),
                                               new_cpu_median=statistics.median(sides[1].cpu_runs),
                                               identical=identical, max_abs_diff=diffs))
    return results


def compare_outputs(old: Path, new: Path) -> tuple[bool, dict[str, float]]:
    """(bit-identical, output -> largest |old - new|) of the two sides' saved image and gradients."""
    import numpy as np

    with np.load(old) as a, np.load(new) as b:
        keys = sorted(set(a.files) | set(b.files))
        diffs, same = {}, True
        for k in keys:
            if k not in a.files or k not in b.files or a[k].shape != b[k].shape:
                diffs[k], same = float("nan"), False
                continue
            same = same and bool(np.array_equal(a[k], b[k]))
            diffs[k] = float(np.max(np.abs(a[k].astype(np.float64) - b[k].astype(np.float64)))) if a[k].size else 0.0
    return same, diffs


def summarize(label: str, against: str, old_s: list[float], new_s: list[float], load: Load,
              cores: int | None = None) -> AbResult:
    """Medians, and the ratio old/new unless the others' load was too high (`Load.loaded`)."""
    cores = usable_cores() if cores is None else cores
    old_med, new_med = statistics.median(old_s), statistics.median(new_s)
    other = round(load.other, 2)
    note = "" if not load.loaded(cores) else (
        f"ratio withheld: load of other processes reached {other} > {load_rule.QUIET_SHARE} x {cores} cores "
        f"(1-minute load average up to {max(load.loads)}, the workers' own {load.own_cpu:.2f} cores discounted; "
        f"not a quiet machine)")
    return AbResult(label, against, old_s, new_s, old_med, new_med, load.loads, round(load.own_cpu, 2), other,
                    cores, None if note else round(old_med / new_med, 3), note)


def format_result(r: AbResult) -> str:
    ratio = f"{r.ratio:.2f}x" if r.ratio is not None else r.note
    if r.identical is None:
        outputs = ""
    elif r.identical:
        outputs = "; image and gradients bit-identical"
    else:
        worst = max(r.max_abs_diff, key=lambda k: r.max_abs_diff[k])
        outputs = (f"; outputs differ: largest |old - new| {r.max_abs_diff[worst]:.3g} ({worst}; rgb "
                   f"{r.max_abs_diff.get('rgb', float('nan')):.3g})")
    return (f"{r.workload}: old {r.against} median {r.old_median * 1e3:.1f} ms, new median "
            f"{r.new_median * 1e3:.1f} ms over {len(r.new_seconds)} alternating runs each; load {r.loads}, own "
            f"{r.own_cpu:.2f} cores, others {r.load_other:.2f}; CPU per run old {r.old_cpu_median * 1e3:.1f} ms, new "
            f"{r.new_cpu_median * 1e3:.1f} ms; {ratio}{outputs}")
