#!/usr/bin/env bash
# Ablation of the training recipe on held-out bodies (issue 11): each variant in
# trainer/configs/ablation/ trains at a small budget, then `python -m bench.heldout` scores
# it on the held-out bodies and the stress set. Results: reports/ablation/<variant>.json,
# summarised by `python -m bench.ablation` into reports/ablation.md.
# DATASET (default data/poses.npz) holds the held-out bodies; TRAIN_DATASET (default the
# same file) is what the variants train on.
#   usage: scripts/ablation.sh [variant ...]   (default: every variant)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-.venv/bin}
DATASET=${DATASET:-data/poses.npz}  # held-out bodies are read from it
TRAIN_DATASET=${TRAIN_DATASET:-$DATASET}  # what the variants train on
variants=("$@")
if [ ${#variants[@]} -eq 0 ]; then
  variants=(full world_pairs no_bodies no_anchor no_delta no_augment)
fi
mkdir -p reports/ablation
for v in "${variants[@]}"; do
  cfg=trainer/configs/ablation/$v.toml
  models=$("$BIN/python" -c "from trainer.config import load_config; print(load_config('$cfg').out_dir)")
  echo "== $v: training ($cfg)"
  "$BIN/pose-trainer" train --config "$cfg" --dataset "$TRAIN_DATASET" --fresh > "reports/ablation/$v.train.log" 2>&1
  echo "== $v: held-out bench"
  "$BIN/python" -m bench.heldout --models "$models" --dataset "$DATASET" \
    --out "reports/ablation/$v.json" > "reports/ablation/$v.bench.log" 2>&1
done
