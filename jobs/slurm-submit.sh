#!/usr/bin/env bash
# Submits a render as COUNT Slurm array tasks and a merge job that runs
# after all of them succeed.
#
#   SCENE=scene.pbrt DIR=/shared/render RENDER_ARGS="--method mc --spp 4096" \
#     jobs/slurm-submit.sh 8
set -euo pipefail
count=${1:?usage: jobs/slurm-submit.sh COUNT}
array=$(sbatch --parsable --array=0-$((count - 1)) jobs/slurm-tasks.sbatch)
sbatch --dependency="afterok:${array%%;*}" jobs/slurm-merge.sbatch
