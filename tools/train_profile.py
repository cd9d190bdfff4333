"""Where a training step's time goes, outside and inside the rasterizer (issue 30).

    python tools/train_profile.py 128                    # bench train's workload: 20,000 Gaussians
    python tools/train_profile.py 256 --steps 20
    python tools/train_profile.py 800 --gaussians 250000 --views 4 --steps 4
    python tools/train_profile.py 128 --clock wall --cprofile 25
    python tools/train_profile.py 800 --gaussians 100000 --steps 3 --kernels 12

Builds `splatbench bench train`'s synthetic scene (`bench.train.synthetic_scene`) and
trains it as bench train does (`Trainer`, ``strategy="none"``, SH degree 3 from the
fourth step, one torch thread, the CPU), untimed warm-up first, then prints the
trainer's stage times (`train.loop.StepTimes`) over ``--steps`` steps, per step and as
shares. ``--clock cpu`` (default) reads the process's CPU time (all threads: Dr.Jit's
pool too) at the stage boundaries instead of wall time: on a shared, loaded machine
the wall time of a stage is mostly waiting for a core, its CPU time is not. ``--cprofile
N`` also runs cProfile over the timed steps and prints its N largest functions by
internal time (the rasterizer's kernels run inside ``torch.from_dlpack``: Dr.Jit
evaluates lazily, when torch takes its outputs). ``--kernels N`` then runs the same number of
steps again with Dr.Jit's kernel history on (each launch timed, so those steps run a little
slower) and prints per step the N costliest compiled kernels (mean ms per step, width,
IR operations) and the time of Dr.Jit's other launches by kind (memset, sort permutation,
block reduction, ...).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time
import types


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("size", type=int, help="square image side (pixels)")
    ap.add_argument("--gaussians", type=int, default=20_000)
    ap.add_argument("--views", type=int, default=16)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=4)
    ap.add_argument("--clock", choices=("cpu", "wall"), default="cpu")
    ap.add_argument("--cprofile", type=int, default=0, metavar="N")
    ap.add_argument("--kernels", type=int, default=0, metavar="N",
                    help="also print the N costliest Dr.Jit kernels per step (kernel history; extra steps)")
    ap.add_argument("--drjit-threads", type=int, default=0, metavar="N",
                    help="Dr.Jit's thread pool (0: its default, one per core); 1: the CPU clock counts "
                         "compute only, not the pool's waiting")
    args = ap.parse_args()
    if args.drjit_threads:
        import drjit as dr

        dr.set_thread_count(args.drjit_threads)

    import splatbench.train.loop as loop
    from splatbench.bench.train import synthetic_scene
    from splatbench.metrics.load import load1
    from splatbench.train.config import SHConfig, StrategyConfig, TrainConfig

    if args.clock == "cpu":  # the trainer's stage clocks read CPU time instead
        loop.time = types.SimpleNamespace(perf_counter=time.process_time)
    dataset, _ = synthetic_scene(args.size, args.gaussians, args.views, 0)
    cfg = TrainConfig(dataset="", out="", iterations=args.warmup + args.steps * (2 if args.kernels else 1),
                      sh=SHConfig(degree=3, interval=1),
                       schedule="absolute", seed=0, device="cpu", torch_threads=1, strategy=StrategyConfig(name=StrategyConfig(name="none")))
    with loop.torch_threads(1):
        trainer = loop.Trainer(cfg, dataset=dataset)
        trainer.warm_up()
        for _ in range(args.warmup):
            trainer.step()
        trainer.times = loop.StepTimes()
        profiler = cProfile.Profile() if args.cprofile else None
        load0 = load1()
        w0, c0 = time.perf_counter(), time.process_time()
        if profiler:
            profiler.enable()
        for _ in range(args.steps):
            status = trainer.step()
        if profiler:
            profiler.disable()
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        history = kernel_history(trainer, args.steps) if args.kernels else None
    t, k = trainer.times, args.steps
    print(f"{args.size}x{args.size}, {trainer.num_gaussians} Gaussians, {k} steps: wall {1e3 * wall / k:.1f} ms, "
          f"CPU {1e3 * cpu / k:.1f} ms per step; last loss {status.loss:.6f}; load average {load0:.2f} -> "
          f"{load1():.2f}; stage clock: {args.clock}")
    for name in ("raster_forward", "loss", "raster_backward", "optimizer", "strategy", "other"):
        v = getattr(t, name)
        print(f"  {name:16s} {1e3 * v / k:9.2f} ms {100 * v / t.total():5.1f} %")
    if profiler:
        out = io.StringIO()
        pstats.Stats(profiler, stream=out).sort_stats("tottime").print_stats(args.cprofile)
        print(out.getvalue())
    if history:
        print_kernels(history, args.steps, args.kernels)


def kernel_history(trainer, steps: int) -> list:
    """Dr.Jit's kernel history of ``steps`` more training steps (each launch timed)."""
    import drjit as dr

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()  # clear
    try:
        for _ in range(steps):
            trainer.step()
        return dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


def print_kernels(history: list, steps: int, count: int) -> None:
    """The ``count`` costliest compiled kernels (same hash: one kernel) and the other launches by kind,
    mean ms per step."""
    import collections

    import drjit as dr

    jit: dict = collections.defaultdict(lambda: [0.0, 0, 0, 0])
    other: dict = collections.defaultdict(float)
    for h in history:
        kind = str(h.get("type", "")).split(".")[-1]
        if h.get("type") == dr.KernelType.JIT:
            entry = jit[h.get("hash")]
            entry[0] += h.get("execution_time", 0.0)
            entry[1] += 1
            entry[2], entry[3] = h.get("size", 0), h.get("operation_count", 0)
        else:
            other[kind] += h.get("execution_time", 0.0)
    total = sum(e[0] for e in jit.values())
    print(f"compiled kernels: {len(jit)} kinds, {sum(e[1] for e in jit.values()) / steps:.0f} launches and "
          f"{total / steps:.1f} ms per step; the costliest (ms per step, launches per step, width, IR operations):")
    for ms, launches, width, ops in sorted(jit.values(), key=lambda e: -e[0])[:count]:
        print(f"  {ms / steps:9.2f} ms  x{launches / steps:<4.2g} width {width:>10,}  ops {ops:>6,}")
    print("other launches (ms per step): " + ", ".join(f"{k} {v / steps:.2f}" for k, v in
                                                       sorted(other.items(), key=lambda kv: -kv[1])))


if __name__ == "__main__":
    main()
