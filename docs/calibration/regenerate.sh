#!/usr/bin/env bash
# Regenerate every calibration artefact: the evaluation set (if missing), the k sweeps, the shipped presets
# (weather_gym/weather/presets.toml), the physical-dim alternative (weather_gym/calibration/presets_physical.toml)
# and the reports and plots in docs/calibration/.
#
#   bash docs/calibration/regenerate.sh            # from the repository root, in the venv
#
# Resumable: a finished sweep cell is never run again (delete docs/calibration/curves.csv and sweep.json to start over, e.g.
# after the detector changes - a new model gets new rows, and the old ones are ignored by model_id).
set -euo pipefail
SET=${SET:-scratch/calib/eval_peanut}     # the fixed evaluation set (git-ignored; rendered deterministically)
WORKERS=${WORKERS:-2}
OUT=docs/calibration

if [ ! -f "$SET/annotations.json" ]; then
  # peanut is held out from the detector's training; default (bright overcast) look; 16 start points x 10 frames
  weather-gym dataset render --track peanut --frames 160 --seed 606 --frames-per-episode 10 --out "$SET"
fi

weather-gym sweep --effect droplets --effect dim --effect dim:mode=physical --k 0:1:0.05 --seeds 5 \
  --dataset "$SET" --out "$OUT" --workers "$WORKERS" --overwrite

weather-gym calibrate --curve "$OUT/curves.csv" --measured "$OUT/study_table2.csv" \
  --study-points "$OUT/study_figure7.csv" --dataset "$SET" --seeds 5 --workers "$WORKERS" \
  --out weather_gym/weather/presets.toml --overwrite --report "$OUT"

weather-gym calibrate --curve "$OUT/curves.csv" --measured "$OUT/study_table2.csv" --use low_light=dim_physical \
  --dataset "$SET" --seeds 5 --workers "$WORKERS" \
  --out weather_gym/calibration/presets_physical.toml --overwrite --report "$OUT/physical"
