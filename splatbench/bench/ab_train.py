"""Training throughput of this checkout against an older commit, timed in alternation.

`run_ab_train` is `splatbench.bench.ab.run_ab` for whole training steps: it checks
the old commit out into a temporary ``git worktree`` (`ab.old_tree`), starts one
persistent worker per side (`ab.Worker`, ``PYTHONPATH`` selects the tree), and each
worker sets up the training of ``splatbench bench train`` -- the synthetic scene of
`splatbench.bench.train.synthetic_scene` (``gaussians`` random Gaussians, ``views``
orbit views, SH degree 3), `splatbench.train.Trainer` with ``strategy="none"``,
``sh_degree=3``, ``sh_interval=1``, one torch thread, on the CPU -- and runs
``warmup`` untimed steps (kernels compile or load from ``~/.drjit``). Then it asks
the two sides in turn (old, new, new, old, ...) for one block of ``block`` steps
at a time, ``pairs`` blocks each, sampling the 1-minute load average between pairs.
Medians, the quiet-machine rule and the withheld ratio come from `ab.summarize`
(one rule for both harnesses); the ratio old/new of the median block times is the
speed-up in iterations per second. Each block's CPU time (the worker process, all
threads) is recorded too: its ratio is reported always, as an indication only -- on a
busy machine it is less disturbed than wall time, but it counts spinning threads and
is not what the target measures. docs/training.md ("Throughput") shows the command.

The worker script uses only `synthetic_scene`, `TrainConfig`, `Trainer` and
`torch_threads`, which c11f838 and this tree both have; it passes
``schedule="absolute"`` only where `TrainConfig` has that field (bench train does
since the field exists; before, steps were always taken as written).
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from pathlib import Path

from splatbench.bench.ab import AbResult, Worker, old_tree, summarize
from splatbench.metrics.load import Load
from splatbench.bench.train import STANDARD_SIZES, check_train_settings
from splatbench.errors import InputError

TRAIN_WORKER = r"""
import dataclasses, json, sys, time
spec = json.loads(sys.argv[1])
import drjit as dr
import splatbench
from splatbench.bench.train import synthetic_scene
from splatbench.train.config import TrainConfig
from splatbench.train.loop import Trainer, torch_threads
dr.set_thread_count(spec["threads"])
dataset, _ = synthetic_scene(spec["size"], spec["gaussians"], spec["views"], spec["seed"])
kwargs = dict(dataset="", out="", iterations=spec["iterations"], seed=spec["seed"], device="cpu", torch_threads=1)
fields = {f.name for f in dataclasses.fields(TrainConfig)}
if "sh" in fields:  # the grouped TrainConfig
    from splatbench.train.config import SHConfig, StrategyConfig
    kwargs.update(strategy=StrategyConfig(name="none"), sh=SHConfig(degree=3, interval=1))
else:  # a commit before the regroup: flat fields
    kwargs.update(strategy="none", sh_degree=3, sh_interval=1)
if "schedule" in fields:
    kwargs["schedule"] = "absolute"
with torch_threads(1):
    trainer = Trainer(TrainConfig(**kwargs), dataset=dataset)
    for _ in range(spec["warmup"]):
        trainer.step()
    print(json.dumps({"ready": splatbench.__file__, "cpu": time.process_time()}), flush=True)
    for line in sys.stdin:
        if line.strip() != "run":
            break
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(spec["block"]):
            status = trainer.step()
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        print(json.dumps({"seconds": seconds, "cpu_seconds": cpu, "loss": status.loss, "cpu": time.process_time()}),
              flush=True)
