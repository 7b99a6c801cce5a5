#!/usr/bin/env bash
# One capture sharded over a Slurm job array (docs/scaling.md): array task k of n renders every n-th frame of the
# same plan into a folder of its own; `diviewer data merge` then joins the shards into one dataset.
#
#   sbatch --array=0-7 docs/examples/capture_slurm.sh                      # 8 tasks, one shard each
#   sbatch --dependency=afterok:JOBID --wrap "diviewer data merge runs/sponza/shards/shard_* --out runs/sponza/data"
#
# Every task must see the same settings (the frames, their seeds and configurations are a function of the scene file
# and these values), the same scene file and the same project version. A killed task resumes where it stopped when
# run again. Override the defaults in the environment: SCENE=cornell FRAMES=6000 sbatch --array=0-7 ...
#SBATCH --job-name=diviewer-capture
#SBATCH --cpus-per-task=8
#SBATCH --time=24:00:00
set -euo pipefail
SCENE=${SCENE:-sponza}
FRAMES=${FRAMES:-3400}
RES=${RES:-228x128}
SPP=${SPP:-64}
GT=${GT:-pt}
OUT=${OUT:-runs/$SCENE/shards}
DIVIEWER=${DIVIEWER:-diviewer}
: "${SLURM_ARRAY_TASK_ID:?run it as a job array (sbatch --array=0-7 ...), or set SLURM_ARRAY_TASK_ID and _COUNT}"
N=${SLURM_ARRAY_TASK_COUNT:?the number of tasks in the array (Slurm sets it)}
K=$((SLURM_ARRAY_TASK_ID - ${SLURM_ARRAY_TASK_MIN:-0} + 1))   # shards count from 1
$DIVIEWER capture --scene "$SCENE" --frames "$FRAMES" --res "$RES" --spp "$SPP" --gt "$GT" --direct-samples 4 \
  --shard "$K/$N" --out "$OUT/shard_$K"
