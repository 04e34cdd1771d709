#!/usr/bin/env bash
# Submits a render as COUNT Slurm array tasks and a merge job that runs once
# all of them have ended; further arguments are sbatch options for both
# (the cores a task uses, a partition, a time limit):
#
#   SCENE=scene.pbrt DIR=/shared/render RENDER_ARGS="--method mc --spp 4096" \
#     jobs/slurm-submit.sh 8 --cpus-per-task=4 --partition=render
#
# The merge waits with afterany, not afterok: a task that was stopped and
# requeued counts as failed under afterok, whose merge then waited for ever
# (DependencyNeverSatisfied) though the requeued task succeeded. `strata
# merge` itself refuses a missing or unfinished part, naming it.
set -euo pipefail
count=${1:?usage: jobs/slurm-submit.sh COUNT [SBATCH OPTIONS...]}
shift
array=$(sbatch --parsable --array=0-$((count - 1)) "$@" jobs/slurm-tasks.sbatch)
sbatch --dependency="afterany:${array%%;*}" "$@" jobs/slurm-merge.sbatch
