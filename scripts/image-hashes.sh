#!/usr/bin/env bash
# The image-hash check: renders every method on a few scenes at a fixed seed and
# sample budget (examples/fingerprint.rs) at 1, 2 and 3 threads (an odd count
# too: work split in halves cannot hide there), and compares the
# SHA-256 of every film, EXR, statistics and first-round checkpoint file with
# the recorded ones in scripts/image-hashes.sha256. Run it before and after any
# change that must not change what a method computes. A change to a checkpoint
# alone changes what a checkpoint holds: bump checkpoint::FORMAT_VERSION.
#
#   scripts/image-hashes.sh            check (exit 1 on any difference)
#   scripts/image-hashes.sh --record   record the current hashes
set -euo pipefail
cd "$(dirname "$0")/.."

record=0
[ "${1:-}" = "--record" ] && record=1
recorded=scripts/image-hashes.sha256
out=out/fingerprints

# The binary the tests build (scripts/test.sh: the test profile, optimized,
# with debug assertions; the tests' features): after the tests, nothing is
# rebuilt (`cargo build --example fingerprint` resolves the features without
# the dev-dependencies' and rebuilt most of the workspace: 80-170 s of CI).
# No optimization level changes a bit (Rust neither contracts nor reorders
# floating point), so release builds give these hashes too.
fingerprint=$(scripts/test.sh --no-run --message-format=json 2>/dev/null |
  grep -o '"executable":"[^"]*/examples/fingerprint"' | sed 's/^"executable":"//; s/"$//') || true
[ -x "$fingerprint" ] || { echo "the fingerprint example was not built" >&2; exit 1; }
rm -rf "$out"
for threads in 1 2 3; do
  "$fingerprint" --threads "$threads" --out "$out/$threads" >/dev/null
done
hashes() { (cd "$out/$1" && sha256sum -- * | sort -k 2); }

status=0
for threads in 2 3; do
  if ! diff <(hashes 1) <(hashes "$threads") >/dev/null; then
    echo "1 and $threads threads differ:"
    diff <(hashes 1) <(hashes "$threads") || true
    status=1
  fi
done
if [ "$record" = 1 ]; then
  hashes 1 >"$recorded"
  echo "recorded $(wc -l <"$recorded") hashes in $recorded"
elif ! diff "$recorded" <(hashes 1); then
  echo "the hashes differ from $recorded (< recorded, > now)"
  status=1
else
  echo "all $(wc -l <"$recorded") hashes match $recorded, at 1, 2 and 3 threads"
fi
exit "$status"
