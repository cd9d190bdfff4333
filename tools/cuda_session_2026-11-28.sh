#!/usr/bin/env bash
# device session 2026-11-28: wheels, then tools/cuda_check.sh, then an old/new A/B of bench train; results tarred into $OUT
# (what made reports/cuda/h200_2026-11-28/, kept as its record: run from the repository root, wheels in .whl/)
set -uo pipefail
R=$PWD; W=/tmp/cc; mkdir -p $W
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 3
export PYTHONPATH=/tmp/site:$R PYTHONUNBUFFERED=1
(
uptime; nproc
PYTHON=python3 timeout ${CC_LIMIT:-330} tools/cuda_check.sh $W .whl/diffuse-128
echo "== cuda_check exit $?"
echo "== A/B bench train: old (7d7939f, CPU parameters) vs new (parameters on CUDA), alternately"
cd /tmp
for i in 1 2; do
  for v in old new; do
    if [ $v = old ]; then P=/tmp/site:$R/.whl/old; else P=/tmp/site:$R; fi
    PYTHONPATH=$P timeout 40 python3 -m splatbench bench train --device cuda --iterations 100 --warmup 10 --out $W/ab_${v}_$i 2>&1 | tail -4
    uptime
  done
done
cd $R
PYTHONPATH=/tmp/site:$R timeout 40 python3 tools/cuda_profile.py $W/profile --repeats 7 2>&1 | tail -30
) 2>&1 | tee $W/log.txt
cp $W/log.txt $OUT/log.txt
cd /tmp && tar --exclude='*.pt' --exclude='*.ply' --exclude='*.npz' -czf $OUT/cc.tgz cc && ls -la $OUT
