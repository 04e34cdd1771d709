#!/usr/bin/env bash
# What an embedder's crate pulls in: a crate outside the workspace that
# depends on `strata` by path, resolved offline from the workspace's
# lockfile (no build). With default features it gets the `strata` command's
# dependencies too (clap, indicatif, ctrlc); with `default-features = false,
# features = ["parallel", "image-io", "native"]`, as README's "Embedding from
# Rust" says, it must not; neither may ever pull the workspace's dev tools.
# With the engine alone (no `native`) it gets no tracer, geometry or images.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
dir="$root/target/embedding-check"
cli=(clap indicatif ctrlc)
dev=(criterion proptest plotters strata-capi)

# The dependency names of an outside crate whose `strata` dependency is `$1`.
pulled() {
  rm -rf "$dir" && mkdir -p "$dir/src"
  printf '[package]\nname = "embedder"\nversion = "0.0.0"\nedition = "2024"\n\n[dependencies]\nstrata = %s\n\n[workspace]\n' "$1" >"$dir/Cargo.toml"
  echo 'fn main() {}' >"$dir/src/main.rs"
  cp "$root/Cargo.lock" "$dir/Cargo.lock"
  cargo tree --offline --manifest-path "$dir/Cargo.toml" -e normal --prefix none --format '{p}' |
    awk '{print $1}' | sort -u
}

has() { grep -qx "$2" <<<"$1"; }

default=$(pulled "{ path = \"$root\" }")
lean=$(pulled "{ path = \"$root\", default-features = false, features = [\"parallel\", \"image-io\", \"native\"] }")
engine=$(pulled "{ path = \"$root\", default-features = false, features = [\"parallel\"] }")
status=0
for crate in "${dev[@]}"; do
  for set in default lean; do
    if has "${!set}" "$crate"; then echo "FAIL: an embedder ($set features) pulls $crate"; status=1; fi
  done
done
for crate in "${cli[@]}"; do
  if has "$lean" "$crate"; then echo "FAIL: an embedder without the cli feature pulls $crate"; status=1; fi
  if ! has "$default" "$crate"; then echo "note: default features no longer pull $crate (README's advice can go)"; fi
done
# A renderer that brings its own rays gets the engine alone.
for crate in strata-native strata-embree glam obvhs tobj image "${cli[@]}"; do
  if has "$engine" "$crate"; then echo "FAIL: an embedder without the native feature pulls $crate"; status=1; fi
done
printf 'an embedder pulls %d crates with the engine alone\n' "$(wc -l <<<"$engine")"
printf 'an embedder pulls %d crates with default features, %d without the cli feature\n' \
  "$(wc -l <<<"$default")" "$(wc -l <<<"$lean")"
exit $status
