#!/usr/bin/env bash
# Regenerate every calibration artefact: the evaluation sets (if missing), the k sweeps, the shipped presets
# (weather_gym/weather/presets.toml), the physical-dim alternative (weather_gym/calibration/presets_physical.toml),
# the transfer check on held-out sets (and what their spread follows) and the reports and plots in docs/calibration/.
#
#   bash docs/calibration/regenerate.sh            # from the repository root, in the venv
#
# Resumable: a finished sweep or transfer cell is never run again (delete docs/calibration/curves.*,
# sweep.json and transfer/**/cells.* to start over). Cells are keyed by effect spec, k, seed, evaluation set
# and detector (a new model gets new rows, the old ones are ignored by model_id), not by the effect's code:
# after changing what an effect draws, delete its rows from curves.csv, remeasured.csv and the transfer/**/cells.csv
# files and delete their .sqlite stores (rebuilt from the CSVs on the next run).
set -euo pipefail
SETS=${SETS:-scratch/calib}              # the rendered evaluation sets (git-ignored; rendered deterministically)
WORKERS=${WORKERS:-2}
OUT=docs/calibration
SET=$SETS/mix                            # the four-track set: the study's modes and the physical dim
POOL=$SETS/pool                          # the calibration pool of the shipped modes: six tracks, both worlds
REAL=${REAL:-}                           # optional: an imported real clear set with its ignore mask (docs/real_data.md)

render() {  # render OUT ARGS...: a fixed set, once
  local out=$1; shift
  [ -f "$out/annotations.json" ] || weather-gym dataset render "$@" --frames-per-episode 10 --out "$out" --quiet
}
# calibration set: four tracks (peanut and two generated tracks are held out from the detector's training),
# default bright-overcast look, 24 start points x 10 frames
render "$SET" --track peanut --track random:80 --track random:81 --track fsds_training --frames 240 --seed 606
# the pool: the four-track set, two more generated tracks, and the realistic world on two of the tracks
render "$SETS/pool_plain" --track random:83 --track random:84 --frames 80 --seed 612
render "$SETS/pool_realistic" --track random:80 --track fsds_training --frames 80 --seed 611 --scene realistic
[ -f "$POOL/annotations.json" ] || weather-gym dataset merge "$SET" "$SETS/pool_plain" "$SETS/pool_realistic" --out "$POOL"
# held-out sets: tracks the calibration never saw, and the realistic world
HELD=(jellybean b_shape hairpin random:82 small_track oval random:85 random:86)
for t in "${HELD[@]}"; do
  render "$SETS/held_${t//:/}" --track "$t" --frames 80 --seed 707
done
# the same eight tracks three times as long (two more 80-frame sets each, merged with the first): how much
# of a preset's spread over the held-out sets is the 80-frame sample, not the track (checked at the end)
RESAMPLES=(); HELD240=()
for t in "${HELD[@]}"; do
  for seed in 710 711; do
    render "$SETS/held_${t//:/}_$seed" --track "$t" --frames 80 --seed "$seed"
    RESAMPLES+=(--set "$t ($seed)=$SETS/held_${t//:/}_$seed")
  done
  [ -f "$SETS/held240_${t//:/}/annotations.json" ] || weather-gym dataset merge "$SETS/held_${t//:/}" \
    "$SETS/held_${t//:/}_710" "$SETS/held_${t//:/}_711" --out "$SETS/held240_${t//:/}"
  HELD240+=(--set "$t=$SETS/held240_${t//:/}")
done
# the first 80-frame set of each held-out track again with the camera model's vignetting off, again
# with its barrel distortion off, and again without the EGL plugin's shadow map (same poses and looks;
# the vignetting, distortion and shadow-map checks at the end)
NOVIG=(); NODIST=(); NOSHADOW=()
for t in "${HELD[@]}"; do
  render "$SETS/held_novig_${t//:/}" --track "$t" --frames 80 --seed 707 --camera-model "$OUT/no_vignetting.toml"
  NOVIG+=(--set "$t=$SETS/held_novig_${t//:/}")
  render "$SETS/held_nodist_${t//:/}" --track "$t" --frames 80 --seed 707 --camera-model "$OUT/no_distortion.toml"
  NODIST+=(--set "$t=$SETS/held_nodist_${t//:/}")
  render "$SETS/held_noshadow_${t//:/}" --track "$t" --frames 80 --seed 707 --shadows off
  NOSHADOW+=(--set "$t=$SETS/held_noshadow_${t//:/}")
