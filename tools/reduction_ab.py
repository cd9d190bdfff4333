"""The per-Gaussian gradient reduction of an older commit against this checkout's, in one process.

    python tools/reduction_ab.py 800 --gaussians 100000 --against 643ced3
    python tools/reduction_ab.py 128 --against 643ced3 --block 10

`splatbench bench ab` and `ab-train` time two whole trees in two processes; this times one
function, `splatbench.raster.reduction.reduce_pairs`, taken from ``--against``
(``git show COMMIT:splatbench/raster/reduction.py``, imported beside this checkout) and from
this checkout, inside one training process on `splatbench bench train`'s workload (20,000
Gaussians unless ``--gaussians``; 16 orbit views; ``strategy="none"``; one torch thread):

1. the reduction alone, on the inputs of one training step, old and new alternately
   (``--calls`` each after two untimed), its outputs compared bit for bit;
2. training steps in blocks of ``--block``, the reduction swapped between old and new for
   each block (ABBA order), ``--pairs`` blocks each after two untimed blocks: the ratio of
   the step times old/new, per pair of adjacent blocks and their median.

Both sides share everything else (binning, compositing, the trained model's state), and a
reduction whose sums are bit-identical leaves the training trajectory unchanged, so the
ratio is that of the reduction alone. Prints the load average before and after: a ratio
from a loaded machine is not a speed claim (docs/benchmarks.md, "Noise").
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def old_reduction(commit: str):
    """The module splatbench/raster/reduction.py at ``commit``, imported as ``_old_reduction``."""
    text = subprocess.run(["git", "-C", str(ROOT), "show", f"{commit}:splatbench/raster/reduction.py"],
                          capture_output=True, text=True)
    if text.returncode:
        sys.exit(f"reduction_ab: --against {commit}: {text.stderr.strip() or 'not a commit'}")
    path = Path(tempfile.mkdtemp()) / "_old_reduction.py"
    path.write_text(text.stdout)
    spec = importlib.util.spec_from_file_location("_old_reduction", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def packet_work(counts: np.ndarray, width: int) -> float:
    """Iterations x lanes of a loop whose lane k runs ``counts[k]`` times, packets of ``width``
    consecutive lanes running as long as their longest, over the iterations the lanes need."""
    padded = np.concatenate([counts, np.zeros(-len(counts) % width, counts.dtype)]).reshape(-1, width)
    return float(padded.max(axis=1).sum() * width / max(counts.sum(), 1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("size", type=int, help="square image side (pixels)")
    ap.add_argument("--against", required=True, metavar="COMMIT")
    ap.add_argument("--gaussians", type=int, default=20_000)
    ap.add_argument("--views", type=int, default=16)
    ap.add_argument("--calls", type=int, default=10, help="timed calls of the reduction alone, per side")
    ap.add_argument("--block", type=int, default=2, help="training steps per timed block")
    ap.add_argument("--pairs", type=int, default=8, help="timed blocks per side")
    args = ap.parse_args()

    import drjit as dr

    import splatbench.raster.compositing as compositing
    import splatbench.train.loop as loop
    from splatbench.bench.train import synthetic_scene
    from splatbench.metrics.load import load1
    from splatbench.raster import reduction
    from splatbench.raster.device import packet_width
    from splatbench.train.config import SHConfig, StrategyConfig, TrainConfig

    sides = {"old": old_reduction(args.against).reduce_pairs, "new": reduction.reduce_pairs}
    captured: dict = {}

    def capture(m, bins, pair, n, slots_per_pair=1):
        captured.update(m=m, bins=bins, pair={k: type(v)(v) for k, v in pair.items()}, n=n, slots=slots_per_pair)
        return sides["new"](m, bins, pair, n, slots_per_pair)

    dataset, _ = synthetic_scene(args.size, args.gaussians, args.views, 0)
    steps = 3 + 2 * (2 + args.pairs) * args.block
    cfg = TrainConfig(dataset="", out="", iterations=steps, schedule="absolute", seed=0, device="cpu", torch_threads=1, strategy=StrategyConfig(name="none"), sh=SHConfig(degree=3, interval=1))
    load0 = load1()
    with loop.torch_threads(1):
        trainer = loop.Trainer(cfg, dataset=dataset)
        trainer.warm_up()
        for _ in range(2):
            trainer.step()
        compositing.reduce_pairs = capture
        trainer.step()

        c = captured
        dr.eval(c["pair"])
        alone: dict = {"old": [], "new": []}
        for call in range(2 + args.calls):
            outputs = {}
            for side in ("old", "new") if call % 2 == 0 else ("new", "old"):
                dr.sync_thread()
                t0 = time.perf_counter()
                out = sides[side](c["m"], c["bins"], c["pair"], c["n"], c["slots"])
                dr.eval(out)
                dr.sync_thread()
                if call >= 2:
                    alone[side].append(time.perf_counter() - t0)
                outputs[side] = {k: v.numpy() for k, v in out.items()}
            for key, value in outputs["old"].items():
                if not np.array_equal(value, outputs["new"][key]):
                    sys.exit(f"reduction_ab: the sums of '{key}' differ from {args.against}'s: not bit-identical")

        blocks: dict = {"old": [], "new": []}
        for b in range(2 + args.pairs):
            for side in ("old", "new") if b % 2 == 0 else ("new", "old"):
                compositing.reduce_pairs = sides[side]
                t0 = time.perf_counter()
                for _ in range(args.block):
                    trainer.step()
                if b >= 2:
                    blocks[side].append((time.perf_counter() - t0) / args.block)
        compositing.reduce_pairs = sides["new"]
    old, new = np.array(blocks["old"]), np.array(blocks["new"])
    counts = c["bins"].counts.numpy().astype(np.int64)
    width = packet_width(c["m"])
    print(f"  loop work (a packet runs as long as its longest lane; packet iterations x {width} lanes / pairs): "
          f"Gaussians in index order {packet_work(counts, width):.2f}, in count order "
          f"{packet_work(np.sort(counts), width):.2f}")
    print(f"{args.size}x{args.size}, {args.gaussians} Gaussians, {c['bins'].num_pairs:,} pairs; against "
          f"{args.against}; load average {load0:.2f} -> {load1():.2f}")
    print(f"  reduction alone: old {1e3 * np.median(alone['old']):.2f} ms, new {1e3 * np.median(alone['new']):.2f} ms "
          f"(medians of {args.calls}); sums bit-identical")
    print(f"  training step: old {1e3 * np.median(old):.1f} ms, new {1e3 * np.median(new):.1f} ms (medians of "
          f"{args.pairs} blocks of {args.block}); old/new per pair {np.round(old / new, 3).tolist()}, "
          f"median x{np.median(old / new):.3f}")


if __name__ == "__main__":
    main()
