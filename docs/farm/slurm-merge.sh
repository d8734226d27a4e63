#!/usr/bin/env bash
#SBATCH --job-name=epfilt-merge
#SBATCH --cpus-per-task=1
#SBATCH --mem=512M
#SBATCH --output=epfilt-merge.%j.log
#
# Put the bands of docs/farm/slurm-bands.sh together; submit it to depend on
# the band array (sbatch --dependency=afterok:<array job> --kill-on-invalid-dep=yes).
# merge copies compressed blocks: it runs at the speed of the disk, in a few MiB.
set -euo pipefail
# Half the job's --mem, in MiB: what epfilt plans for (it also reads the
# job's cgroup limit where Slurm confines it, and takes half of that).
export EPFILT_MAX_MEMORY=${EPFILT_MAX_MEMORY:-256}
EPFILT=${EPFILT:-epfilt}
OUT=${OUT:-/shared/shots/sh010/matte.filtered.exr}
shopt -s nullglob
bands=("${OUT%.exr}".band*of*.exr)
[ ${#bands[@]} -gt 0 ] || { echo "no bands beside $OUT" >&2; exit 1; }
"$EPFILT" merge "${bands[@]}" "$OUT" --report "${OUT%.exr}.merge.json"
rm -f "${bands[@]}"
