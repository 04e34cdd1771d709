#!/usr/bin/env bash
# Instructions per traced path of every method against MC (issue 19), counted
# by valgrind's callgrind: unlike wall times on a shared 2-core machine, the
# count does not move with the machine's load, so it shows what a change to
# the engine costs or saves to the instruction, run after run.
#
# Each method renders the pbrt Cornell box at 128x128 with 16 paths per pixel
# on 1 thread (seed 0); the count covers the whole process (scene loading,
# bootstrap, set-up, reconstruction) and is divided by every path traced,
# bootstrap included, as `strata render` reports them. Writes
# out/bench/instructions.csv; needs valgrind (apt-get install valgrind).
#
#   scripts/instruction-counts.sh            every method
#   scripts/instruction-counts.sh pssmlt     MC and the methods named
set -euo pipefail
cd "$(dirname "$0")/.."

command -v valgrind >/dev/null || { echo "valgrind is not installed" >&2; exit 2; }
scene="${STRATA_SCENES:-../shared/scenes}/cornell-box/scene.pbrt"
methods=("${@:-pssmlt stratified erpt replica}")
read -r -a methods <<<"${methods[*]}"

cargo build --release --bin strata
out=out/bench
mkdir -p "$out/instructions"
csv="$out/instructions.csv"
echo "method,instructions,paths,instructions_per_path,ratio" >"$csv"

mc_per_path=""
for method in mc "${methods[@]}"; do
  extra=()
  # Replica exchange as issue 19 measures it: power tempering, 4 chains to T = 100.
  [ "$method" = replica ] && extra=(--tempering power --replicas 4 --t-max 100)
  log="$out/instructions/$method.log"
  valgrind --tool=callgrind --callgrind-out-file=/dev/null \
    target/release/strata render "$scene" --method "$method" "${extra[@]}" \
    --width 128 --height 128 --spp 16 --threads 1 --out "$out/instructions/$method" >"$log" 2>&1
  instructions=$(sed -n 's/.*I *refs: *//p' "$log" | tr -d ,)
  # "paths: N (+B bootstrap)": every path traced.
  paths=$(sed -n 's/^paths: \([0-9]*\) (+\([0-9]*\) bootstrap).*/\1 \2/p' "$log" | awk '{print $1 + $2}')
  per_path=$(awk -v i="$instructions" -v p="$paths" 'BEGIN {printf "%.0f", i / p}')
  mc_per_path=${mc_per_path:-$per_path}
  ratio=$(awk -v a="$per_path" -v b="$mc_per_path" 'BEGIN {printf "%.3f", a / b}')
  printf '%-11s %6d instructions per path (%s x MC), %d paths\n' "$method" "$per_path" "$ratio" "$paths"
  echo "$method,$instructions,$paths,$per_path,$ratio" >>"$csv"
done
echo "wrote $csv"
