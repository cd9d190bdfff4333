"""Resident memory of a training run, phase by phase, and the libraries it loaded (issue 30).

    python tools/train_rss.py data/scenes/diffuse-128 --set iterations=200
    python tools/train_rss.py data/scenes/diffuse-256 --set iterations=2000

Runs `splatbench.train.train` (the ``splatbench train`` run, without the progress bar)
and prints the process's resident set now and its peak (``ru_maxrss``) after the
imports, after each of torch and Dr.Jit alone, once the trainer is built (dataset read,
model initialised), after the warm-up (kernels compiled or loaded), after steps 0, 1,
10, 100, 1000 and the last, and around each evaluation, with the heavy libraries
loaded by then. ``--set`` takes TrainConfig fields as ``splatbench train`` does; the
output folder is a temporary one. Units: MiB (2^20 bytes).
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile

HEAVY = ("torch._dynamo", "sympy", "scipy", "kornia", "pycolmap", "PIL", "mitsuba", "pandas", "pyarrow",
         "matplotlib", "dask", "gsplat", "torchvision")


def _now_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def mark(what: str) -> None:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
    loaded = [m for m in HEAVY if m in sys.modules]
    print(f"{what:34s} now {_now_mib():6.0f}  peak {peak:6.0f}  {' '.join(loaded)}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    mark("start")
    import torch  # noqa: F401
    mark("import torch")
    import drjit  # noqa: F401
    mark("import drjit")
    import splatbench.train.loop as loop
    from splatbench.train.config import TrainConfig, apply_overrides
    mark("import splatbench.train")

    evaluate, warm_up = loop.Trainer.evaluate, loop.Trainer.warm_up

    def evaluate_marked(self, *a, **k):
        mark(f"before evaluation, step {self.step_index}")
        out = evaluate(self, *a, **k)
        mark(f"after evaluation, step {self.step_index}")
        return out

    def warm_up_marked(self):
        mark("trainer built")
        warm_up(self)
        mark("after warm-up")

    loop.Trainer.evaluate, loop.Trainer.warm_up = evaluate_marked, warm_up_marked
    with tempfile.TemporaryDirectory() as out:
        config = apply_overrides(TrainConfig(dataset=args.dataset, out=out), args.sets)
        last = config.iterations - 1

        def progress(status):
            if status.step in (0, 1, 10, 100, 1000, last):
                mark(f"after step {status.step}, N {status.num_gaussians}")

        loop.train(config, progress=progress)
    mark("end")


if __name__ == "__main__":
    main()
