#!/usr/bin/env bash
# What an embedder's crate pulls in: a crate outside the workspace that
# depends on `strata` by path, resolved offline from the workspace's
# lockfile (no build). It never gets the `strata` command's dependencies
# (clap, indicatif, ctrlc: the command is the crate strata-cli) nor the
# workspace's dev tools; with the engine alone (`default-features = false,
# features = ["parallel"]`) no tracer, geometry or images.
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
engine=$(pulled "{ path = \"$root\", default-features = false, features = [\"parallel\"] }")
status=0
for crate in "${dev[@]}" "${cli[@]}"; do
  if has "$default" "$crate"; then echo "FAIL: an embedder pulls $crate"; status=1; fi
done
# A renderer that brings its own rays gets the engine alone.
for crate in strata-native strata-embree glam obvhs tobj image "${cli[@]}"; do
  if has "$engine" "$crate"; then echo "FAIL: an embedder without the native feature pulls $crate"; status=1; fi
done
printf 'an embedder pulls %d crates with the engine alone\n' "$(wc -l <<<"$engine")"
printf 'an embedder pulls %d crates with default features\n' "$(wc -l <<<"$default")"
exit $status
