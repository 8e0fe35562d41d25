#!/usr/bin/env bash
# Regenerate the shipped perception-surrogate model (weather_gym/surrogate/models/shipped.npz):
# log the full pipeline (render -> weather -> the shipped ONNX detector) on the fitting tracks for
# clear weather and every calibrated preset, then fit. The validation track (hairpin) is not used here.
# Usage: docs/surrogate/regenerate.sh [LOG_DIR]   (about 15 min of one core per condition group)
set -euo pipefail
LOGS=${1:-scratch/surrogate_logs}
PY=${PYTHON:-python}
TRACKS=small_track,peanut
SEEDS=0,1
STEPS=600
mkdir -p "$LOGS"
for w in clear droplets@1 droplets@2 droplets@3 droplets@4 low_light@1 low_light@2 low_light@3 low_light@4; do
  f="$LOGS/${w/@/_}.npz"
  [ -f "$f" ] || $PY -m weather_gym.cli surrogate log --track $TRACKS --weather "$w" --seeds $SEEDS \
      --steps $STEPS --out "$f"
done
$PY -m weather_gym.cli surrogate fit "$LOGS"/*.npz --out weather_gym/surrogate/models/shipped.npz --overwrite
