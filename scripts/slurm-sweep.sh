#!/usr/bin/env bash
# SLURM array-job template: each array task computes one shard of a sweep, then a dependent job
# merges the shards into one HDF5 file. Edit the variables, then submit from a login node:
#
#   bash scripts/slurm-sweep.sh            # submits the array and the merge job
#
# Each task runs
#   crawlsim velocity $GAIT $SWEEP --shard $SLURM_ARRAY_TASK_ID/$SHARDS -o $OUT/part-$ID.h5
# and resumes by itself if it is requeued: on SLURM's SIGTERM (time limit, preemption) crawlsim
# flushes the shard's journal of finished points and exits 143, and the rerun reads it back.
# Each task's log ($OUT/part-ID.log) gets a progress line (points done, rate, ETA) every
# $PROGRESS seconds.
set -euo pipefail
GAIT=${GAIT:-gaits/peristalsis-4.yaml}
SWEEP=${SWEEP:-"--sweep links.*.amplitude=0.05:0.45:200 --sweep links.1.phase=0:1:200"}
SHARDS=${SHARDS:-32}
OUT=${OUT:-sweep-out}
CPUS=${CPUS:-4}
TIME=${TIME:-01:00:00}
OPTIONS=${OPTIONS:-"--steps-per-period 400"}
export CRAWLSIM_PROGRESS_INTERVAL=${PROGRESS:-60}

mkdir -p "$OUT"
array=$(sbatch --parsable --job-name=crawlsim-sweep --array="1-$SHARDS" \
    --cpus-per-task="$CPUS" --time="$TIME" --requeue --output="$OUT/part-%a.log" \
    --wrap="crawlsim velocity $GAIT $SWEEP $OPTIONS --jobs $CPUS \
--shard \$SLURM_ARRAY_TASK_ID/$SHARDS -o $OUT/part-\$SLURM_ARRAY_TASK_ID.h5")
sbatch --job-name=crawlsim-merge --dependency="afterok:$array" --time=00:10:00 \
    --output="$OUT/merge.log" --wrap="crawlsim merge $OUT/part-*.h5 -o $OUT/sweep.h5"
echo "submitted array job $array ($SHARDS shards) and its merge into $OUT/sweep.h5"
