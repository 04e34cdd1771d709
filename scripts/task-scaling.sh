#!/usr/bin/env bash
# A render split into tasks, simulated on one machine (the
# measurements, docs/BENCHMARKS.md "A render split into tasks"): for MC and
# PSSMLT (METHODS="mc replica ..." for others), the unsplit render and then its N tasks one after another, each
# timed with its peak resident memory (/usr/bin/time -v); the partial
# files' sizes; the merge's time and peak; the slowest task over the mean;
# and whether the merged PNG and EXR are the unsplit render's bytes.
# Writes out/bench/tasks.csv. Needs `cargo build --release` first.
#
#   scripts/task-scaling.sh [SCENE] [WIDTH] [HEIGHT] [SPP] [N]
#   (default: cornell 1280 720 8 8)
#
# With TIME=SECONDS, every task (and the unsplit render) gets that time
# budget instead of SPP (the work balance of a time-split budget; the
# merged image is then not compared: a time budget's image varies from run
# to run), and the csv is out/bench/tasks-time.csv. SET="NAME=VALUE ..."
# passes settings to every render (e.g. SET=runs=8 for stratified MCMC and
# multi-stage MLT, which split by runs).
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-cornell}
width=${2:-1280}
height=${3:-720}
spp=${4:-8}
n=${5:-8}
bin=target/release/strata
dir=out/bench/tasks
csv=out/bench/tasks${TIME:+-time}.csv
budget=(--spp "$spp")
[ -n "${TIME:-}" ] && budget=(--time "$TIME")
sets=()
# SET="runs=8 chains=64": each NAME=VALUE as its flag, --NAME VALUE.
for setting in ${SET:-}; do
  name=${setting%%=*}
  sets+=("--${name//_/-}" "${setting#*=}")
done
mkdir -p "$dir"
echo "method,what,index,seconds,peak_mb,file_mb" >"$csv"
timed() { # label index command... -> a csv line
  local label=$1 index=$2
  shift 2
  /usr/bin/time -v "$@" 2>"$dir/time.txt" >/dev/null
  local secs peak
  secs=$(awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, t, ":"); s = 0; for (i = 1; i <= n; i++) s = s * 60 + t[i]; print s}' "$dir/time.txt")
  peak=$(awk -F': ' '/Maximum resident/ {printf "%.1f", $2 / 1024}' "$dir/time.txt")
  echo "$label,$index,$secs,$peak"
}
for method in ${METHODS:-mc pssmlt}; do
  common=(render "$scene" --method "$method" "${budget[@]}" "${sets[@]}" --seed 1 --width "$width" --height "$height" --threads 2)
  line=$(timed whole 0 "$bin" "${common[@]}" --out "$dir/$method-whole")
  echo "$method,$line," >>"$csv"
  for ((i = 0; i < n; i++)); do
    line=$(timed task "$i" "$bin" "${common[@]}" --task-index "$i" --task-count "$n" --out "$dir/$method-part-$i")
    size=$(stat -c %s "$dir/$method-part-$i.part")
    echo "$method,$line,$(awk -v s="$size" 'BEGIN {printf "%.1f", s / 1e6}')" >>"$csv"
  done
  line=$(timed merge 0 "$bin" merge "$dir/$method"-part-*.part --out "$dir/$method-merged")
  echo "$method,$line," >>"$csv"
  for ext in png exr; do
    [ -n "${TIME:-}" ] && break
    cmp "$dir/$method-whole.$ext" "$dir/$method-merged.$ext" ||
      { echo "$method: the merged $ext differs from the unsplit render's" >&2; exit 1; }
  done
  awk -F, -v m="$method" '$1 == m && $2 == "task" {s += $4; if ($4 > x) x = $4; k++}
    END {printf "%s: %d tasks, slowest over mean %.3f\n", m, k, x / (s / k)}' "$csv"
done
echo "wrote $csv"
