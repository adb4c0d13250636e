#!/usr/bin/env bash
# Training data and all four reconstruction variants at scale on one CUDA machine: the recipe of the
# shipped checkpoints (their model cards record each run's exact command).
#   scripts/train_at_scale.sh DATA_DIR RUNS_DIR TRAIN_SHARDS TEST_SHARDS TRAIN_MINUTES
# Train shards are 4/5 realistic, 1/5 plain domain; test shards realistic. Everything resumes: finished
# shards are skipped, and each variant continues from RUNS_DIR/<variant>/state.pt. Optional environment:
# RESOLUTION (grid side in voxels, default datagen's), INIT_DIR (start each variant without a state from
# INIT_DIR/<variant>.pt, e.g. the shipped checkpoints), BASE_CHANNELS (default 24), GENERATE=0 (train on
# the shards DATA_DIR already holds), FINAL_EVAL_SAMPLES (held-out samples in the final evaluation, 0 = all).
set -euo pipefail
data=$1 runs=$2 train_shards=$3 test_shards=$4 minutes=$5
workers=$(nproc)
mkdir -p "$runs"
realistic=$((train_shards * 4 / 5))
gen() {
  python -m arm_training.reconstruction.datagen --out "$data" --workers "$workers" ${RESOLUTION:+--resolution "$RESOLUTION"} \
    "$@" | tail -n 3
}
if [[ "${GENERATE:-1}" != 0 ]]; then
  gen --split test --shards "$test_shards" --domain realistic
  gen --split train --shards "$realistic" --domain realistic
  gen --split train --shards $((train_shards - realistic)) --first-seed "$realistic" --domain plain
fi
declare -A extra=(
  [baseline]=""
  [arm-c-s]=""
  [arm-c]="--stability-weight 3e-5"
  [arm]="--stability-weight 3e-5 --connectivity-weight 1e-4"
)
for variant in baseline arm-c-s arm-c arm; do
  # shellcheck disable=SC2086
  python -m arm_training.reconstruction.train --variant "$variant" --data "$data" --device "${DEVICE:-cuda}" --threads 2 \
    --base-channels "${BASE_CHANNELS:-24}" --batch-size 64 --lr 4e-4 --steps 200000 --time-limit-min "$minutes" \
    --eval-every 1000 --eval-samples 256 --final-eval-samples "${FINAL_EVAL_SAMPLES:-0}" --checkpoint-every 500 ${extra[$variant]} \
    ${INIT_DIR:+--init-from "$INIT_DIR/$variant.pt"} \
    --out "$runs/$variant/$variant.pt" > "$runs/$variant.log" 2>&1 &
done
wait
tail -n 4 "$runs"/*.log
