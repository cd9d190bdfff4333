#!/usr/bin/env bash
# device session 2026-11-28, call 4: A/B bench train ABBA (3 pairs), old 7d7939f vs new (.whl/commit.txt); MCMC resume into its own folder
# (what made reports/cuda/h200_2026-11-28/ab_abba/ and resume_check/, kept as its record: run from the repository root)
set -uo pipefail
R=$PWD; W=/tmp/cc2; mkdir -p $W
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 3
export PYTHONUNBUFFERED=1
cp .whl/commit.txt $W/new_commit.txt; echo 7d7939f > $W/old_commit.txt
(
cd /tmp
for pair in 1 2 3; do
  if [ $pair = 2 ]; then order="new old"; else order="old new"; fi
  for v in $order; do
    if [ $v = old ]; then P=/tmp/site:$R/.whl/old; else P=/tmp/site:$R; fi
    echo "== pair $pair $v: load $(cut -d' ' -f1-3 /proc/loadavg)"
    PYTHONPATH=$P timeout 40 python3 -m splatbench bench train --device cuda --iterations 100 --warmup 10 --out $W/ab_${v}_$pair 2>&1 | grep -E "it/s|^ *[0-9]+x"
  done
done
cd $R; export PYTHONPATH=/tmp/site:$R
timeout 60 python3 -m splatbench train .whl/diffuse-128 --set device=cuda --set layout=blender --set strategy=mcmc --set iterations=600 --set checkpoint_every=300 --out $W/mcmc_full --quiet --json > $W/mcmc_full.json
timeout 60 python3 -m splatbench train --resume $W/mcmc_full/checkpoints/iteration_300.pt --out $W/mcmc_resumed --quiet --json > $W/mcmc_resumed.json
python3 - <<'PY'
import hashlib, json, numpy as np
from plyfile import PlyData
W = "/tmp/cc2"
a, b = (PlyData.read(f"{W}/{r}/point_cloud.ply")["vertex"].data for r in ("mcmc_full", "mcmc_resumed"))
names = a.dtype.names
diff = max(float(np.max(np.abs(a[n].astype(np.float64) - b[n].astype(np.float64)))) for n in names) if len(a) == len(b) else float("nan")
sha = [hashlib.sha256(open(f"{W}/{r}/point_cloud.ply", "rb").read()).hexdigest() for r in ("mcmc_full", "mcmc_resumed")]
ra, rb = (json.load(open(f"{W}/{r}.json")) for r in ("mcmc_full", "mcmc_resumed"))
out = {"gaussians": [len(a), len(b)], "max_abs_param_diff": diff, "ply_sha256": sha, "ply_identical": sha[0] == sha[1],
       "test_psnr": [ra["test_psnr"], rb["test_psnr"]]}
print(json.dumps(out)); json.dump(out, open(f"{W}/mcmc_resume_check.json", "w"), indent=1)
PY
) 2>&1 | tee $W/log.txt
cp $W/log.txt $OUT/log.txt
cd /tmp && tar --exclude='*.pt' --exclude='*.ply' -czf $OUT/cc2.tgz cc2 && ls -la $OUT
