#!/usr/bin/env bash
# The main job: the most complete end-to-end run that exists today, on the
# synthetic work site (config/scene.yaml) with a simulated operator. It grows
# into `foresight demo` (the ORU changeout on the embedded simulated robot,
# over DDS) once the controller daemon and the link exist.
#
#   1. the robot model;
#   2. the simulated operator clicks on the arm (4 arm poses) and the ORU in
#      four camera views (1 px noise);
#   3. each camera calibrated with the arm as the fixture (the paper's two-step
#      method) into cameras.yaml;
#   4. the ORU localized from all four views, compared with the truth;
#   5. the changeout approach planned through the ORU's tag frames (joint move
#      to 20 cm in front of the hole, straight-line insertion and extraction,
#      back to the start) and validated as the remote will;
#   6. what the operator sees: a synthetic video frame, the calibrated overlay
#      (hidden-line wire-frame, tag triads), the preview video with its contact
#      sheet, and a predictive frame (commanded ghost over a 2 s old arm);
#   7. the accuracy study (Monte Carlo of the paper's tables, with the bound).
#
# Everything is written to $FORESIGHT_DEMO_DIR (default build/demo); each
# step's full output is kept there as a .txt file.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
BUILD=${FORESIGHT_BUILD_DIR:-build}
F="$PWD/$BUILD/bin/foresight"
OUT=${FORESIGHT_DEMO_DIR:-$BUILD/demo}
rm -rf "$OUT"
mkdir -p "$OUT"
cd "$OUT"
step() { printf '\n== %s ==\n' "$*"; }

step "1. robot model (config/robot.urdf)"
"$F" robot >robot.txt
sed -n 1,14p robot.txt

step "2. simulated operator: clicks on the arm and the ORU, 1 px noise"
"$F" synth-clicks --calibration-out arm_clicks.csv --object-out oru_clicks.csv --joints-out arm_pose.txt \
  --noise-px 1.0 --seed 7
Q=$(cat arm_pose.txt)

step "3. camera calibration, the arm as the fixture"
for cam in side oblique overhead_wide overhead_zoom; do
  "$F" calibrate arm_clicks.csv --camera "$cam" --out cameras.yaml >"calibrate_$cam.txt"
  sed -n 1,4p "calibrate_$cam.txt"
done

step "4. ORU localization from four views (compare with the true pose in step 2)"
"$F" localize oru_clicks.csv --cameras cameras.yaml >localize.txt
sed -n 1,3p localize.txt
"$F" localize oru_clicks.csv --cameras cameras.yaml --json >localize.json

step "5. changeout approach: plan through the ORU's tags, validate as the remote will"
"$F" plan --object-pose localize.json --from "$Q" \
  --to approach_20cm,hole_entrance:linear,tool_inserted:linear,hole_entrance:linear,approach_20cm:linear,start \
  --dwell-s 0.5 --out approach.csv
"$F" validate approach.csv

step "6. what the operator sees (camera oblique)"
"$F" synth --camera oblique --joints "$Q" --out video_oblique.png
"$F" overlay --cameras cameras.yaml --camera oblique --image video_oblique.png --joints "$Q" \
  --object-pose localize.json --tags --mode hidden --out overlay_oblique.png
"$F" preview approach.csv --cameras cameras.yaml --camera oblique --image video_oblique.png \
  --object-pose localize.json --speed 4 --out preview_oblique.mp4 --contact-sheet preview_sheet.png
"$F" predictive --cameras cameras.yaml --camera oblique --image video_oblique.png \
  --commanded "$(sed -n 700p approach.csv | cut -d, -f2-)" --actual "$(sed -n 500p approach.csv | cut -d, -f2-)" \
  --delay-s 2.0 --object-pose localize.json --out predictive_oblique.png

step "7. accuracy study: the paper's Tables 1-3 beside the Cramer-Rao bound (200 trials, 1 px)"
"$F" eval localization --trials 200 --noise-px 1 >eval_localization.txt 2>/dev/null
tail -n 3 eval_localization.txt

step "done: outputs in $OUT"
ls -1
