#!/usr/bin/env bash
# Run the pending 7K grids (issue 39) resumably across sessions and machines.
#
#   tools/run_grids.sh                 run every pending grid, in GRIDS' order (hours: in the background,
#                                      e.g. `nohup setsid tools/run_grids.sh > ~/.cache/splatbench/grids.log 2>&1 &`)
#   tools/run_grids.sh sh_degree       only these grids
#   tools/run_grids.sh --save          copy each grid's finished run records into reports/NAME/runs/
#                                      (those its table lists: commit them, a fresh machine resumes from
#                                      them), and name the committed ones its grid no longer has
#
# Results live outside the checkout, in $SPLATBENCH_CACHE (default ~/.cache/splatbench): results/NAME/
# (the runner's folder: finished runs are skipped), reports/NAME/ (the report of what is finished).
# Before running, the records committed in reports/NAME/runs/*.json are copied into results/NAME/
# (never over a record already there), so a machine that kept nothing starts where the last one
# stopped; every grid's, before any runs, since a grid copies the runs another grid finished under
# the same run id (graphdeco's default cell: the runner's reuse, docs/experiments.md). Run it from a
# checkout that stays put while it runs (e.g. a `git worktree` of a commit): the workers import
# splatbench from it. One lane per core (below): SPLATBENCH_LANES=1 for one.
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
    -h|--help) sed -n '2,/^set -u/p' "$0" | sed '$d'; exit 0 ;;
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
if [ "$SAVE" = 1 ]; then  # the grid's finished runs: those its table (results.parquet) lists as done
  for name in "${NAMES[@]}"; do
    results="$CACHE/results/$name" saved="$ROOT/reports/$name/runs"
    [ -f "$results/results.parquet" ] || { echo "$name: no results in $results"; continue; }
    mkdir -p "$saved"
    # the table's run ids, "done" or not: the grid as the last `splatbench run` of it found its file
    table=$("$ROOT/.venv/bin/python" -c 'import sys, pandas as pd
t = pd.read_parquet(sys.argv[1])
print("\n".join(f"{i} {s}" for i, s in zip(t.run_id, t.status)))' "$results/results.parquet" 2>/dev/null) || {
      echo "$name: could not read $results/results.parquet: nothing saved" >&2; continue; }
    mapfile -t rows <<< "$table"
    n=0 old=()
    for row in "${rows[@]}"; do
      id=${row%% *}
      [ "${row#* }" = done ] && [ -f "$results/$id.json" ] && cp "$results/$id.json" "$saved/" && n=$((n + 1))
    done
    for f in "$saved"/*.json; do
      [ -f "$f" ] || continue
      printf '%s\n' "${rows[@]}" | grep -q "^$(basename "$f" .json) " || old+=("$(basename "$f")")
    done
    echo "$name: $n finished run records in reports/$name/runs/"
    [ ${#old[@]} = 0 ] || echo "$name: ${#old[@]} committed records are of runs its grid no longer has" \
      "(its file changed; the report they made is in git): git rm them once its new report is in"
  done
  exit 0
fi

report() {  # the report of what is finished, one writer at a time
  mkdir -p "$CACHE/reports"
  flock "$CACHE/reports/.lock" nice -n 5 "$SB" report "$ROOT/experiments/$1.toml" --results "$CACHE/results" \
    --out "$CACHE/reports/$1" --force
}

# One lane per core: a runner of one worker pinned to its core (one Dr.Jit thread, as each of two
# workers of one runner has), every lane going through the grids in order. The runners share each
# grid through its claims, and a lane whose grid has nothing left to claim starts the next grid
# while the others finish their last runs: no core waits for the longest run of a grid (a 30K check
# run, about an hour). A run two grids share is run once (the runner leaves to the other grid's
# runner the run it holds); the last pass below copies what a lane left that way.
LANES=${SPLATBENCH_LANES:-$(nproc)}
lane() {
  local core=$1 name
  for name in "${NAMES[@]}"; do
    echo "$name: lane $core start $(date -Is) at $(git -C "$ROOT" rev-parse --short HEAD)"
    taskset -c "$core" nice -n 5 "$SB" run "$ROOT/experiments/$name.toml" --results "$CACHE/results" \
      --workers 1 --no-progress
    echo "$name: lane $core done $(date -Is)"
    report "$name"
  done
}
cores=($(taskset -pc $$ | sed 's/.*: //' | tr ',' '\n' | while IFS=- read -r a b; do seq "$a" "${b:-$a}"; done))
for ((k = 0; k < LANES && k < ${#cores[@]}; k++)); do lane "${cores[$k]}" & done
wait
for name in "${NAMES[@]}"; do  # the last pass: the shared runs a lane left to another lane, anything failed
  nice -n 5 "$SB" run "$ROOT/experiments/$name.toml" --results "$CACHE/results" --workers "$LANES" --no-progress
  report "$name"
  echo "$name: done $(date -Is)"
done
