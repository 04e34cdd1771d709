#!/usr/bin/env bash
# The container recipe under a real container engine. Builds
# jobs/Containerfile with podman as the Kubernetes Job's comment says, then
# runs in that image what jobs/kubernetes.yaml and jobs/kubernetes-merge.yaml
# run: COUNT tasks (`jobs/task.sh INDEX COUNT` from /strata, the parts on a
# volume mounted at /render), one of them stopped by SIGTERM while it
# renders (`podman stop`, as Kubernetes stops a pod) and started again, then
# the merge. Passes when the stopped task left a checkpoint and continued
# from it, and the merged PNG and EXR are the unsplit render's, byte for
# byte (the unsplit render run in the same image).
#
#   scripts/container-check.sh
#
# Installs Debian's podman and runc when missing (as root). Where the
# Containerfile's base images cannot be pulled (a machine without a
# registry), it makes stand-ins of the same names and says so:
# debian:bookworm-slim from debootstrap, rust:1-bookworm from that with gcc,
# this machine's Rust toolchain and its own certificate authorities (for a
# machine that reaches crates.io through a TLS proxy). Run by hand, not by CI (the build takes
# minutes); the last run is in docs/RESULTS.md, "Hostile input".
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
count=${COUNT:-3}
render_args=${RENDER_ARGS:---method pssmlt --spp 1024 --seed 1 --width 256 --height 192}
work=$root/target/container-check
rm -rf "$work"
mkdir -p "$work/render"