"""


@dataclass(frozen=True)
class AbTrainSettings:
    """What each side trains and how it is timed (validated on construction)."""

    sizes: tuple[int, ...] = STANDARD_SIZES  # square image sides (pixels), as bench train
    gaussians: int = 20_000              # N trained (fixed: no densification)
    views: int = 16                      # training views of the synthetic scene
    block: int = 10                      # training steps per timed block
    pairs: int = 5                       # timed blocks per side (>= 5: a median of at least five)
    warmup: int = 5                      # untimed steps per side first (SH degree 3 active from step 3)
    threads: int = 2                     # Dr.Jit threads per side (torch: 1, as bench train)
    seed: int = 0                        # scene and training seed

    def __post_init__(self) -> None:
        if self.pairs < 5:
            raise InputError(f"--pairs: expected >= 5 timed blocks per side, got {self.pairs}")
        check_train_settings(self, ("gaussians", "views", "block", "threads"), min_size=16,
                             size_reason=" (the 11-tap SSIM window)")


@dataclass(frozen=True)
class AbTrainResult:
    """One size, old vs new. ``timing`` holds the seconds per block of ``block`` steps."""

    size: int                  # square image side (pixels)
    gaussians: int             # N trained on both sides
    block: int                 # steps per timed block
    old_it_per_s: float        # block / median old block time
    new_it_per_s: float        # block / median new block time
    old_losses: list[float]    # training loss of the last step of each block, in run order
    new_losses: list[float]
    timing: AbResult           # block seconds, loads, ratio old/new (None when withheld) and note
    old_cpu_seconds: list[float]  # CPU time of each block's process (all its threads), in run order
    new_cpu_seconds: list[float]
    cpu_ratio: float           # median old / median new CPU time: an indication on a busy machine only


def _spec(settings: AbTrainSettings, size: int) -> dict:
    return {"size": size, "gaussians": settings.gaussians, "views": settings.views, "block": settings.block,
            "warmup": settings.warmup, "threads": settings.threads, "seed": settings.seed,
            "iterations": settings.warmup + settings.block * settings.pairs}


class _TrainWorker(Worker):
    def block(self) -> dict:
        self.proc.stdin.write("run\n")
        self.proc.stdin.flush()
        return self._read()


def run_ab_train(repo: Path, against: str, settings: AbTrainSettings = AbTrainSettings(), *,
                 progress=None) -> list[AbTrainResult]:
    """Train at each size old vs new, timing blocks of steps in alternation.

    Args:
        repo: a checkout of this repository (the new side is the tree this module was
            imported from). against: the old commit (e.g. ``"c11f838"``).
    Returns:
        One `AbTrainResult` per size, in ``settings.sizes`` order.
    """
    new_tree = Path(__file__).resolve().parents[2]
    results = []
    with old_tree(repo, against) as old:
        for size in settings.sizes:
            spec = _spec(settings, size)
            label = f"train {settings.gaussians} {size}x{size}, {settings.block} steps per block"
            if progress:
                progress(f"{label}: building the scene and warming up both sides ...")
            sides: list[_TrainWorker] = []
            runs: tuple[list[dict], list[dict]] = ([], [])
            load = Load.start(cpu=0.0)  # before the workers exist: all their CPU time is the benchmark's own
            try:
                sides.append(_TrainWorker(old, spec, TRAIN_WORKER))
                sides.append(_TrainWorker(new_tree, spec, TRAIN_WORKER))
                for k in range(settings.pairs):
                    load = load.sample()
                    for side in ((0, 1) if k % 2 == 0 else (1, 0)):  # neither side always goes first
                        runs[side].append(sides[side].block())
                load = load.stop(cpu=sum(w.cpu for w in sides))
            finally:
                for w in sides:
                    w.close()
            timing = summarize(label, against, [r["seconds"] for r in runs[0]], [r["seconds"] for r in runs[1]],
                               load)
            old_cpu, new_cpu = ([r["cpu_seconds"] for r in side] for side in runs)
            results.append(AbTrainResult(size, settings.gaussians, settings.block,
                                         round(settings.block / timing.old_median, 3),
                                         round(settings.block / timing.new_median, 3),
                                         [r["loss"] for r in runs[0]], [r["loss"] for r in runs[1]], timing,
                                         old_cpu, new_cpu,
                                         round(statistics.median(old_cpu) / statistics.median(new_cpu), 3)))
    return results


def format_train_result(r: AbTrainResult) -> str:
    """One line: both sides' it/s and ms per step, the loads, the ratio (or why withheld)."""
    t = r.timing
    ratio = f"{t.ratio:.2f}x" if t.ratio is not None else t.note
    old_ms, new_ms = (1e3 * m / r.block for m in (t.old_median, t.new_median))
    return (f"train {r.gaussians} @ {r.size}x{r.size}: old {t.against} {r.old_it_per_s:.2f} it/s (median "
            f"{old_ms:.1f} ms/step), new {r.new_it_per_s:.2f} it/s ({new_ms:.1f} ms/step) over "
            f"{len(t.new_seconds)} alternating blocks of {r.block} steps each; load {t.loads}; {ratio} "
            f"(CPU time old/new {r.cpu_ratio:.2f}x)")


__all__ = ["AbTrainSettings", "AbTrainResult", "run_ab_train", "format_train_result", "TRAIN_WORKER"]
