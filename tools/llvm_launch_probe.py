"""The rasterizer under other settings of Dr.Jit's LLVM launches: SIMD packet width and block size.

    python tools/llvm_launch_probe.py --model guitar --model biker --size 400x300
    python tools/llvm_launch_probe.py --model guitar --size 400x300 --width 16 --width 8 --width 32 --rounds 5
    python tools/llvm_launch_probe.py --synthetic 100000 512x512 --block-size 0 --block-size 256 --block-size 64

Dr.Jit 1.5 picks the LLVM packet width from the CPU (16 lanes with AVX-512, 8 with AVX2,
4 otherwise) and splits each kernel launch into blocks of at most 16,384 lanes (with
2 threads, a kernel under 65,536 lanes runs as 4 blocks). Neither is a Python setting;
drjit-core exports both setters (``jit_llvm_set_target``, ``jit_llvm_set_block_size``,
C++ symbols), which this tool calls through ctypes in a fresh process per setting, then
runs `splatbench bench raster`'s measurement of one workload (`bench.raster.run_one`:
warm-up untimed, ``--repeats`` runs, median) and prints forward+backward and the
compositing stages (the forward stage includes the lanes' lists, the backward one the
per-Gaussian reduction). The evaluation count is `work_stats`'s, whose packets are at most
a tile's lanes: at 32 lanes it prints the 16-lane count. Settings take turns, ``--rounds`` times; the last line of each
workload gives each setting's median over the rounds, and the load average is printed
before and after (a ratio from a loaded machine is not a speed claim: docs/benchmarks.md,
"Noise"). A width other than the CPU's is also handed to the rasterizer, so more than the
packets change: below a tile's 16 lanes (8) each tile's lanes are sorted by list length
(`blocks.sort_lanes_by_length`) and a pair gets a gradient slot per packet
(`reduction.lane_group`: 2 at 8 lanes); at 32 lanes a packet spans two tiles. The tool
times; it does not compare images or gradients.

What it showed is in docs/history/benchmarks.md ("Dr.Jit's launch settings"). Linux, x86-64.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

_SET_TARGET = "_Z19jit_llvm_set_targetPKcS0_j"    # void jit_llvm_set_target(const char*, const char*, uint32_t)
_TARGET_CPU = "_Z19jit_llvm_target_cpuv"          # const char* jit_llvm_target_cpu()
_TARGET_FEATURES = "_Z24jit_llvm_target_featuresv"
_VECTOR_WIDTH = "_Z21jit_llvm_vector_widthv"      # uint32_t jit_llvm_vector_width()
_SET_BLOCK_SIZE = "_Z23jit_llvm_set_block_sizej"  # void jit_llvm_set_block_size(uint32_t)
_BLOCK_SIZE = "_Z19jit_llvm_block_sizev"


def _child(job: dict) -> None:
    """One setting, one workload: prints a JSON line of its times."""
    import ctypes

    import splatbench.raster.device as device  # sets DRJIT_LIBLLVM_PATH before Dr.Jit loads
    import drjit as dr
    from drjit.llvm import Float

    dr.eval(Float(1.0) + 1.0)  # the LLVM backend is up: its target can be changed now
    core = ctypes.CDLL(os.path.join(dr.__path__[0], "libdrjit-core.so"))
    for name, res in ((_TARGET_CPU, ctypes.c_char_p), (_TARGET_FEATURES, ctypes.c_char_p),
                      (_VECTOR_WIDTH, ctypes.c_uint32), (_BLOCK_SIZE, ctypes.c_uint32)):
        getattr(core, name).restype = res
    getattr(core, _SET_TARGET).argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    getattr(core, _SET_BLOCK_SIZE).argtypes = [ctypes.c_uint32]
    if job["width"]:
        getattr(core, _SET_TARGET)(getattr(core, _TARGET_CPU)(), getattr(core, _TARGET_FEATURES)(), job["width"])
        # `device.packet_width` looks this name up when called: the lanes and the reduction follow the packets
        device._llvm_packet_width = lambda: job["width"]
    if job["block_size"]:
        getattr(core, _SET_BLOCK_SIZE)(job["block_size"])

    from splatbench.bench.raster import BenchSettings, run_one
    from splatbench.workloads import parse_models, parse_synthetic

    if job["synthetic"]:
        spec = parse_synthetic(*job["synthetic"])
    else:
        spec = parse_models((job["model"],), None, 1, job["size"])[0]
    r = run_one(spec, BenchSettings(repeats=job["repeats"], device="cpu"))
    print(json.dumps({"width": int(getattr(core, _VECTOR_WIDTH)()), "block_size": int(getattr(core, _BLOCK_SIZE)()),
                      "name": r.name, "fwd_bwd_ms": r.fwd_bwd_ms, "compositing_ms": r.stages.compositing_ms,
                      "backward_compositing_ms": r.stages.backward_compositing_ms,
                      "binning_ms": r.stages.binning_ms, "evaluations": r.evaluations}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", action="append", default=[], help="guitar, biker or a PLY (repeatable)")
    ap.add_argument("--size", default="400x300", help="the models' image size, WxH")
    ap.add_argument("--synthetic", nargs=2, action="append", default=[], metavar=("N", "WxH"))
    ap.add_argument("--width", type=int, action="append", default=[],
                    help="packet width (lanes, a power of two >= 4; 0: the CPU's); default: 0, 8 and 32")
    ap.add_argument("--block-size", type=int, action="append", default=[],
                    help="lanes per block (0: Dr.Jit's 16,384); a power of two >= the packet width")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(json.loads(args.child))
        return
    widths = args.width or ([0] if args.block_size else [0, 8, 32])
    blocks = args.block_size or [0]

    def power_of_two(x: int) -> bool:
        return x > 0 and x & (x - 1) == 0

    for w in widths:
        # the reduction's lane groups (`reduction.lane_group`) divide a tile's lanes: a power of two
        if w and not (power_of_two(w) and w >= 4):
            sys.exit(f"llvm_launch_probe: --width {w}: expected 0 or a power of two >= 4")
    from splatbench._llvm import packet_width  # imports no Dr.Jit

    cpu_width = packet_width()
    for w in widths:
        for b in blocks:
            # drjit-core's jit_llvm_set_block_size refuses anything else (and would abort the child)
            packet = w or cpu_width
            whose = "" if w else ", this CPU's"
            if b and not (power_of_two(b) and b >= packet):
                sys.exit(f"llvm_launch_probe: --block-size {b}: expected 0 or a power of two >= the packet width "
                         f"({packet} lanes{whose})")
    settings = [(w, b) for w in widths for b in blocks]
    workloads = [{"model": m, "size": args.size, "synthetic": None} for m in args.model]
    workloads += [{"model": None, "size": None, "synthetic": list(s)} for s in args.synthetic]
    if not workloads:
        sys.exit("llvm_launch_probe: give --model or --synthetic")
    print(f"load average before: {os.getloadavg()}")
    for wl in workloads:
        runs: dict[tuple[int, int], list[dict]] = {s: [] for s in settings}
        for _ in range(args.rounds):
            for w, b in settings:
                job = {**wl, "width": w, "block_size": b, "repeats": args.repeats}
                out = subprocess.run([sys.executable, __file__, "--child", json.dumps(job)],
                                     capture_output=True, text=True)
                lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
                if out.returncode or not lines:
                    tail = (out.stderr.strip().splitlines() or ["no output"])[-1]
                    sys.exit(f"llvm_launch_probe: width {w}, block size {b}: {tail}")
                r = json.loads(lines[-1])
                runs[(w, b)].append(r)
                print(f"  {r['name']}: width {r['width']}, block size {r['block_size']}: fwd+bwd {r['fwd_bwd_ms']:.1f} ms, "
                      f"compositing {r['compositing_ms']:.1f} + {r['backward_compositing_ms']:.1f} ms, "
                      f"binning {r['binning_ms']:.1f} ms, {r['evaluations']:,} evaluations", flush=True)
        base = statistics.median(r["fwd_bwd_ms"] for r in runs[settings[0]])
        for (w, b), rs in runs.items():
            med = statistics.median(r["fwd_bwd_ms"] for r in rs)
            comp = statistics.median(r["compositing_ms"] + r["backward_compositing_ms"] for r in rs)
            print(f"{rs[0]['name']}: width {rs[0]['width']}, block size {rs[0]['block_size']}: median fwd+bwd "
                  f"{med:.1f} ms (x{base / med:.2f} of the first setting), compositing fwd+bwd {comp:.1f} ms "
                  f"over {len(rs)} rounds")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