done
render "$SETS/held_realistic" --track peanut --track random:82 --frames 80 --seed 708 --scene realistic
render "$SETS/held_realistic2" --track hairpin --track random:85 --frames 80 --seed 709 --scene realistic
# a blind check: sets first rendered after the presets and the night camera were fixed (nothing was tuned on
# them): three more generated tracks, the skidpad (cones all round the frame), the realistic world on two more tracks
BLIND=()
for t in random:90 random:91 random:92 skidpad; do
  render "$SETS/blind_${t//:/}" --track "$t" --frames 80 --seed 707
  BLIND+=(--set "$t=$SETS/blind_${t//:/}")
done
render "$SETS/blind_realistic" --track jellybean --track small_track --frames 80 --seed 713 --scene realistic
BLIND+=(--set "realistic (jellybean, small_track)=$SETS/blind_realistic")

# the study's faithful effects and the physical dim on the four-track set, on a 0.1 grid (refractive drops
# too, for the physical alternative); the shipped modes on the pool, the night camera finer where it falls
weather-gym sweep --weather droplets,dim,dim:k:mode=physical,droplets:k:mode=refractive \
  --k-grid 0:1:0.1 --seeds 3 --dataset "$SET" --out "$OUT" --workers "$WORKERS" --overwrite --quiet
# the study's dim is a cliff (near 1 up to k 0.85, gone by 0.95): finer, to show its shape
weather-gym sweep --weather dim --k-grid 0:1:0.05 --seeds 3 --dataset "$SET" --out "$OUT" --workers "$WORKERS" \
  --overwrite --quiet
weather-gym sweep --weather droplets:k:mode=refractive --k-grid 0:1:0.1 --seeds 2 \
  --dataset "$POOL" --out "$OUT" --workers "$WORKERS" --overwrite --quiet
weather-gym sweep --weather dim:k:mode=night \
  --k-grid 0,0.2,0.4,0.5,0.55,0.6,0.625,0.65,0.675,0.7,0.725,0.75,0.775,0.8,0.825,0.85,0.875,0.9,0.925,0.95,0.975,1 \
  --seeds 3 --dataset "$POOL" --out "$OUT" --workers "$WORKERS" --overwrite --quiet

id_of() { python -c "from weather_gym._io import file_id; print(file_id('$1/annotations.json'))"; }
POOL_ID=$(id_of "$POOL"); SET_ID=$(id_of "$SET")
python docs/calibration/plot_modes.py "$OUT/curves.csv" --dataset-id "$POOL_ID" --dataset-id "$SET_ID" \
  --out "$OUT/modes.png"

weather-gym calibrate --curve "$OUT/curves.csv" --dataset-id "$POOL_ID" --measured "$OUT/study_table2.csv" \
  --metric map50_blue_yellow --use droplets=droplets_refractive --use low_light=dim_night \
  --study-points "$OUT/study_figure7.csv" --dataset "$POOL" --seeds 5 --workers "$WORKERS" \
  --out weather_gym/weather/presets.toml --overwrite --report "$OUT" --quiet

weather-gym calibrate --curve "$OUT/curves.csv" --dataset-id "$SET_ID" --measured "$OUT/study_table2.csv" \
  --metric map50_blue_yellow --use droplets=droplets_refractive --use low_light=dim_physical \
  --dataset "$SET" --seeds 5 --workers "$WORKERS" \
  --out weather_gym/calibration/presets_physical.toml --overwrite --report "$OUT/physical" --quiet

