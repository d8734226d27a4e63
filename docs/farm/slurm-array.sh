#!/usr/bin/env bash
#SBATCH --job-name=epfilt-sh010
#SBATCH --array=0-7
#SBATCH --cpus-per-task=16
#SBATCH --mem=2G
#SBATCH --time=04:00:00
#SBATCH --requeue
#SBATCH --output=epfilt-sh010.%A_%a.log
#
# Filter shot sh010 (frames 1-240) on a Slurm job array: `sbatch slurm-array.sh`.
# Each of the 8 array tasks filters one contiguous chunk of the frames; epfilt
# reads its share from SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_MIN,
# SLURM_ARRAY_TASK_STEP and SLURM_ARRAY_TASK_COUNT. Outputs appear whole or
# not at all, and --skip-existing makes a requeued or resubmitted task redo
# only the frames that are missing. The exit status is 1 when a frame failed
# (the others are still done); its report names the frame and the cause.
#
# The paths are variables so the same script runs anywhere (docs/farm.md; CI
# runs it locally with the SLURM_* variables set).
set -euo pipefail
# Half the job's --mem, in MiB: what epfilt plans for (it also reads the
# job's cgroup limit where Slurm confines it, and takes half of that).
export EPFILT_MAX_MEMORY=${EPFILT_MAX_MEMORY:-1024}
EPFILT=${EPFILT:-epfilt}
FRAMES=${FRAMES:-/shared/shots/sh010/render}
OUT=${OUT:-/shared/shots/sh010/filtered}
RANGE=${RANGE:-1-240}
mkdir -p "$OUT"
exec "$EPFILT" filter "$FRAMES/beauty.####.exr" "$OUT/beauty.####.exr" \
    --frames "$RANGE" --method ep-gauss --threads "${SLURM_CPUS_PER_TASK:-0}" \
    --skip-existing --report "$OUT/report.task-${SLURM_ARRAY_TASK_ID:-0}.json"