need=()
command -v podman >/dev/null || need+=(podman)
command -v runc >/dev/null || need+=(runc)
if [ ${#need[@]} -gt 0 ]; then
  echo "installing ${need[*]} (Debian's packages)"
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${need[@]}" >/dev/null
fi

# Containers keep podman's own resource limits: a machine without
# CAP_SYS_RESOURCE cannot raise them to podman's defaults.
printf '[containers]\ndefault_ulimits = []\n' >"$work/containers.conf"
export CONTAINERS_CONF=$work/containers.conf
runtime=()

# Stand-ins for base images that cannot be pulled.
standins=()
rootfs=${ROOTFS:-/var/tmp/strata-container-rootfs}
debian_rootfs() {
  if [ ! -x "$rootfs/bin/sh" ]; then
    command -v debootstrap >/dev/null ||
      DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap >/dev/null
    echo "debootstrap: Debian bookworm into $rootfs"
    debootstrap --variant=minbase bookworm "$rootfs" http://deb.debian.org/debian >"$work/debootstrap.log"
  fi
}
label=strata-check.stand-in
base() {
  local name=$1 image=docker.io/library/$1
  if podman image exists "$image" || podman pull -q "$image" >/dev/null 2>&1; then
    # A stand-in an earlier run made is said again.
    if [ "$(podman image inspect --format "{{index .Labels \"$label\"}}" "$image")" = true ]; then
      standins+=("$name")
    fi
    return
  fi
  standins+=("$name")
  debian_rootfs
  case $name in
  debian:*)
    tar -C "$rootfs" -c . |
      podman import -q --change "LABEL $label=true" - "$image" >/dev/null
    ;;
  rust:*)
    # The official image's parts: Debian, gcc, a Rust toolchain on the PATH.
    base debian:bookworm-slim
    local sysroot
    sysroot=$(rustc --print sysroot)
    cat >"$work/rust.containerfile" <<'EOF'
FROM debian:bookworm-slim
RUN apt-get update && apt-get install -y --no-install-recommends gcc libc6-dev ca-certificates && rm -rf /var/lib/apt/lists/* && update-ca-certificates
COPY . /usr/local/rust
ENV PATH=/usr/local/rust/bin:/usr/local/cargo/bin:$PATH CARGO_HOME=/usr/local/cargo
EOF
    local authorities=()
    [ -d /usr/local/share/ca-certificates ] &&
      authorities=(-v /usr/local/share/ca-certificates:/usr/local/share/ca-certificates:ro)
    podman build "${runtime[@]}" --network host --pull=never -q "${authorities[@]}" --label "$label=true" \
      -t "$image" -f "$work/rust.containerfile" "$sysroot" >/dev/null 2>"$work/rust-build.log"
    ;;
  esac
}

# The runtime: podman's default, or runc where the default cannot start a
# container (crun refuses cgroups in hybrid mode).
base debian:bookworm-slim
if ! podman run --rm debian:bookworm-slim true 2>"$work/runtime.log"; then
  runtime=(--runtime runc)
  podman "${runtime[@]}" run --rm debian:bookworm-slim true
  echo "runtime: runc ($(head -1 "$work/runtime.log"))"
fi
run() { podman "${runtime[@]}" run --rm "$@"; }
base rust:1-bookworm
[ ${#standins[@]} -eq 0 ] || echo "stand-ins (no registry): $(printf '%s\n' "${standins[@]}" | sort -u | xargs)"

# The recipe, as the Kubernetes Job's comment says, from the repository's root.
start=$SECONDS
podman "${runtime[@]}" build --network host --pull=never -t strata:latest \
  -f jobs/Containerfile . >"$work/build.log" 2>&1 || {
  tail -20 "$work/build.log"
  echo "FAIL: jobs/Containerfile did not build"
  exit 1
}
echo "built strata:latest in $((SECONDS - start)) s ($(podman image inspect strata:latest --format '{{.Size}}') bytes)"

# A task as the Indexed Job's pod runs it: its command, environment and volume.
task() {
  local index=$1
  shift
  run "$@" -v "$work/render:/render" -w /strata \
    -e JOB_COMPLETION_INDEX="$index" -e SCENE=cornell -e DIR=/render \
    -e RENDER_ARGS="$render_args" -e THREADS="$(nproc)" \
    strata:latest /bin/sh -c "exec jobs/task.sh \"\$JOB_COMPLETION_INDEX\" $count"
}
status=0
# Task 0, once it has rendered a while, is stopped as Kubernetes stops a pod.
task 0 -d --name strata-check-task-0 >/dev/null
for _ in $(seq 60); do
  podman logs strata-check-task-0 2>&1 | grep -q triangles && break
  sleep 0.5
done
sleep 2
podman "${runtime[@]}" stop -t 60 strata-check-task-0 >/dev/null
podman rm -f strata-check-task-0 >/dev/null 2>&1 || true
if [ -f "$work/render/part-0.ckpt" ] && [ ! -f "$work/render/part-0.part" ]; then
  echo "task 0: stopped by SIGTERM, checkpoint saved"
else
  echo "FAIL: task 0 saved no checkpoint when SIGTERM stopped it (it ran too short?)"
  status=1
fi
for index in $(seq 0 $((count - 1))); do
  task "$index" >"$work/task-$index.log" 2>&1 || {
    echo "FAIL: task $index: $(tail -1 "$work/task-$index.log")"
    status=1
  }
done
grep -h -i "resum" "$work/task-0.log" | sed 's/^/task 0: /' | head -3 || true
[ ! -f "$work/render/part-0.ckpt" ] || { echo "FAIL: task 0's checkpoint was not removed"; status=1; }

# The merge Job's command, and the render unsplit in the same image.
run -v "$work/render:/render" strata:latest \
  /bin/sh -c "exec strata merge /render/part-*.part --out /render/image" >"$work/merge.log" 2>&1
read -r -a args <<<"$render_args"
run -v "$work/render:/render" strata:latest \
  strata render cornell "${args[@]}" --out /render/whole >/dev/null 2>&1
for ext in png exr; do
  if cmp -s "$work/render/image.$ext" "$work/render/whole.$ext"; then
    echo "merged $ext: the unsplit render's bytes"
  else
    echo "FAIL: merged $ext differs from the unsplit render (or is missing)"
    status=1
  fi
done
ls "$work/render"
exit $status