# do the presets transfer? relative mAP per preset on the held-out sets (and real frames, if given)
TRANSFER=()
for t in "${HELD[@]}"; do TRANSFER+=(--set "$t=$SETS/held_${t//:/}"); done
TRANSFER+=(--set "realistic (peanut, random:82)=$SETS/held_realistic" --set "realistic (hairpin, random:85)=$SETS/held_realistic2")
[ -n "$REAL" ] && TRANSFER+=(--set "real (Estoril, masked)=$REAL")
python docs/calibration/transfer.py "${TRANSFER[@]}" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer"
# the spread of 80-frame sets of one track: the two more samples of each held-out track, then all three merged
python docs/calibration/transfer.py "${RESAMPLES[@]}" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/resamples"
python docs/calibration/transfer.py "${HELD240[@]}" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/held240"
python docs/calibration/transfer.py "${BLIND[@]}" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/blind"
# the same first sets without vignetting and without distortion; then where in the frame each set's cones
# are against its relative mAP, over the held-out and resampled sets (docs/calibration.md, "Why low light
# spreads over tracks")
python docs/calibration/transfer.py "${NOVIG[@]}" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/no_vignetting"
python docs/calibration/transfer.py "${NODIST[@]}" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/no_distortion"
# the same first sets without the shadow map (SimConfig.shadows=False): what that option does to the presets
python docs/calibration/transfer.py "${NOSHADOW[@]}" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/no_shadow_map"
PLACE=(--transfer "$OUT/transfer" "${TRANSFER[@]}" --transfer "$OUT/transfer/resamples" "${RESAMPLES[@]}"
       --transfer "$OUT/transfer/held240" "${HELD240[@]}")
python docs/calibration/placement.py "${PLACE[@]}" --reference "calibration pool=$POOL" --out "$OUT/transfer/placement"
python docs/calibration/edge_recall.py "${HELD240[@]}" --out "$OUT/transfer/placement"   # which cones go first
# is the low-light spread over tracks the work of one ISP stage? the night camera with stages off, each
# matched to the study's low-light targets on the held-out tracks' first sets (the realistic world reported)
ISP=(); for t in "${HELD[@]}"; do ISP+=(--set "$t=$SETS/held_${t//:/}"); done
python docs/calibration/isp_stages.py "${ISP[@]}" --extra "realistic (peanut, random:82)=$SETS/held_realistic" \
  --extra "realistic (hairpin, random:85)=$SETS/held_realistic2" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/isp_stages"
# is it the car's motion blur (the longer exposure smears by each frame's speed and yaw rate)? the low-light
# presets on the same sets scored as recorded and with the car standing still
python docs/calibration/still_camera.py "${ISP[@]}" --set "realistic (peanut, random:82)=$SETS/held_realistic" \
  --set "realistic (hairpin, random:85)=$SETS/held_realistic2" --seeds 2 --workers "$WORKERS" --out "$OUT/transfer/still_camera"
# would bigger colour blotches (damage more per cone, like the drops) transfer better? matched on the eight
# tracks' 240-frame sets, then on the calibration pool as the presets are (the second run reuses the cells)
BLOTCHES=(--variant 'night (shipped)={"mode": "night"}'
          --variant '32 px blotches, 1.5x={"mode": "night", "chroma_cell_px": 32, "chroma_noise": 24}')
REALISTIC=(--extra "realistic (peanut, random:82)=$SETS/held_realistic" --extra "realistic (hairpin, random:85)=$SETS/held_realistic2")
python docs/calibration/isp_stages.py "${HELD240[@]}" "${REALISTIC[@]}" "${BLOTCHES[@]}" --seeds 2 --workers "$WORKERS" \
  --stem night_blotches --out "$OUT/transfer/night_blotches"
python docs/calibration/isp_stages.py "${HELD240[@]}" "${REALISTIC[@]}" --extra "calibration pool=$POOL" \
  --match "calibration pool" "${BLOTCHES[@]}" --seeds 2 --workers "$WORKERS" --stem night_blotches_pool \
  --out "$OUT/transfer/night_blotches"
