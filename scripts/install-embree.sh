#!/usr/bin/env bash
# Installs what the Embree backend (oracle-embree, feature `embree`) needs:
#   - Embree 4: from apt where it offers libembree-dev >= 4 (Debian 13+);
#     otherwise (Debian 12, whose apt has Embree 3) the libembree4 shipped in
#     the PyPI wheel embreex==4.4.0.post1 (pinned by sha256) is unpacked into
#     oracle-embree/vendor/lib with a libembree4.so link name; the wheel also
#     carries the TBB library Embree needs, next to it.
#   - libclang for bindgen (embree4-sys generates its bindings at build time).
# Idempotent; run as root or with sudo available. Prints the library
# directory the build uses (oracle-embree/build.rs finds it by itself).
set -euo pipefail
cd "$(dirname "$0")/.."

WHEEL_VERSION=4.4.0.post1
WHEEL_FILE=embreex-4.4.0.post1-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl
WHEEL_SHA256=2cd0f7d5c6342e6247e31f700761689cae7829454d8c6de0c41e62124a023e1f
VENDOR=oracle-embree/vendor/lib

SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
export DEBIAN_FRONTEND=noninteractive

apt_updated=0
apt_install() {
    if [ "$apt_updated" = 0 ]; then $SUDO apt-get update -qq; apt_updated=1; fi
    $SUDO apt-get install -y -qq --no-install-recommends "$@"
}
candidate() { apt-cache policy "$1" 2>/dev/null | awk '/Candidate:/ {print $2}'; }

# libclang for bindgen.
if ! ls /usr/lib/llvm-*/lib/libclang.so* /usr/lib/*/libclang-[0-9]*.so* >/dev/null 2>&1; then
    $SUDO apt-get update -qq; apt_updated=1
    if [ -n "$(candidate libclang1-14)" ] && [ "$(candidate libclang1-14)" != "(none)" ]; then
        apt_install libclang1-14 libclang-common-14-dev
    else
        apt_install libclang-dev
    fi
fi

# Embree 4 (already here: nothing to fetch, so a second run is quick).
if [ -e "$VENDOR/libembree4.so" ]; then
    echo "Embree 4 already in $VENDOR"
    exit 0
fi
if ldconfig -p 2>/dev/null | grep -q 'libembree4\.so '; then
    echo "Embree 4 already on the system library path."
    exit 0
fi
if [ "$apt_updated" = 0 ]; then $SUDO apt-get update -qq; apt_updated=1; fi
embree_candidate=$(candidate libembree-dev)
case "$embree_candidate" in
    4.*|[5-9].*)
        apt_install libembree-dev
        echo "Embree $embree_candidate installed from apt (system library path)."
        exit 0
        ;;
esac

command -v python3 >/dev/null || apt_install python3 python3-pip
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 -m pip download --quiet --no-deps --only-binary=:all: \
    --python-version 3.11 --implementation cp --platform manylinux_2_28_x86_64 \
    "embreex==$WHEEL_VERSION" -d "$tmp"
echo "$WHEEL_SHA256  $tmp/$WHEEL_FILE" | sha256sum --check --quiet
mkdir -p "$VENDOR"
python3 - "$tmp/$WHEEL_FILE" "$VENDOR" <<'PY'
import os, sys, zipfile
wheel, out = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    for name in z.namelist():
        base = os.path.basename(name)
        if name.startswith("embreex.libs/") and ".so" in base:
            with z.open(name) as src, open(os.path.join(out, base), "wb") as dst:
                dst.write(src.read())
PY
embree=$(cd "$VENDOR" && ls libembree4-*.so.4 | head -n 1)
ln -sf "$embree" "$VENDOR/libembree4.so"
echo "Embree 4 ($WHEEL_FILE) unpacked into $VENDOR:"
ls -l "$VENDOR"
