#!/usr/bin/env bash
# Instructions per traced path of every method against MC, counted
# by valgrind's callgrind: unlike wall times on a shared 2-core machine, the
# count does not move with the machine's load, so it shows what a change to
# the engine costs or saves to the instruction, run after run.
#
# Each method renders the pbrt Cornell box at 128x128 with 16 paths per pixel
# (multistage MLT 24, above its smallest budget)
# on 1 thread (seed 0); the count covers the whole process (scene loading,
# bootstrap, set-up, reconstruction) and is divided by every path traced,
# bootstrap included, as `strata render` reports them. With --step, each
# method renders at 16 and at 48 paths per pixel instead (multistage MLT
# at 24 and 72), and the count is the difference divided by the paths
# traced between them: a chain step alone, without the fixed costs. Replica exchange runs as the cost table measures
# it (power tempering, 4 chains to T = 100) unless REPLICA_ARGS gives other
# `strata render` options (e.g. "--tempering power --replicas 8 --t-max 2500
# --exchange none"). Writes out/bench/instructions.csv (or
# instructions-step.csv); needs valgrind (apt-get install valgrind).
#
# METHOD_ARGS adds `strata render` options to every method but MC (e.g.
# "--emission-rays 0": the engine's cost alone, without the emission
# seen directly estimated apart, which changes the paths the chains take).
# With --check (after --step, if given), each method's count is compared
# with scripts/instruction-baseline.csv (committed; its rows name the
# options they were counted with): more than 2 % over fails, and the
# change is named. `--record` rewrites that file instead.
#
#   scripts/instruction-counts.sh                 every method
#   scripts/instruction-counts.sh pssmlt          MC and the methods named
#   scripts/instruction-counts.sh --step replica  a chain step of each
#   scripts/instruction-counts.sh --step --check  a step of each, against the baseline
set -euo pipefail
cd "$(dirname "$0")/.."

command -v valgrind >/dev/null || { echo "valgrind is not installed" >&2; exit 2; }
scene="${STRATA_SCENES:-scenes}/cornell-box/scene.pbrt"
step=false
if [ "${1:-}" = --step ]; then
  step=true
  shift
fi
mode=""
if [ "${1:-}" = --check ] || [ "${1:-}" = --record ]; then
  mode=$1
  shift
fi
read -r -a method_args <<<"${METHOD_ARGS:-}"
baseline=${BASELINE:-scripts/instruction-baseline.csv}
methods=("${@:-pssmlt stratified erpt replica multistage}")
read -r -a methods <<<"${methods[*]}"
read -r -a replica_args <<<"${REPLICA_ARGS:---tempering power --replicas 4 --t-max 100}"

cargo build --release --bin strata
out=out/bench
mkdir -p "$out/instructions"
if $step; then csv="$out/instructions-step.csv"; else csv="$out/instructions.csv"; fi
echo "method,instructions,paths,instructions_per_path,ratio" >"$csv"

# Prints "instructions paths" of one render of `$1` at `$2` paths per pixel.
count() {
  local method=$1 spp=$2 extra=()
  [ "$method" = replica ] && extra=("${replica_args[@]}")
  [ "$method" != mc ] && extra+=("${method_args[@]}")
  local log="$out/instructions/$method-$spp.log"
  valgrind --tool=callgrind --callgrind-out-file=/dev/null \
    target/release/strata render "$scene" --method "$method" "${extra[@]}" \
    --width 128 --height 128 --spp "$spp" --threads 1 --out "$out/instructions/$method" >"$log" 2>&1
  local instructions paths
  instructions=$(sed -n 's/.*I *refs: *//p' "$log" | tr -d ,)
  # "paths: N (+B bootstrap)": every path traced.
  paths=$(sed -n 's/^paths: \([0-9]*\) (+\([0-9]*\) bootstrap).*/\1 \2/p' "$log" | awk '{print $1 + $2}')
  echo "$instructions $paths"
}

# The two budgets (paths per pixel) a step is measured between; the first
# is the whole-process count's.
step_spp() {
  case $1 in
    multistage) echo "24 72" ;;
    *) echo "16 48" ;;
  esac
}

mc_per_path=""
for method in mc "${methods[@]}"; do
  if $step; then
    read -r low_spp high_spp < <(step_spp "$method")
    read -r low low_paths < <(count "$method" "$low_spp")
    read -r high high_paths < <(count "$method" "$high_spp")
    instructions=$((high - low))
    paths=$((high_paths - low_paths))
  else
    read -r spp _ < <(step_spp "$method")
    read -r instructions paths < <(count "$method" "$spp")
  fi
  per_path=$(awk -v i="$instructions" -v p="$paths" 'BEGIN {printf "%.0f", i / p}')
  mc_per_path=${mc_per_path:-$per_path}
  ratio=$(awk -v a="$per_path" -v b="$mc_per_path" 'BEGIN {printf "%.3f", a / b}')
  printf '%-11s %6d instructions per path (%s x MC), %d paths\n' "$method" "$per_path" "$ratio" "$paths"
  echo "$method,$instructions,$paths,$per_path,$ratio" >>"$csv"
done
echo "wrote $csv"

# The baseline: method, options, step, instructions per path.
key() { printf '%s,%s,%s' "$1" "${METHOD_ARGS:-}" "$step"; }
if [ "$mode" = --record ]; then
  tail -n +2 "$csv" | while IFS=, read -r method _ _ per_path _; do
    grep -v "^$(key "$method")," "$baseline" 2>/dev/null >"$baseline.new" || true
    echo "$(key "$method"),$per_path" >>"$baseline.new"
    mv "$baseline.new" "$baseline"
  done
  echo "recorded in $baseline"
elif [ "$mode" = --check ]; then
  status=0
  while IFS=, read -r method _ _ per_path _; do
    was=$(grep "^$(key "$method")," "$baseline" | cut -d, -f4)
    if [ -z "$was" ]; then
      echo "$method: no baseline for these options"
      status=1
    elif awk -v now="$per_path" -v was="$was" 'BEGIN {exit !(now > 1.02 * was)}'; then
      echo "$method: $per_path instructions per path, baseline $was (+$(awk -v n="$per_path" -v w="$was" 'BEGIN {printf "%.1f", 100 * (n / w - 1)}') %)"
      status=1
    else
      echo "$method: $per_path instructions per path, baseline $was: kept"
    fi
  done < <(tail -n +2 "$csv")
  exit $status
fi
