#!/usr/bin/env bash
# The job files under a real Slurm. Installs Debian's slurm-wlm and munge
# (as root), starts a one-node cluster on this machine (its own config,
# spool and logs under target/slurm-check; proctrack/linuxproc, no cgroups),
# and runs jobs/slurm-submit.sh as the README says: COUNT array tasks and
# the merge job. One task is requeued while it renders (Slurm stops it with
# SIGTERM, as for a preemption or a time limit) and must continue from its
# checkpoint. Passes when every task ends, the merge runs after the requeued
# task, and the merged PNG and EXR are the unsplit render's, byte for byte.
#
#   scripts/slurm-check.sh [STRATA]     (default target/release/strata, built if missing)
#
# Run by hand, not by CI (the install and the daemons take minutes); the
# last run is in docs/RESULTS.md, "Hostile input".
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
strata=${1:-$root/target/release/strata}
[ -x "$strata" ] || cargo build --release -p strata-cli
strata=$(realpath "$strata")
count=${COUNT:-3}
render_args=${RENDER_ARGS:---method pssmlt --spp 1024 --seed 1 --width 256 --height 192}

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  echo "installing slurm-wlm and munge (Debian's packages)"
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge >/dev/null
fi

work=$root/target/slurm-check
host=$(hostname -s)
conf=$work/slurm.conf
stop_cluster() {
  SLURM_CONF=$conf scontrol shutdown >/dev/null 2>&1 || true
  if [ -f "$work/munged.pid" ]; then kill "$(cat "$work/munged.pid")" 2>/dev/null || true; fi
}
stop_cluster
rm -rf "$work"
mkdir -p "$work/ctld" "$work/slurmd" "$work/munge" "$work/out"
ln -s "$root/jobs" "$work/jobs"

# munge: a key of this run's own, a daemon on a socket of its own.
dd if=/dev/urandom of="$work/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$work/munge/munge.key"
socket=$work/munge/munge.socket
munged --force --key-file="$work/munge/munge.key" --socket="$socket" \
  --pid-file="$work/munged.pid" --log-file="$work/munge/munged.log" \
  --seed-file="$work/munge/munged.seed"

cat >"$conf" <<EOF
ClusterName=strata-check
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
StateSaveLocation=$work/ctld
SlurmdSpoolDir=$work/slurmd
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
KillWait=30
NodeName=$host CPUs=$(nproc) State=UNKNOWN
PartitionName=check Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$conf
trap stop_cluster EXIT
slurmctld -f "$conf"
slurmd -f "$conf"
for _ in $(seq 60); do
  sinfo -h -o %T 2>/dev/null | grep -qx idle && break
  sleep 1
done
sinfo -h -o '%P %D %T %c' | sed 's/^/slurm: /'

# The render unsplit, then the same render as Slurm tasks.
read -r -a args <<<"$render_args"
"$strata" render cornell "${args[@]}" --threads 1 --out "$work/whole" >/dev/null 2>&1
cd "$work"
export SCENE=cornell DIR=$work/out RENDER_ARGS=$render_args STRATA=$strata
submitted=$(jobs/slurm-submit.sh "$count" --cpus-per-task=1)
array=$(squeue -h -o '%F' | sort -u | head -1)
echo "slurm: array $array, $submitted"

# Task 1, once it has rendered a while, is requeued: stopped by SIGTERM.
status=0
for _ in $(seq 120); do
  [ "$(squeue -h -j "${array}_1" -o %T 2>/dev/null)" = RUNNING ] && break
  sleep 0.5
done
sleep 4
scontrol requeue "${array}_1"
for _ in $(seq 60); do
  [ -f out/part-1.ckpt ] && break
  sleep 0.5
done
if [ -f out/part-1.ckpt ]; then
  echo "task 1: stopped by its requeue, checkpoint saved"
else
  echo "FAIL: task 1 saved no checkpoint when its requeue stopped it (it ran too short?)"
  status=1
fi

# Everything ends (the merge job last).
for _ in $(seq 600); do
  [ -z "$(squeue -h)" ] && break
  sleep 1
done
[ -z "$(squeue -h)" ] || { echo "FAIL: jobs still queued: $(squeue -h)"; status=1; }
for ext in png exr; do
  if cmp -s "out/image.$ext" "whole.$ext"; then
    echo "merged $ext: the unsplit render's bytes"
  else
    echo "FAIL: merged $ext differs from the unsplit render (or is missing)"
    status=1
  fi
done
grep -h -i "resum\|stopped\|error" strata-*.log 2>/dev/null | sed 's/^/log: /' | head -20
ls out
exit $status
