"""Where a training step's time goes, outside and inside the rasterizer (issue 30).

    python tools/train_profile.py 128                    # bench train's workload: 20,000 Gaussians
    python tools/train_profile.py 256 --steps 20
    python tools/train_profile.py 800 --gaussians 250000 --views 4 --steps 4
    python tools/train_profile.py 128 --clock wall --cprofile 25

Builds `splatbench bench train`'s synthetic scene (`bench.train.synthetic_scene`) and
trains it as bench train does (`Trainer`, ``strategy="none"``, SH degree 3 from the
fourth step, one torch thread, the CPU), untimed warm-up first, then prints the
trainer's stage times (`train.loop.StepTimes`) over ``--steps`` steps, per step and as
shares. ``--clock cpu`` (default) reads the process's CPU time (all threads: Dr.Jit's
pool too) at the stage boundaries instead of wall time: on a shared, loaded machine
the wall time of a stage is mostly waiting for a core, its CPU time is not. ``--cprofile
N`` also runs cProfile over the timed steps and prints its N largest functions by
internal time (the rasterizer's kernels run inside ``torch.from_dlpack``: Dr.Jit
evaluates lazily, when torch takes its outputs).
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
    from splatbench.train.config import TrainConfig

    if args.clock == "cpu":  # the trainer's stage clocks read CPU time instead
        loop.time = types.SimpleNamespace(perf_counter=time.process_time)
    dataset, _ = synthetic_scene(args.size, args.gaussians, args.views, 0)
    cfg = TrainConfig(dataset="", out="", iterations=args.warmup + args.steps, strategy="none", sh_degree=3,
                      sh_interval=1, schedule="absolute", seed=0, device="cpu", torch_threads=1)
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


if __name__ == "__main__":
    main()
