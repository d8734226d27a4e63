#!/usr/bin/env bash
#SBATCH --job-name=epfilt-bands
#SBATCH --array=0-3
#SBATCH --cpus-per-task=16
#SBATCH --mem=2G
#SBATCH --time=04:00:00
#SBATCH --requeue
#SBATCH --output=epfilt-bands.%A_%a.log
#
# One huge frame across the 4 tasks of a Slurm array: each task filters one
# band of the output rows (`--band env`: band SLURM_ARRAY_TASK_ID + 1 of
# SLURM_ARRAY_TASK_COUNT, K counted from 1 as the band files name it) into
# OUT's name with .bandKofN before the extension. A job that depends on the
# array puts them together (docs/farm/slurm-merge.sh):
#
#   A=$(sbatch --parsable docs/farm/slurm-bands.sh)
#   sbatch --dependency=afterok:$A --kill-on-invalid-dep=yes docs/farm/slurm-merge.sh
#
# The merged file is byte-identical to one run over the whole image. Each band
# records the fingerprint of its input and settings: merge refuses a band of
# another input or other settings, naming it, and --skip-existing lets a
# requeued task keep a band that is already complete.
set -euo pipefail
# Half the job's --mem, in MiB: what epfilt plans for (it also reads the
# job's cgroup limit where Slurm confines it, and takes half of that).
export EPFILT_MAX_MEMORY=${EPFILT_MAX_MEMORY:-1024}
EPFILT=${EPFILT:-epfilt}
IN=${IN:-/shared/shots/sh010/matte.exr}
OUT=${OUT:-/shared/shots/sh010/matte.filtered.exr}
K=$((SLURM_ARRAY_TASK_ID - ${SLURM_ARRAY_TASK_MIN:-0} + 1))
exec "$EPFILT" filter "$IN" "${OUT%.exr}.band${K}of${SLURM_ARRAY_TASK_COUNT}.exr" \
    --band env --threads "${SLURM_CPUS_PER_TASK:-0}" --skip-existing -q
