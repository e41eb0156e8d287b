#!/usr/bin/env bash
# Reproduces the shipped learned-descriptor models (config/descriptors/): the trainer with the
# settings they were made with, on this machine's CPUs. Usage: scripts/train.sh <build> [lrf|augment|all]
# Parts held out of training (the evaluation's unseen parts): blade and holder. An interrupted run
# resumes from <build>/train_*.ckpt; delete them to train from scratch. Training samples a fixed
# number of centres per level; the shipped files sample them down to a spacing instead
# (--resample: the same weights), so that a part inside a whole scene gets the centres it would
# get alone.
set -euo pipefail
BUILD=${1:-_build}
WHICH=${2:-all}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
TRAIN="$BUILD/devel/lib/cellsight/cellsight_train_descriptor"
MESHES=(--mesh "$ROOT/config/models/housing/mesh.ply" --mesh "$ROOT/config/models/flanged_shaft/mesh.ply"
        --mesh "$ROOT/config/models/bracket/mesh.ply")
SPACING=(--centre-spacing 0.25,0.5)
COMMON=(--generated 200 --dims 16 --levels 2 --threads 1 --seed 7 --validate-every 500 --model-pair-share 0.6 --time-limit 7000)
if [ "$WHICH" = lrf ] || [ "$WHICH" = all ]; then
  echo "== learned descriptor, local reference frames (config/descriptors/learned_k16.pt)"
  "$TRAIN" "${MESHES[@]}" "${COMMON[@]}" --rotation lrf --steps 12000 --output "$BUILD/train_lrf.pt" \
    --checkpoint "$BUILD/train_lrf.ckpt" --resume
  "$TRAIN" --resample "$BUILD/train_lrf.pt" "${SPACING[@]}" --output "$ROOT/config/descriptors/learned_k16.pt"
fi
if [ "$WHICH" = augment ] || [ "$WHICH" = all ]; then
  echo "== learned descriptor, rotation augmentation (config/descriptors/learned_k16_augment.pt)"
  "$TRAIN" "${MESHES[@]}" "${COMMON[@]}" --rotation augment --steps 6000 \
    --output "$BUILD/train_augment.pt" --checkpoint "$BUILD/train_augment.ckpt" --resume
  "$TRAIN" --resample "$BUILD/train_augment.pt" "${SPACING[@]}" --output "$ROOT/config/descriptors/learned_k16_augment.pt"
fi
