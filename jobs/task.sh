#!/usr/bin/env bash
# Task INDEX of COUNT of a render split into tasks: what every scheduler's
# job runs (jobs/slurm-tasks.sbatch, jobs/kubernetes.yaml, or xargs on one
# machine; README, "Rendering on a cluster"). Writes $DIR/part-INDEX.part;
# `strata merge $DIR/part-*.part --out IMAGE` then gives the image the
# render unsplit gives, byte for byte.
#
#   jobs/task.sh INDEX COUNT
#
# Environment: SCENE (a built-in name or a .pbrt file; default cornell), DIR
# (shared storage for the parts; default out/tasks), RENDER_ARGS (the
# render's flags, the same for every task: method, budget, seed, size;
# default "--method pssmlt --spp 64 --seed 1"), THREADS (default: every
# core), STRATA (the strata command; default: the one on PATH),
# STRATA_CHECKPOINT_KEY (if set, checkpoints and parts are sealed with it).
#
# A task that is run again finds its finished part and does nothing but
# remove a checkpoint left beside it; one that was stopped (preempted,
# requeued; SIGTERM saves a checkpoint) continues from its checkpoint,
# written every 10 minutes and removed once the part is written.
set -euo pipefail
index=${1:?usage: jobs/task.sh INDEX COUNT}
count=${2:?usage: jobs/task.sh INDEX COUNT}
scene=${SCENE:-cornell}
dir=${DIR:-out/tasks}
strata=${STRATA:-strata}
read -r -a render_args <<<"${RENDER_ARGS:---method pssmlt --spp 64 --seed 1}"
threads=${THREADS:-$(nproc)}
out="$dir/part-$index"
mkdir -p "$dir"
if [ -f "$out.part" ]; then
  # Finished: a checkpoint left by a stop between the two is stale.
  rm -f "$out.ckpt"
  exit 0
fi
resume=()
[ -f "$out.ckpt" ] && resume=(--resume "$out.ckpt")
"$strata" render "$scene" "${render_args[@]}" --threads "$threads" \
  --task-index "$index" --task-count "$count" --out "$out" \
  --checkpoint-every 600 "${resume[@]}" &
# The render in the background so that a scheduler's SIGTERM reaches it
# (and the checkpoint is saved) while this shell waits.
render=$!
trap 'kill -TERM "$render" 2>/dev/null' TERM INT
status=0
wait "$render" || status=$?
# A stopped wait returns early: wait for the render to save and exit.
while kill -0 "$render" 2>/dev/null; do wait "$render" || status=$?; done
if [ "$status" = 0 ] && [ -f "$out.part" ]; then
  rm -f "$out.ckpt"
fi
exit "$status"
