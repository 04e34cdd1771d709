#!/usr/bin/env bash
# The long reference of veach-ajar at its own 1280x720:
# independent bidirectional-MC chunks of 64 paths per pixel, seeds 5000,
# 5001, ..., each written to out/reference/ as an EXR; the reference is
# their mean (equal weights). Hours of work: run it in the background, niced,
# and again later; finished chunks are skipped, a chunk in progress
# checkpoints every 600 s and resumes while the checkpoint format is
# unchanged. Needs `cargo build --release` first (or STRATA_BIN: a strata
# binary kept apart, so that rebuilding meanwhile does not swap it).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${STRATA_BIN:-$root/target/release/strata}"
scene="${STRATA_SCENES:-$root/scenes}/veach-ajar/scene.pbrt"
mkdir -p "$root/out/reference" && cd "$root/out/reference"
for seed in $(seq 5000 5999); do
  out=veach-ajar-1280x720-bdpt-mc-s$seed-64spp
  [ -f "$out.exr" ] && continue
  resume=()
  [ -f "$out.ckpt" ] && resume=(--resume "$out.ckpt")
  nice -n 19 "$bin" render "$scene" --method mc --path-sampler bidirectional --spp 64 \
    --seed "$seed" --checkpoint-every 600 --out "$out" "${resume[@]}" >>chunks.log 2>&1
  rm -f "$out.ckpt"
done
