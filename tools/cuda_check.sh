#!/usr/bin/env bash
# The CUDA checks, for a machine with an NVIDIA GPU (`make cuda-check`; docs/benchmarks.md "CUDA"):
#   1. the rasterizer's parity and gradient tests on Dr.Jit's CUDA backend (the `drjit-cuda` cases
#      that skip on a CPU-only machine);
#   2. `splatbench bench raster` and `splatbench bench train` on CUDA;
#   3. `splatbench compare` of drjit, torch and gsplat (fused CUDA kernels) on CUDA against the
#      float64 oracle (gradients too: the oracle runs on the CPU), when gsplat's CUDA extension builds;
#   4. training runs of the diffuse scene on CUDA (128²): the default strategy for 2000 iterations
#      (it/s and test PSNR), MCMC for 600 with a checkpoint at 300, and a resume from it.
# Every step runs even when one before it failed; the exit status says whether any failed. gsplat's
# extension compiles (nvcc, minutes) beside the untimed tests and is finished before anything is timed.
#
# Usage: tools/cuda_check.sh OUTDIR [DIFFUSE_DATASET]
#   OUTDIR            where everything is written (one sub-folder per step, and log.txt)
#   DIFFUSE_DATASET   a rendered diffuse 128² dataset (`splatbench scenes render diffuse --resolution 128`);
#                     rendered here when not given (needs Mitsuba)
# Environment: PYTHON (default: python3) with splatbench and its dependencies importable;
#              SPLATBENCH (default: "$PYTHON -m splatbench");
#              STEPS (default: "tests bench compare train"): the steps to run, in that order;
#              COMPARE (default: "--synthetic 10000 256x256 --scene garden"): compare's workloads and options
#              (the float64 oracle runs on the CPU: minutes per workload, more with finite differences).
set -uo pipefail
out=${1:?usage: tools/cuda_check.sh OUTDIR [DIFFUSE_DATASET]}
data=${2:-}
PY=${PYTHON:-python3}
SB=${SPLATBENCH:-"$PY -m splatbench"}
STEPS=" ${STEPS:-tests bench compare train} "
mkdir -p "$out"
failed=()
want() { [[ $STEPS == *" $1 "* ]]; }

run() {  # run NAME COMMAND...: log the command, its output and its time; remember a failure
  local name=$1; shift
  echo "== $name: $*"
  local t0=$SECONDS
  "$@"
  local rc=$?
  echo "== $name: exit $rc after $((SECONDS - t0)) s"
  [ $rc -eq 0 ] || failed+=("$name")
}

if ! $PY -c 'import sys, splatbench.raster.device as d; sys.exit(0 if d.cuda_available() else 1)'; then
  echo "cuda_check: Dr.Jit finds no CUDA device here; nothing to check" >&2
  exit 2
fi
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader > "$out/gpu.txt" 2>&1
$PY -c 'import drjit, torch, platform; print("python", platform.python_version(), "drjit", drjit.__version__,
"torch", torch.__version__, "torch.cuda", torch.version.cuda)' >> "$out/gpu.txt"
cat "$out/gpu.txt"

build=
if want compare; then  # gsplat's CUDA extension: compiled on first import (torch's JIT build)
  echo "== gsplat-build: started in the background (log: $out/gsplat_build.log)"
  $PY -c 'from gsplat.cuda._backend import _C; assert _C is not None, "no _C"' > "$out/gsplat_build.log" 2>&1 &
  build=$!
fi
gsplat_built() {  # wait for the background build; its exit status
  [ -n "$build" ] || return 1
  local t0=$SECONDS rc
  wait "$build"; rc=$?
  echo "== gsplat-build: exit $rc, waited $((SECONDS - t0)) s"
  build=; built=$rc; return $rc
}
built=1

if want tests; then
  run tests $PY -m pytest -q -p no:cacheprovider -k "drjit-cuda" --junitxml="$out/tests_cuda.xml" \
    tests/test_raster_parity.py tests/test_raster_grads.py
fi
[ -z "$build" ] || gsplat_built || true  # nothing timed runs beside the compiler
if want bench; then
  run bench-raster $SB bench raster --device cuda --repeats 9 --out "$out/bench"
  run bench-train $SB bench train --device cuda --iterations 200 --warmup 20 --out "$out/bench"
  # NeRF-synthetic size (800x800, 300k Gaussians): what one step of lego's 30K schedule costs here
  run bench-train-800 $SB bench train --device cuda --size 800 --gaussians 300000 --iterations 100 --warmup 10 \
    --out "$out/bench_800"
fi
if want compare; then
  if [ "$built" = 0 ]; then
    # shellcheck disable=SC2086  # COMPARE is a list of words
    run compare $SB compare --device cuda --backend drjit --backend torch --backend gsplat \
      ${COMPARE:---synthetic 10000 256x256 --scene garden --repeats 3} --out "$out/compare"
  else
    echo "== compare: skipped, gsplat's CUDA extension did not build (see $out/gsplat_build.log)"
    failed+=("gsplat-build")
  fi
fi

if want train; then
  if [ -z "$data" ]; then
    data="$out/diffuse-128"
    run render $SB scenes render diffuse --resolution 128 --out "$data"
  fi
  # The Blender layout of the rendered dataset: the COLMAP one would need pycolmap on the GPU machine.
  run train-diffuse $SB train "$data" --set device=cuda --set data.layout=blender --set iterations=2000 \
    --out "$out/train_diffuse" --quiet --json
  # MCMC's draws on the CUDA device, a checkpoint, and a resume from it on CUDA
  run train-mcmc $SB train "$data" --set device=cuda --set data.layout=blender --set strategy=mcmc \
    --set iterations=600 --set checkpoint_every=300 --out "$out/train_mcmc" --quiet --json
  run train-resume $SB train --resume "$out/train_mcmc/checkpoints/iteration_300.pt" --quiet --json
fi
if [ ${#failed[@]} -gt 0 ]; then
  echo "cuda_check: failed: ${failed[*]}"
  exit 1
fi
echo "cuda_check: all steps passed"
