#!/usr/bin/env bash
# The tests, the Embree backend's included: installs what that backend needs
# (scripts/install-embree.sh; quick once done), then one `cargo test` build of
# the whole workspace but the study programs (studies/) and the Python
# extension (python/, built by pip and tested by pytest; CI's clippy checks
# both), with the `embree` feature, every test binary run even when one
# fails (`--no-fail-fast`). Extra arguments go to
# `cargo test` (`scripts/test.sh --no-run --message-format=json` lists the
# binaries: scripts/image-hashes.sh and CI's fuzzing step run those, so they
# reuse this build rather than resolve other features and rebuild).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-embree.sh >&2
exec cargo test --workspace --exclude strata-studies --exclude strata-python --features strata/embree --no-fail-fast "$@"
