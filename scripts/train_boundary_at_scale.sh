#!/usr/bin/env bash
# The boundary network's frames and training on one CUDA machine (run 2026-11-28; the result was not
# shipped, see docs/experiments.md).
#   scripts/train_boundary_at_scale.sh DATA_DIR RUNS_DIR GEN_MINUTES TRAIN_MINUTES
# Test frames: the 16 held-out-category scenes x 6 views every boundary.pt is scored on. Training
# scenes are rendered by all cores for GEN_MINUTES (finished shards are kept, so a rerun adds to them),
# then two networks train side by side on the GPU for TRAIN_MINUTES, as many steps as fit:
# `continued` from the shipped weights (lr 1e-3) and `fresh` from scratch (lr 3e-3).
set -euo pipefail
data=$1 runs=$2 gen_minutes=$3 train_minutes=$4
workers=$(nproc)
mkdir -p "$runs/continued" "$runs/fresh"
shipped=src/arm_segmentation/arm_segmentation/checkpoints/boundary.pt
gen() { python -m arm_training.segmentation.boundary_data --out "$data" --views 6 --workers "$workers" "$@" | tail -n 1; }
gen --split test --shards 16
timeout "${gen_minutes}m" python -m arm_training.segmentation.boundary_data --out "$data" --views 6 --workers "$workers" \
  --split train --shards 100000 > "$runs/datagen.log" 2>&1 || true
pkill -f arm_training.segmentation.boundary_data || true  # the pool's workers outlive the timeout
echo "training shards: $(ls "$data/train" | wc -l)"
common=(--data "$data" --device "${DEVICE:-cuda}" --workers $((workers / 2)) --minutes "$train_minutes" --steps 0
  --batch 64 --outline-weight 1.5 --object-band-weight 4 --save-every 1000)
python -m arm_training.segmentation.boundary_train "${common[@]}" --init "$shipped" --lr 1e-3 \
  --out "$runs/continued/boundary.pt" > "$runs/continued.log" 2>&1 &
python -m arm_training.segmentation.boundary_train "${common[@]}" --lr 3e-3 --out "$runs/fresh/boundary.pt" > "$runs/fresh.log" 2>&1 &
wait
tail -n 2 "$runs"/*.log
