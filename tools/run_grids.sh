#!/usr/bin/env bash
# Run the pending 7K grids (issue 39) resumably across sessions and machines.
#
#   tools/run_grids.sh                 run every pending grid, in GRIDS' order (hours: in the background,
#                                      e.g. `nohup setsid tools/run_grids.sh > ~/.cache/splatbench/grids.log 2>&1 &`)
#   tools/run_grids.sh sh_degree       only these grids
#   tools/run_grids.sh --save          copy each grid's finished run records into reports/NAME/runs/
#                                      (commit them: a fresh machine resumes from them)
#
# Results live outside the checkout, in $SPLATBENCH_CACHE (default ~/.cache/splatbench): results/NAME/
# (the runner's folder: finished runs are skipped), reports/NAME/ (the report of what is finished).
# Before running, the records committed in reports/NAME/runs/*.json are copied into results/NAME/
# (never over a record already there), so a machine that kept nothing starts where the last one
# stopped; every grid's, before any runs, since a grid copies the runs another grid finished under
# the same run id (graphdeco's default cell: the runner's reuse, docs/experiments.md). Run it from a checkout that stays put while it runs (e.g. a `git worktree` of a commit):
# the workers import splatbench from it.
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
CACHE=${SPLATBENCH_CACHE:-$HOME/.cache/splatbench}
# sh_degree_quick (done: the input of sh_degree's quick-versus-7K rank agreement), the three pending
# grids, then sh_degree's rerun in graphdeco's evaluation order (its committed report is stale until then)
GRIDS=(sh_degree_quick loss_weighting densification_schedules densification sh_degree)
SAVE=0
NAMES=()
for arg in "$@"; do
  case "$arg" in
    --save) SAVE=1 ;;
    -h|--help) sed -n '2,17p' "$0"; exit 0 ;;
    *) [ -f "$ROOT/experiments/$arg.toml" ] || { echo "run_grids: no experiments/$arg.toml" >&2; exit 2; }
       NAMES+=("$arg") ;;
  esac
done
[ ${#NAMES[@]} -gt 0 ] || NAMES=("${GRIDS[@]}")
SB="$ROOT/.venv/bin/splatbench"
[ -x "$SB" ] || { echo "run_grids: $SB not found: run make setup first" >&2; exit 2; }
export PYTHONPATH="$ROOT" SPLATBENCH_DATASETS="${SPLATBENCH_DATASETS:-$CACHE/datasets}"
if [ "$SAVE" = 0 ]; then  # every grid's committed records first: a grid reuses another's identical runs
  for name in "${GRIDS[@]}"; do
    mkdir -p "$CACHE/results/$name"
    for f in "$ROOT/reports/$name/runs"/*.json; do [ -f "$f" ] && cp -n "$f" "$CACHE/results/$name/"; done
  done
fi
for name in "${NAMES[@]}"; do
  results="$CACHE/results/$name" saved="$ROOT/reports/$name/runs"
  if [ "$SAVE" = 1 ]; then
    mkdir -p "$saved"
    n=0
    for f in "$results"/*.json; do
      [ -f "$f" ] || continue
      grep -q '"status": "done"' "$f" || continue
      cp "$f" "$saved/" && n=$((n + 1))
    done
    echo "$name: $n finished run records in reports/$name/runs/"
    continue
  fi
  echo "$name: start $(date -Is) at $(git -C "$ROOT" rev-parse --short HEAD)"
  nice -n 5 "$SB" run "$ROOT/experiments/$name.toml" --results "$CACHE/results" --no-progress
  nice -n 5 "$SB" report "$ROOT/experiments/$name.toml" --results "$CACHE/results" --out "$CACHE/reports/$name" --force
  echo "$name: done $(date -Is)"
done
